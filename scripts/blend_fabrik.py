"""The neural soft answer blended with FABRIK's (docs/generalisation-4.md, item 67).

For every set of ``python -m bench.heldout``'s families (the held-out bodies, the in-studio
TEST split as captured and rebuilt as other bodies; the same edits, seed 0): the shipped
soft answer (neural + bone pass) ``N``, FABRIK's answer from the caller's start ``F``, and
``bone_pass(lam * N + (1 - lam) * F)`` for each ``--lam``. Prints, per group of families,
the mean MPJPE over sets and how many sets each answer has below FABRIK, and the 5 end
effectors' MPJPE over FABRIK's (issue 11's goal: at most 0.7). ``--split val`` scores the
VAL split's clips (sources the networks trained on, clips they did not) as the held-out
families; ``--per-set`` also prints, per family and set, the best ``lam`` of 0, 0.1, .., 1.

    .venv/bin/python scripts/blend_fabrik.py [--models models] [--lam 0.5 0.75]
        [--split holdout|val] [--per-set]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import bench.heldout as heldout
from bench.edits import FIVE, Edits, solve
from bench.metrics import per_item
from core.kinematics import bone_pass
from core.skeleton import bone_lengths
from trainer.data.dataset import load_dataset

GRID = [round(0.1 * i, 1) for i in range(11)]
GROUPS = {
    "held-out sources": lambda f: (
        f.split(": ")[0] in ("holdout", "val") and not f.endswith(": all")
    ),
    "in-studio world": lambda f: f == heldout.STUDIO,
    "stress bodies": lambda f: f.startswith("test: ") and f.endswith("bodies"),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", type=Path, default=Path("models"))
    ap.add_argument("--dataset", type=Path, default=heldout.DEFAULT_DATASET)
    ap.add_argument("--lam", type=float, nargs="+", default=[0.5, 0.75])
    ap.add_argument("--split", default="holdout", choices=["holdout", "val"])
    ap.add_argument("--per-set", action="store_true")
    args = ap.parse_args()
    engine = heldout.engine_for(args.models, None, threads=1)
    calls: list[dict[str, dict[str, float]]] = []  # per run_sets call: set -> answer -> MPJPE
    run_sets = heldout.run_sets

    def patched(engine: Any, sets: dict[str, Edits], *a: Any, **k: Any) -> Any:
        out = run_sets(engine, sets, *a, **k)
        row: dict[str, dict[str, float]] = {}
        for name, edits in sets.items():
            fab = solve(engine, edits, "fabrik")
            net = solve(engine, edits, "neural_bone")
            row[name] = {
                "fabrik": float(per_item(edits, fab)["mpjpe"].mean()),
                "shipped": float(per_item(edits, net)["mpjpe"].mean()),
            }
            lengths = bone_lengths(edits.start)
            for lam in [*args.lam, *(GRID if args.per_set else [])]:
                mix = bone_pass(lam * net + (1 - lam) * fab, lengths)
                row[name][f"blend {lam:g}"] = float(per_item(edits, mix)["mpjpe"].mean())
        calls.append(row)
        return out

    heldout.run_sets = patched  # type: ignore[assignment]
    res = heldout.run_heldout(
        engine,
        load_dataset(args.dataset),
        heldout.HeldoutConfig(),
        split=args.split,
        log=lambda s: None,
    )
    names = [f.name for f in res.families if not f.name.endswith(": all")]
    answers = ["shipped", *(f"blend {lam:g}" for lam in args.lam)]
    print("| families | answer | mean MPJPE over sets, cm | sets below FABRIK | "
          "5 end effectors / FABRIK |")  # fmt: skip
    print("|---|---|---|---|---|")
    for group, pick in GROUPS.items():
        rows = [r for n, r in zip(names, calls, strict=True) if pick(n)]
        for a in ["fabrik", *answers]:
            means = [s[a] for r in rows for s in r.values()]
            below = sum(s[a] < s["fabrik"] for r in rows for s in r.values())
            five = np.mean([r[FIVE][a] / r[FIVE]["fabrik"] for r in rows])
            print(f"| {group} | {a} | {np.mean(means):.4f} | {below} / {len(means)} | {five:.3f} |")
    if args.per_set:
        print("\n| family | set | FABRIK | shipped | best lam | its MPJPE |")
        print("|---|---|---|---|---|---|")
        for n, r in zip(names, calls, strict=True):
            for name, v in r.items():
                best = min(GRID, key=lambda lam: v[f"blend {lam:g}"])
                print(f"| {n} | {name} | {v['fabrik']:.3f} | {v['shipped']:.3f} | {best:g} | "
                      f"{v[f'blend {best:g}']:.3f} |")  # fmt: skip


if __name__ == "__main__":
    main()
