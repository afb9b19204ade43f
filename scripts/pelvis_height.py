"""Pelvis edits that lower or raise the body (docs/generalisation-serving-2.md, item 33).

Edits of the pelvis alone, from real pairs 0.2-1 s apart whose start stays where it was
captured (bench.heldout's pairs, ``captured``), kept where the goal's pelvis lies at least
8 cm below (or above) the start's. For each split and direction: MPJPE to the real goal
pose, and how far the lowest ankle or foot joint sinks below the goal's (cm), for the start
unchanged, FABRIK, and the neural answers with ``serving.pelvis_travel`` (the start moved
across, the height left to the networks). FABRIK's answer to a lone pelvis target is the
start moved onto it, which is also what moving the start vertically too would give.

    .venv/bin/python scripts/pelvis_height.py [--models models] [--edits 300]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.edits import Edits, sample_pairs, solve
from bench.heldout import PELVIS, world_pairs
from core.skeleton import JOINT_INDEX
from service.engine import Engine
from trainer.data.dataset import load_dataset

FEET = [JOINT_INDEX[n] for n in ("left_ankle", "left_foot", "right_ankle", "right_foot")]
METHODS = ("identity", "fabrik", "neural_bone", "neural_exact")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="models")
    ap.add_argument("--dataset", default="data/poses.npz")
    ap.add_argument("--edits", type=int, default=300)
    ap.add_argument("--seed", type=int, default=5)
    args = ap.parse_args()
    data = load_dataset(Path(args.dataset))
    engine = Engine(args.models, threads=1)
    print(f"models {engine.version}, pelvis_travel {engine.serving.pelvis_travel}")
    print("| split | pelvis | edits | mean height change | " + " | ".join(METHODS) + " |")
    print("|---|---|---|---|" + "---|" * len(METHODS))
    for split in ("test", "holdout"):
        part = data.subset(data.split_mask(split))
        world = part.world()
        a, b = sample_pairs(part, 20000, np.random.default_rng(args.seed))
        pairs = world_pairs(part, world, a, b, captured=True)
        dy = pairs.goal[:, PELVIS, 1] - pairs.start[:, PELVIS, 1]
        for name, keep in (("lowered", dy < -0.08), ("raised", dy > 0.08)):
            idx = np.flatnonzero(keep)[: args.edits]
            joints = [np.asarray([PELVIS])] * len(idx)
            edits = Edits(
                pairs.start[idx], joints, [pairs.goal[i, [PELVIS]] for i in idx], pairs.goal[idx]
            )
            cells = []
            for method in METHODS:
                out = solve(engine, edits, method)
                mpjpe = 100 * np.linalg.norm(out - edits.goal, axis=-1).mean()
                low = edits.goal[:, FEET, 1].min(axis=1) - out[:, FEET, 1].min(axis=1)
                cells.append(f"{mpjpe:.2f} (sinks {100 * np.maximum(low, 0).mean():.2f})")
            print(
                f"| {split} | {name} | {len(idx)} | {100 * dy[idx].mean():+.1f} cm | "
                + " | ".join(cells)
                + " |"
            )


if __name__ == "__main__":
    main()
