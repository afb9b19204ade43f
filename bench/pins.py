"""Do pins hold? ``python -m bench.pins [--poses 6] [--dataset data/poses.npz] [--characters]``.

Real poses (seeded, half from the TEST split, half from the held-out bodies), each edited
with one pin set (a joint or two held where they are) and one far target set (joints moved
0.3, 1 or 3 m in seeded directions), through :class:`service.engine.Engine` with the
shipped models: neural and FABRIK, soft and exact reach. A pin is a hard constraint
(docs/limits.md, "Pins"): the table counts the edits that left a pin more than its
tolerance (1 mm) and more than 2 mm from where it was asked, and the farthest, per pin
set; beside them the targets' mean miss, which says the targets were still approached, and
the edits whose answer the pin polish finished (``pin-polish`` in its solvers,
:mod:`service.pins`) with the median time of a solve, those and the others (one thread).

``--characters``: the same question on users' own files through ``/v1/bvh/solve``'s steps
in process (:mod:`bench.characters`' twelve files, two frames each): the neck, the head, an
elbow, both ankles, or the neck and both ankles pinned, one or both wrists or the head
moved 0.5 or 1.5 m, soft, exact and FABRIK; the pin's miss is measured on the character's
own joints (the canonical answer it is laid onto holds its pins).
"""

from __future__ import annotations

import itertools
import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer

from core.skeleton import JOINT_INDEX

if TYPE_CHECKING:
    from core.bvh import BVH
    from service.engine import Engine

#: What is held: a joint off the legs, the legs, both, or the hands.
PIN_SETS: tuple[tuple[str, ...], ...] = (
    ("neck",), ("spine2",), ("head",), ("left_shoulder",), ("left_elbow",), ("left_hip",),
    ("left_knee",), ("left_ankle", "right_ankle"), ("neck", "left_ankle", "right_ankle"),
    ("left_wrist", "right_wrist"),
)  # fmt: skip
#: What is dragged (a set sharing a joint with the pins is skipped): ends, and joints
#: above a pin (an elbow, a collar, the chest over pinned hands or shoulder).
TARGET_SETS: tuple[tuple[str, ...], ...] = (
    ("left_wrist",), ("right_wrist",), ("left_wrist", "right_wrist"), ("head",),
    ("left_ankle",), ("left_elbow",), ("pelvis",), ("spine2",), ("left_collar",),
)  # fmt: skip
DISTANCES = (0.3, 1.0, 3.0)
#: The row of pins drawn at random: 2-6 of any joints (trunk and collars too), 1-3 other
#: joints dragged (a normal step of 0.7 m per axis), RANDOM_SETS per pose.
RANDOM_PINS, RANDOM_SETS = ("any 2-6 joints",), 40


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


#: Of one edit: farthest pin, targets' mean miss (m), pin-polished, seconds of its solve.
Row = tuple[float, float, bool, float]


def run(models: Path, poses: np.ndarray, seed: int) -> dict[tuple[str, ...], list[Row]]:
    """Per pin set: a :data:`Row` of every edit."""
    from service.engine import Engine

    engine = Engine(models, threads=1)
    rng = np.random.default_rng(seed)
    out: dict[tuple[str, ...], list[Row]] = {p: [] for p in (*PIN_SETS, RANDOM_PINS)}
    modes = list(itertools.product(("neural", "fabrik"), ("soft", "exact")))
    cases = itertools.product(PIN_SETS, TARGET_SETS, DISTANCES, modes)
    for pins, targets, dist, mode in cases:
        if set(pins) & set(targets):
            continue
        idx = np.asarray([JOINT_INDEX[j] for j in (*targets, *pins)], dtype=np.intp)
        for pose in poses:
            d = rng.normal(size=(len(targets), 3))
            step = dist * d / np.linalg.norm(d, axis=1, keepdims=True)
            out[pins].append(_edit(engine, pose, idx, step, mode))
    for pose in poses:
        for _ in range(RANDOM_SETS):
            k, m = int(rng.integers(1, 4)), int(rng.integers(2, 7))
            idx = rng.permutation(len(JOINT_INDEX))[: k + m].astype(np.intp)
            step = rng.normal(0.0, 0.7, (k, 3))
            for mode in modes:
                out[RANDOM_PINS].append(_edit(engine, pose, idx, step, mode))
    return out


def _edit(
    engine: Engine, pose: np.ndarray, idx: np.ndarray, step: np.ndarray, mode: tuple[str, str]
) -> Row:
    """One edit: the joints ``idx`` (targets, then pins), the targets moved by ``step``."""
    from service.problems import SolveProblem

    goal = pose[idx].copy()
    goal[: len(step)] += step
    floor = float(pose[:, 1].min()) - 10.0  # out of the way: pins and reach alone
    problem = SolveProblem(
        pose=pose, target_idx=idx, target_pos=goal, weights=np.ones(len(idx)),
        n_targets=len(step), method=mode[0], reach=mode[1], floor=floor,
    )  # fmt: skip
    t0 = time.perf_counter()
    res = engine.solve([problem])[0]
    took = time.perf_counter() - t0
    polished = "pin-polish" in res.solvers
    return float(res.pin_errors.max()), float(res.errors.mean()), polished, took


#: (pins, targets) on a character (canonical names; the file's own joints by its map)
CHARACTER_PINS: tuple[tuple[str, ...], ...] = (
    ("neck",), ("head",), ("left_elbow",), ("left_ankle", "right_ankle"),
    ("neck", "left_ankle", "right_ankle"),
)  # fmt: skip
CHARACTER_TARGETS: tuple[tuple[str, ...], ...] = (
    ("right_wrist",), ("left_wrist", "right_wrist"), ("head",),
)  # fmt: skip
CHARACTER_OPTIONS = ({"reach": "soft"}, {"reach": "exact"}, {"method": "fabrik", "reach": "exact"})


