"""Do pins hold? ``python -m bench.pins [--poses 6] [--dataset data/poses.npz]``.

Real poses (seeded, half from the TEST split, half from the held-out bodies), each edited
with one pin set (a joint or two held where they are) and one far target set (joints moved
0.3, 1 or 3 m in seeded directions), through :class:`service.engine.Engine` with the
shipped models: neural and FABRIK, soft and exact reach. A pin is a hard constraint
(docs/service.md, "Pins"): the table counts the edits that left a pin more than its
tolerance (1 mm) and more than 2 mm from where it was asked, and the farthest, per pin
set; beside them the targets' mean miss, which says the targets were still approached.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from core.skeleton import JOINT_INDEX

#: What is held: a joint off the legs, the legs, or both.
PIN_SETS: tuple[tuple[str, ...], ...] = (
    ("neck",), ("spine2",), ("head",), ("left_shoulder",), ("left_elbow",), ("left_hip",),
    ("left_knee",), ("left_ankle", "right_ankle"), ("neck", "left_ankle", "right_ankle"),
)  # fmt: skip
#: What is dragged (a set sharing a joint with the pins is skipped).
TARGET_SETS: tuple[tuple[str, ...], ...] = (
    ("left_wrist",), ("right_wrist",), ("left_wrist", "right_wrist"), ("head",),
    ("left_ankle",), ("left_elbow",), ("pelvis",),
)  # fmt: skip
DISTANCES = (0.3, 1.0, 3.0)


def sample_poses(dataset: Path, n: int, seed: int) -> np.ndarray:
    """``n`` poses from the TEST split and ``n`` from the held-out bodies, seeded."""
    from trainer.data.dataset import load_dataset

    data = load_dataset(dataset)
    rng = np.random.default_rng(seed)
    picks = [
        rng.choice(np.flatnonzero(data.split_mask(s)), n, replace=False)
        for s in ("test", "holdout")
    ]
    out: np.ndarray = data.positions[np.concatenate(picks)].astype(np.float64)
    return out


def run(
    models: Path, poses: np.ndarray, seed: int
) -> dict[tuple[str, ...], list[tuple[float, float]]]:
    """Per pin set: (farthest pin, targets' mean miss) of every edit, metres."""
    from service.engine import Engine
    from service.problems import SolveProblem

    engine = Engine(models, threads=1)
    rng = np.random.default_rng(seed)
    out: dict[tuple[str, ...], list[tuple[float, float]]] = {p: [] for p in PIN_SETS}
    cases = itertools.product(
        PIN_SETS, TARGET_SETS, DISTANCES, ("neural", "fabrik"), ("soft", "exact")
    )
    for pins, targets, dist, method, reach in cases:
        if set(pins) & set(targets):
            continue
        idx = np.asarray([JOINT_INDEX[j] for j in (*targets, *pins)], dtype=np.intp)
        for pose in poses:
            d = rng.normal(size=(len(targets), 3))
            goal = pose[idx].copy()
            goal[: len(targets)] += dist * d / np.linalg.norm(d, axis=1, keepdims=True)
            floor = float(pose[:, 1].min()) - 10.0  # out of the way: pins and reach alone
            problem = SolveProblem(
                pose=pose, target_idx=idx, target_pos=goal, weights=np.ones(len(idx)),
                n_targets=len(targets), method=method, reach=reach, floor=floor,
            )  # fmt: skip
            res = engine.solve([problem])[0]
            out[pins].append((float(res.pin_errors.max()), float(res.errors.mean())))
    return out


def main(
    models: Annotated[Path, typer.Option(help="Models folder (manifest.json).")] = Path("models"),
    dataset: Annotated[Path, typer.Option(help="Dataset file (format 2).")] = Path(
        "data/poses.npz"
    ),
    poses: Annotated[int, typer.Option(min=1, help="Poses per split (TEST, held-out).")] = 6,
    seed: Annotated[int, typer.Option(help="Seed of the poses and directions.")] = 0,
) -> None:
    """Print, per pin set, how many edits left a pin off and by how much."""
    res = run(models, sample_poses(dataset, poses, seed), seed)
    print(
        "| pins | edits | pin > 1 mm | pin > 2 mm | farthest pin (mm) | targets' mean miss (cm) |"
    )
    print("|---|---|---|---|---|---|")
    total = [0, 0, 0]
    for pins, rows in res.items():
        off = np.asarray([r[0] for r in rows])
        miss = np.asarray([r[1] for r in rows])
        total = [
            total[0] + len(off),
            total[1] + int((off > 1e-3).sum()),
            total[2] + int((off > 2e-3).sum()),
        ]
        print(
            f"| {' + '.join(pins)} | {len(off)} | {(off > 1e-3).sum()} | {(off > 2e-3).sum()} | "
            f"{1000 * off.max():.1f} | {100 * miss.mean():.1f} |"
        )
    print(f"| all | {total[0]} | {total[1]} | {total[2]} | | |")


if __name__ == "__main__":
    typer.run(main)
