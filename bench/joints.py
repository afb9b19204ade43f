"""Where an edit set's error sits: the mean distance of each joint to the real pose, per
method, on the same world-space edits as :mod:`bench.heldout` (the held-out sources
pooled, or the in-studio TEST split as captured), and the sum over body parts divided by
the joint count, so the parts add up to the set's MPJPE.

``python -m bench.joints --set left_elbow --set right_elbow [--split test] [--serving K=V]``
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import numpy.typing as npt
import typer

from bench.characters import Serving
from bench.edits import solve
from bench.heldout import DEFAULT_DATASET, METHODS, HeldoutConfig, _rng, engine_for, family_sets
from core.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS
from service.engine import Engine

F64 = npt.NDArray[np.floating[Any]]
#: Body parts (every joint in one).
PARTS: dict[str, tuple[str, ...]] = {
    "trunk": ("pelvis", "spine1", "spine2", "neck", "head"),
    "left arm": ("left_collar", "left_shoulder", "left_elbow", "left_wrist"),
    "right arm": ("right_collar", "right_shoulder", "right_elbow", "right_wrist"),
    "legs": tuple(j for j in JOINT_NAMES if j.endswith(("hip", "knee", "ankle", "foot"))),
}
assert sorted(j for js in PARTS.values() for j in js) == sorted(JOINT_NAMES)


def joint_errors(
    engine: Engine, dataset: Any, sets: list[str], split: str, cfg: HeldoutConfig
) -> dict[str, dict[str, F64]]:
    """Per set and method, the mean distance of each joint to the real pose ``[21]`` (cm),
    over :mod:`bench.heldout`'s edits of ``split`` ("holdout": every source, pooled as
    its "holdout: all" family; "test": its "test: as captured" family)."""
    part = dataset.subset(dataset.split_mask(split))
    world = part.world()
    if split == "test":
        draws = [(part, world, cfg.stress, _rng(cfg.seed, 31, 0))]
    else:
        sources = sorted(set(part.clip_source[np.unique(part.clip)].tolist()))
        share = math.ceil(cfg.edits / len(sources))
        draws = []
        for k, source in enumerate(sources):
            mask = part.source_mask(source)
            draws.append((part.subset(mask), world[mask], share, _rng(cfg.seed, 11, k)))
    errors: dict[str, dict[str, list[F64]]] = {s: {m: [] for m in METHODS} for s in sets}
    for data, poses, n, rng in draws:
        edits, _, _ = family_sets(engine, data, poses, n, cfg, rng)
        for name in sets:
            goal = edits[name].goal
            assert goal is not None
            for method in METHODS:
                solved = solve(engine, edits[name], method, cfg.chunk)
                errors[name][method].append(np.linalg.norm(solved - goal, axis=-1) * 100.0)
    return {
        s: {m: np.concatenate(e).mean(axis=0) for m, e in by.items()} for s, by in errors.items()
    }


def parts_of(per_joint: F64) -> dict[str, float]:
    """Each body part's share of the MPJPE (its joints' sum over all joints' count)."""
    return {
        name: float(sum(per_joint[JOINT_INDEX[j]] for j in joints) / NUM_JOINTS)
        for name, joints in PARTS.items()
    }


def main(
    set_: Annotated[list[str], typer.Option("--set", help="Edit set (bench.heldout's name).")],
    models: Annotated[Path, typer.Option(help="Models folder (manifest.json).")] = Path("models"),
    dataset: Annotated[Path, typer.Option(help="Dataset file (format 2).")] = DEFAULT_DATASET,
    split: Annotated[str, typer.Option(help="holdout (pooled) or test.")] = "holdout",
    serving: Serving = None,
    seed: Annotated[int, typer.Option(help="Seed of every sample.")] = 0,
) -> None:
    """Print per joint and per body part where each method's error sits."""
    from trainer.data.dataset import load_dataset

    engine = engine_for(models, serving, threads=1)
    cfg = HeldoutConfig(seed=seed)
    res = joint_errors(engine, load_dataset(dataset), set_, split, cfg)
    for name, by in res.items():
        print(f"{name} ({split}): mean distance to the real pose, cm")
        print(f"{'':16}" + "".join(f"{m:>14}" for m in by))
        print(f"{'MPJPE':16}" + "".join(f"{v.mean():14.3f}" for v in by.values()))
        shares = {m: parts_of(v) for m, v in by.items()}
        for part in PARTS:
            print(f"{'  ' + part:16}" + "".join(f"{shares[m][part]:14.3f}" for m in by))
        for j, joint in enumerate(JOINT_NAMES):
            print(f"{joint:16}" + "".join(f"{v[j]:14.2f}" for v in by.values()))


if __name__ == "__main__":
    typer.run(main)
