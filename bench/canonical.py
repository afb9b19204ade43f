"""`make bench`'s B1 construction on any split, per source: each edit's start and goal
are real frames 0.2-1 s apart of one clip, each canonicalised over its own pelvis floor
point (facing +Z, its pelvis at its own height), the goal's joints the targets, scored
against the goal (:func:`bench.edits.edits_from_pairs`).

:mod:`bench.heldout`'s world edits put the start on the goal's pelvis, so there a pelvis
that does not move is right by construction, and FABRIK never moves it. Here the goal's
pelvis lies at its own height, as a body that crouched or rose between the frames has it:
the view that tells whether a set lost on the held-out bodies is lost to the body or to
that construction (docs/generalisation-3.md item 57).

``python -m bench.canonical [--split holdout|test|val] [--serving K=V] [--edits N]``
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from bench.accuracy import run_methods
from bench.characters import Serving
from bench.edits import b1_sets, edits_from_pairs, joint_idx, sample_pairs
from bench.heldout import DEFAULT_DATASET, engine_for
from bench.metrics import per_item

METHODS = ("identity", "fabrik", "neural_bone", "neural_exact")


def main(
    models: Annotated[Path, typer.Option(help="Models folder (manifest.json).")] = Path("models"),
    dataset: Annotated[Path, typer.Option(help="Dataset file (format 2).")] = DEFAULT_DATASET,
    split: Annotated[str, typer.Option(help="Split: holdout (per source), test, val.")] = "holdout",
    serving: Serving = None,
    edits: Annotated[int, typer.Option(min=1, help="Edits per source and set.")] = 400,
    seed: Annotated[int, typer.Option(help="Seed of every sample.")] = 0,
) -> None:
    """Print, per source of ``split``, each B1 set's MPJPE (cm) by method, in Markdown."""
    from trainer.data.dataset import load_dataset

    engine = engine_for(models, serving, threads=1)
    data = load_dataset(dataset)
    try:
        part = data.subset(data.split_mask(split))
    except ValueError as exc:  # not a split
        raise typer.BadParameter(str(exc), param_hint="--split") from None
    if len(part) == 0:
        raise typer.BadParameter(f"the dataset has no {split!r} frames", param_hint="--split")
    sources = sorted(set(part.clip_source[np.unique(part.clip)].tolist()))
    print(f"Models {engine.version}, split {split}, serving overrides {serving or []}, seed {seed}")
    for k, source in enumerate(sources):
        sub = part.subset(part.source_mask(source))
        a, b = sample_pairs(sub, edits, np.random.default_rng([seed, k]))
        rows = {}
        for name, joints in b1_sets(engine).items():
            sets = edits_from_pairs(sub, a, b, [joint_idx(joints)] * len(a))
            poses, _ = run_methods(engine, sets, METHODS, 512)
            rows[name] = {m: float(per_item(sets, poses[m])["mpjpe"].mean()) for m in METHODS}
        below = sum(r["neural_bone"] < r["fabrik"] for r in rows.values())
        below_ex = sum(r["neural_exact"] < r["fabrik"] for r in rows.values())
        print(f"\n{split}: {source}, {len(a)} edits per set; soft below FABRIK on {below} of "
              f"{len(rows)} sets, exact on {below_ex}\n")  # fmt: skip
        print("| set | start | FABRIK | soft | exact |\n|---|---|---|---|---|")
        for name, r in {**rows, "mean": _mean(rows)}.items():
            soft = f"**{r['neural_bone']:.3f}**" if r["neural_bone"] < r["fabrik"] else (
                f"{r['neural_bone']:.3f}"
            )  # fmt: skip
            print(f"| {name} | {r['identity']:.3f} | {r['fabrik']:.3f} | {soft} | "
                  f"{r['neural_exact']:.3f} |")  # fmt: skip


def _mean(rows: dict[str, dict[str, float]]) -> dict[str, float]:
    return {m: float(np.mean([r[m] for r in rows.values()])) for m in METHODS}


if __name__ == "__main__":
    typer.run(main)
