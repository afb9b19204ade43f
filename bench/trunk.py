"""A trunk dragged over pinned limbs: ``python -m bench.trunk [--poses 100] [--dataset
data/poses.npz]``.

Real poses (seeded, half from the TEST split, half from the held-out bodies:
:func:`bench.pins.sample_poses`), one joint of the trunk (the chest, the neck, the head)
dragged 5-20 cm in a seeded direction with the wrists, the ankles or both pinned, through
:class:`service.engine.Engine` with the shipped models: neural soft and exact, and FABRIK.
Per set and method, with the engine's retry of a dragged trunk (``service.fabrik_set.
onto_trunk``) and without it, side by side in one run: the dragged joint's mean miss (cm),
the answers that folded the hips or the shoulders (their distance below 80 % of the
start's), and the farthest pin (mm).
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer

from bench.pins import sample_poses
from core.geometry import rotation_about
from core.skeleton import JOINT_INDEX

if TYPE_CHECKING:
    from service.problems import SolveResult

app = typer.Typer(add_completion=False)

WRISTS, ANKLES = ("left_wrist", "right_wrist"), ("left_ankle", "right_ankle")
#: (dragged joint, pinned joints) of each set
SETS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("spine2", WRISTS), ("spine1", WRISTS), ("neck", WRISTS), ("head", WRISTS),
    ("spine2", ANKLES), ("neck", ANKLES), ("spine2", WRISTS + ANKLES),
    ("head", WRISTS + ANKLES),
)  # fmt: skip
METHODS = (("neural", "soft"), ("neural", "exact"), ("fabrik", "soft"))
PAIRS = (("left_hip", "right_hip"), ("left_shoulder", "right_shoulder"))
#: Of one set and method: mean miss (m), hips folded, shoulders folded, farthest pin (m).
Row = tuple[float, int, int, float]


@contextlib.contextmanager
def without_retry() -> Iterator[None]:
    """The engine as it answers without :func:`service.fabrik_set.onto_trunk` and without
    the rigid-hips retry (which over pinned legs keeps a valid body before reach)."""
    from service import fabrik_set

    kept, folded = fabrik_set._TRUNK, fabrik_set.FOLDED
    fabrik_set._TRUNK, fabrik_set.FOLDED = np.zeros_like(kept), 0.0
    try:
        yield
    finally:
        fabrik_set._TRUNK, fabrik_set.FOLDED = kept, folded


def run(models: Path, poses: np.ndarray, seed: int) -> dict[tuple[str, str, str], list[Row]]:
    """Per (dragged joint, pins, method): the :data:`Row` with the retry, then without."""
    from service.engine import Engine
    from service.problems import SolveProblem

    engine = Engine(models, threads=1)
    out: dict[tuple[str, str, str], list[Row]] = {}
    for joint, pins in SETS:
        rng = np.random.default_rng(seed)
        d = rng.normal(size=(len(poses), 3))
        d *= rng.uniform(0.05, 0.2, size=(len(poses), 1)) / np.linalg.norm(d, axis=1)[:, None]
        idx = np.asarray([JOINT_INDEX[j] for j in (joint, *pins)], dtype=np.intp)
        for method, reach in METHODS:
            problems = [
                SolveProblem(
                    pose=pose,
                    target_idx=idx,
                    target_pos=np.concatenate([pose[idx[:1]] + step, pose[idx[1:]]]),
                    weights=np.ones(len(idx)),
                    n_targets=1,
                    method=method,
                    reach=reach,
                    floor=float(pose[:, 1].min()) - 10.0,  # (out of the way)
                )
                for pose, step in zip(poses, d, strict=True)
            ]
            key = (joint, "+".join(pins), "FABRIK" if method == "fabrik" else reach)
            out[key] = [_row(engine.solve(problems), poses)]
            with without_retry():
                out[key].append(_row(engine.solve(problems), poses))
    return out


def _row(results: list[SolveResult], poses: np.ndarray) -> Row:
    ans = np.stack([r.pose for r in results])
    folds = []
    for a, b in PAIRS:
        i, j = JOINT_INDEX[a], JOINT_INDEX[b]
        width = np.linalg.norm(ans[:, i] - ans[:, j], axis=-1)
        folds.append(int((width < 0.8 * np.linalg.norm(poses[:, i] - poses[:, j], axis=-1)).sum()))
    miss = float(np.mean([r.errors[0] for r in results]))
    return miss, folds[0], folds[1], float(max(r.pin_errors.max() for r in results))


def table(res: dict[tuple[str, str, str], list[Row]], n: int) -> str:
    lines = [
        f"| dragged | pinned | method | miss, cm | hips folded (of {n}) | shoulders folded "
        "| farthest pin, mm |",
        "|---|---|---|---|---|---|---|",
    ]
    for (joint, pins, method), (ours, before) in res.items():
        lines.append(
            f"| {joint} | {pins.replace('_', ' ')} | {method} | {before[0] * 100:.2f} → "
            f"{ours[0] * 100:.2f} | {before[1]} → {ours[1]} | {before[2]} → {ours[2]} | "
            f"{before[3] * 1e3:.2f} → {ours[3] * 1e3:.2f} |"
        )
    return "\n".join(lines)


def reach_bound(poses: np.ndarray, seed: int, joint: str = "spine2") -> tuple[float, float]:
    """A lower bound on the mean miss of a body with its hips apart on the ``joint`` drags
    over pinned ankles (:data:`SETS`' seeded steps): its pelvis moved without turning, and
    turned up to 30 degrees (60 seeded axes, 10-30 degrees). The pelvis must lie within
    each leg's straight reach of its ankle (the hip's offset turned with it); the nearest
    such point to the goal (Dykstra's projection onto the two balls) leaves the goal this
    far beyond the spine's straight length up to ``joint``: no bend limit is counted, so a
    real body can only miss more."""
    from core.skeleton import PARENTS
    from service.fabrik_set import nearest_within

    rng = np.random.default_rng(seed)
    d = rng.normal(size=(len(poses), 3))
    d *= rng.uniform(0.05, 0.2, size=(len(poses), 1)) / np.linalg.norm(d, axis=1)[:, None]
    turns = np.stack([np.eye(3)] + [
        rotation_about(a / np.linalg.norm(a), np.radians(t))
        for a in rng.normal(size=(60, 3)) for t in (10, 20, 30)
    ])  # fmt: skip
    j = JOINT_INDEX[joint]
    still, turned = [], []
    for pose, step in zip(poses, d, strict=True):
        goal, spine, a = pose[j] + step, 0.0, j
        while a != 0:
            spine += float(np.linalg.norm(pose[a] - pose[PARENTS[a]]))
            a = PARENTS[a]
        legs = []
        for side in ("left", "right"):
            hip, knee, ankle = (JOINT_INDEX[f"{side}_{n}"] for n in ("hip", "knee", "ankle"))
            reach = np.linalg.norm(pose[hip] - pose[knee]) + np.linalg.norm(
                pose[knee] - pose[ankle]
            )
            legs.append((pose[ankle], pose[hip] - pose[0], float(reach)))
        centres = [ankle - turns @ off for ankle, off, _ in legs]  # [T, 3] each
        near, inside = nearest_within(goal, centres, [r for _, _, r in legs])
        miss = np.maximum(np.linalg.norm(goal - near, axis=1) - spine, 0.0)
        miss = np.where(inside, miss, 1.0)
        still.append(float(miss[0]))
        turned.append(float(miss.min()))
    return float(np.mean(still)), float(np.mean(turned))


@app.command()
def main(
    poses: Annotated[int, typer.Option(help="Poses of each split (TEST, held out).")] = 100,
    dataset: Annotated[Path, typer.Option()] = Path("data/poses.npz"),
    models: Annotated[Path, typer.Option()] = Path("models"),
    seed: Annotated[int, typer.Option()] = 11,
) -> None:
    picked = sample_poses(dataset, poses, seed)
    res = run(models, picked, seed)
    typer.echo(f"{len(picked)} poses; each cell: without the retry → with it (the engine's)")
    typer.echo(table(res, len(picked)))
    still, turned = reach_bound(picked, seed)
    typer.echo(
        f"\nThe chest over pinned ankles, the least mean miss of a body with its hips apart: "
        f"{still * 100:.2f} cm with the pelvis moved without turning, {turned * 100:.2f} cm "
        "with it turned up to 30 degrees."
    )


if __name__ == "__main__":
    app()
