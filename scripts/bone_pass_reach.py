"""How far the bone pass moves a target the network reached (docs/generalisation.md, item 8).

For each held-out source: world-space edits of one joint (bench.heldout's pairs), solved by
the engine in soft reach with and without the bone pass; prints the mean reach error of each.

    .venv/bin/python scripts/bone_pass_reach.py [--models models] [--passes 1]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.edits import joint_idx, problems, sample_pairs
from bench.heldout import world_pairs
from service.engine import Engine
from trainer.data.dataset import load_dataset


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default="models")
    ap.add_argument("--dataset", default="data/poses.npz")
    ap.add_argument("--passes", type=int, default=1)
    ap.add_argument("--edits", type=int, default=200)
    args = ap.parse_args()
    data = load_dataset(args.dataset)
    held = data.subset(data.split_mask("holdout"))
    world = held.world()
    engine = Engine(Path(args.models), threads=1, serving={"passes": args.passes})
    print("source     joint        reach cm: no bone pass / with bone pass")
    for source in sorted(set(held.clip_source[np.unique(held.clip)].tolist())):
        mask = held.source_mask(source)
        part = held.subset(mask)
        rng = np.random.default_rng([0, 98])
        pairs = world_pairs(part, world[mask], *sample_pairs(part, args.edits, rng))
        for joint in ("left_wrist", "left_elbow", "left_knee", "left_ankle"):
            edits = pairs.edits([joint_idx((joint,))] * len(pairs))
            kept, raw = problems(edits, "neural_bone"), problems(edits, "neural_raw")
            r_raw = np.mean([r.errors.mean() for r in engine.solve(raw)]) * 100
            r_kept = np.mean([r.errors.mean() for r in engine.solve(kept)]) * 100
            print(f"{source:10s} {joint:12s} {r_raw:6.2f} / {r_kept:6.2f}")


if __name__ == "__main__":
    main()