def run_characters(models: Path, mocap: Path, seed: int) -> dict[tuple[str, ...], list[Row]]:
    """Per pin set: a :data:`Row` of every edit (the pin measured on the character, the
    time of its solve and polish), over :mod:`bench.characters`' files, two frames each."""
    import tempfile

    from bench.characters import extract, frame_pairs, read_as
    from service.character_bvh import read_request_bvh
    from service.engine import Engine

    engine = Engine(models, threads=1)
    rng = np.random.default_rng(seed)
    out: dict[tuple[str, ...], list[Row]] = {p: [] for p in CHARACTER_PINS}
    with tempfile.TemporaryDirectory() as tmp:
        for path, units, root in extract(mocap, Path(tmp)):
            text = path.read_text(encoding="utf-8", errors="replace")
            bvh = read_request_bvh(text)
            for i, _ in frame_pairs(
                bvh.num_frames, 1.0 / bvh.frame_time, 2, np.random.default_rng(1)
            ):
                base: dict[str, object] = {"bvh": text, "frame": i, **read_as(units, root)}
                _character_frame(engine, bvh, base, rng, out)
    return out


def _character_frame(
    engine: Engine, bvh: BVH, base: dict[str, object], rng: np.random.Generator,
    out: dict[tuple[str, ...], list[Row]],
) -> None:  # fmt: skip
    """Every pin set, target set, distance and option on one frame of a file, into ``out``."""
    from core.retarget import canonical_points
    from service.bvh_models import BVHSolveRequest
    from service.character_bvh import character_from_bvh
    from service.characters import character_problem, solve_prepared

    still = [{"joint": "head", "position": [0.0, 0.0, 0.0]}]  # (the character alone)
    req = BVHSolveRequest.model_validate({**base, "targets": still})
    ch = character_from_bvh(bvh, req, req.frame)
    here = canonical_points(ch.skel, ch.pose, ch.jmap)
    label, metres = ch.jmap.describe(), ch.scale  # (metres per unit of the file)
    cases = itertools.product(CHARACTER_PINS, CHARACTER_TARGETS, (0.5, 1.5), CHARACTER_OPTIONS)
    for pins, targets, dist, options in cases:
        if set(pins) & set(targets):
            continue
        d = rng.normal(size=(len(targets), 3))
        d *= dist / metres / np.linalg.norm(d, axis=1, keepdims=True)
        idx = [JOINT_INDEX[t] for t in targets]
        asked = here[idx] + d
        moved = [
            {"joint": label[t], "position": a.tolist()} for t, a in zip(targets, asked, strict=True)
        ]
        body = {**base, "options": options, "pins": [label[p] for p in pins], "targets": moved}
        req = BVHSolveRequest.model_validate(body)
        t0 = time.perf_counter()
        edit = solve_prepared(engine, ch, character_problem(ch, req))
        took = time.perf_counter() - t0
        got = canonical_points(ch.skel, edit.pose, ch.jmap)
        held = [JOINT_INDEX[p] for p in pins]
        off = np.linalg.norm(got[held] - here[held], axis=1).max()
        miss = np.linalg.norm(got[idx] - asked, axis=1).mean()
        polished = "pin-polish" in edit.result.solvers
        out[pins].append((float(off * metres), float(miss * metres), polished, took))


def _ms(seconds: np.ndarray) -> str:
    return f"{1000 * float(np.median(seconds)):.2f}" if seconds.size else "-"


def print_table(res: dict[tuple[str, ...], list[Row]]) -> None:
    print(
        "| pins | edits | pin > 1 mm | pin > 2 mm | farthest pin (mm) | targets' mean miss (cm) "
        "| pin-polished | ms p50 (pin-polished / others) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    every = [r for rows in res.values() for r in rows]
    for pins, rows in [*res.items(), (("all",), every)]:
        off, miss, took = (np.asarray([r[i] for r in rows]) for i in (0, 1, 3))
        polished = np.asarray([r[2] for r in rows], dtype=np.bool_)
        counts = [len(off), int((off > 1e-3).sum()), int((off > 2e-3).sum())]
        far = "|" if rows is every else f"{1000 * off.max():.1f} | {100 * miss.mean():.1f}"
        print(
            f"| {' + '.join(pins)} | {' | '.join(map(str, counts))} | {far} | "
            f"{int(polished.sum())} | {_ms(took[polished])} / {_ms(took[~polished])} |"
        )


def main(
    models: Annotated[Path, typer.Option(help="Models folder (manifest.json).")] = Path("models"),
    dataset: Annotated[Path, typer.Option(help="Dataset file (format 2).")] = Path(
        "data/poses.npz"
    ),
    poses: Annotated[int, typer.Option(min=1, help="Poses per split (TEST, held-out).")] = 6,
    seed: Annotated[int, typer.Option(help="Seed of the poses and directions.")] = 0,
    characters: Annotated[bool, typer.Option(help="Users' own files instead.")] = False,
    mocap: Annotated[Path, typer.Option(help="Archives of the files.")] = Path("../shared/mocap"),
) -> None:
    """Print, per pin set, how many edits left a pin off and by how much."""
    if characters:
        print_table(run_characters(models, mocap, seed))
    else:
        print_table(run(models, sample_poses(dataset, poses, seed), seed))


if __name__ == "__main__":
    typer.run(main)
