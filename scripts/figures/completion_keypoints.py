"""Key-point completion on real TEST poses: how many requests leave a key point off, and
bodies scaled out of the networks' band (docs/service.md, "Key-point completion": the
bone whose two ends are key points, and ``TORSO_BAND``).

``--poses`` TEST-split poses (``numpy.random.default_rng(--seed).choice``, as
captured: pelvis over the origin, feet on the floor at 0) are completed through
``Engine.complete`` (``service.completion.complete``, no ``bone_lengths``) from the key
points of each completion level (6, 11 and 16 points) and from all 21 joints:

1. per key-point set, the requests with a key point more than ``--off`` (1 mm) from where
   it was asked, the worst key point, and the MPJPE to the real pose (cm);
2. with 6 key points, the key points scaled about the origin by each ``--scales`` factor
   (the floor stays at 0), the answer scaled back: its MPJPE to the real pose (cm) and
   the mean relative error of its bone lengths against the real pose's (scaled).

    python scripts/figures/completion_keypoints.py [--poses 40] [--seed 0] [--scales 1 3 0.3]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.edits import test_split
from core.skeleton import JOINT_INDEX, JOINT_NAMES, bone_lengths
from service.engine import Engine
from trainer.data.dataset import load_dataset

CM = 100.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, default=Path("models"))
    ap.add_argument("--dataset", type=Path, default=Path("data/poses.npz"))
    ap.add_argument("--poses", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--off", type=float, default=1e-3, help="a key point this far (m) is off")
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 3.0, 0.3])
    args = ap.parse_args()

    engine = Engine(args.models, threads=1)
    test = test_split(load_dataset(args.dataset))
    rows = np.random.default_rng(args.seed).choice(len(test), size=args.poses, replace=False)
    real = test.positions[rows].astype(np.float64)
    sets = [tuple(e.joints) for e in engine.manifest.completion_levels()] + [JOINT_NAMES]
    print(f"models {engine.version}; {args.poses} TEST poses, seed {args.seed}, no bone_lengths")
    print(
        f"| key points | requests with one > {args.off * 1000:g} mm off | worst (mm) | MPJPE (cm) |"
    )
    print("|---|---|---|---|")
    for joints in sets:
        worst, mpjpe = [], []
        for pose in real:
            res = engine.complete({j: pose[JOINT_INDEX[j]] for j in joints}, None)
            worst.append(float(res.errors.max()))
            mpjpe.append(float(np.linalg.norm(res.pose - pose, axis=-1).mean()))
        off = sum(w > args.off for w in worst)
        print(f"| {len(joints)} | {off} / {len(real)} | {max(worst) * 1000:.2f} | "
              f"{np.mean(mpjpe) * CM:.3f} |")  # fmt: skip

    six = sets[0]
    real_bones = bone_lengths(real)
    print(f"\n{len(six)} key points scaled by s about the origin, the answer scaled back by 1/s")
    print("| s | MPJPE to the real pose (cm) | bone lengths, mean relative error |")
    print("|---|---|---|")
    for s in args.scales:
        back = np.stack([
            engine.complete({j: s * pose[JOINT_INDEX[j]] for j in six}, None).pose / s
            for pose in real
        ])  # fmt: skip
        mpjpe = np.linalg.norm(back - real, axis=-1).mean() * CM
        bones = np.abs(bone_lengths(back) / real_bones - 1.0).mean()
        print(f"| {s:g} | {mpjpe:.2f} | {100.0 * bones:.1f} % |")


if __name__ == "__main__":
    main()
