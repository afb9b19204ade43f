"""Cleaning a whole clip: does a smooth drag give a smooth answer?
``python -m bench.clips [FILE.bvh ...] [--frames 240] [--serving K=V]``; with no file, the
twelve of ``bench.characters.DEFAULT_FILES`` (ten bodies no model was trained on, two of
the training studios') taken out of ``--mocap`` (``../shared/mocap``).

A clean-up user sends every frame of a clip as one batch: each frame's own pose is the
start, one joint's target is where that frame has it plus a smooth offset (seeded; up to
about 15 cm, a few millimetres a frame), and a lone wrist keeps both feet pinned, as a
fix of a reach keeps the feet planted. Each frame is solved alone (``Engine.solve_arrays``
over the clip, frames at about 30 per second), so nothing carries the answer of one frame
to the next: what keeps the answers in step is that the solve is continuous in its start
and targets. Per set and method, over every frame step of every clip:

* the edit's (answer minus the frame's own pose) largest change from one frame to the
  next, over the 21 joints, mm;
* jumps: steps whose edit changes more than :data:`JUMP` and more than :data:`GAIN` times
  the motion (the frame's largest joint step plus the offset's step; its p99 and max are
  printed beside);
* flips: an arm or leg bent 5 cm or more in both frames whose bend turns to the other side
  (more than a right angle) between them (:func:`flips`; the clips' own, beside): an
  elbow or knee swapping sides between two nearly equal edits (``serving.bend_side``,
  docs/generalisation-3.md item 52);
* and over every frame, the dragged targets' miss (the farthest one's distance): its mean
  and the frames missing by more than 1 cm (a smoother answer that leaves its target is
  no cleaner clip: ``options.soft_ik``, item 56).
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from bench.characters import Files, Mocap, Models, Serving, unreadable
from core.ends import across
from core.skeleton import JOINT_INDEX, NUM_JOINTS

app = typer.Typer(add_completion=False)

#: (name, dragged joints, pinned joints) of each edit set
SETS: tuple[tuple[str, tuple[str, ...], tuple[str, ...]], ...] = (
    ("L wrist, feet pinned", ("left_wrist",), ("left_ankle", "right_ankle")),
    ("R wrist", ("right_wrist",), ()),
    ("L ankle", ("left_ankle",), ()),
    ("R elbow", ("right_elbow",), ()),
    ("L wrist + R wrist", ("left_wrist", "right_wrist"), ()),
)
#: (column, solve_arrays options)
METHODS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("FABRIK", {"fabrik": True, "exact": True}),
    ("soft", {}),
    ("exact", {"exact": True}),
    ("soft, soft_ik 1 cm", {"soft_ik": 0.01}),
    ("exact, soft_ik 1 cm", {"exact": True, "soft_ik": 0.01}),
)
#: A jump: a frame step whose edit changes more than JUMP (m) and GAIN times the motion
#: (the frame's largest joint step plus the offset's step).
JUMP, GAIN = 0.03, 3.0


def clip_points(path: Path, units: str | float | None, root: str, frames: int) -> np.ndarray:
    """The clip's frames (about 30 a second, at most ``frames``) as the service's 21
    points ``[F, 21, 3]``, metres, +Y up, as ``/v1/bvh/solve`` reads them."""
    from bench.characters import file_character, frame_points
    from service.character_bvh import read_request_bvh

    text = path.read_text(encoding="utf-8", errors="replace")
    bvh = read_request_bvh(text)
    ch, _ = file_character(bvh, text, 0, units, root)
    step = max(1, round(1.0 / (30.0 * bvh.frame_time)))
    picked = range(0, bvh.num_frames, step)[:frames]
    return np.stack([ch.to_service(frame_points(ch, bvh, f, root)) for f in picked])


def offsets(n: int, rng: np.random.Generator) -> np.ndarray:
    """A smooth offset path ``[n, 3]`` (m): each axis a sine of its own period (2-4 s at
    30 frames a second) and phase, up to 0.15 m (0.1 across)."""
    t = np.arange(n) / 30.0
    period = rng.uniform(2.0, 4.0, 3)
    phase = rng.uniform(0.0, 2.0 * np.pi, 3)
    amp = np.asarray([0.1, 0.15, 0.15])
    return amp * np.sin(2.0 * np.pi * t[:, None] / period + phase)


#: The limbs whose side is watched: (top, middle, end) joints of both arms and legs.
LIMBS = np.asarray(
    [[JOINT_INDEX[f"{side}_{j}"] for j in joints] for side in ("left", "right")
     for joints in (("shoulder", "elbow", "wrist"), ("hip", "knee", "ankle"))]
)  # fmt: skip
#: A flip: a limb bent by at least FLIP_BEND (m) in two frames running whose bend side turns
#: by more than a right angle between them.
FLIP_BEND = 0.05


def flips(poses: np.ndarray) -> np.ndarray:
    """Per frame step ``[F - 1]``, how many of the four limbs flip (:data:`FLIP_BEND`)."""
    top, mid, end = (poses[:, LIMBS[:, k]] for k in range(3))  # [F, 4, 3]
    axis = end - top
    axis /= np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
    bend = across(mid - top, axis)
    size = np.linalg.norm(bend, axis=-1)
    big = (size[1:] >= FLIP_BEND) & (size[:-1] >= FLIP_BEND)
    turned = np.sum(bend[1:] * bend[:-1], axis=-1) < 0.0
    return np.asarray(np.sum(big & turned, axis=-1))


def edit_steps(engine: Any, points: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    """Per set, ``[F - 1]`` per frame step: per method the edit's change (largest joint,
    m) and its flips (``"<method> flips"``), the motion (``motion``, m) and the clip's own
    flips (``clip flips``)."""
    n = len(points)
    moved = np.linalg.norm(np.diff(points, axis=0), axis=-1).max(axis=-1)
    out: dict[str, Any] = {}
    for name, dragged, pinned in SETS:
        idx = [JOINT_INDEX[j] for j in dragged + pinned]
        off = np.stack([offsets(n, rng) for _ in dragged], axis=1)  # [F, k, 3]
        goal = points[:, idx].copy()
        goal[:, : len(dragged)] += off
        steps = {"motion": moved + np.linalg.norm(np.diff(off, axis=0), axis=-1).max(axis=-1)}
        for column, options in METHODS:
            ans = engine.solve_arrays(
                points, np.tile(idx, (n, 1)), goal, n_targets=len(dragged), **options
            )
            edit = np.asarray(ans.pose) - points
            steps[column] = np.linalg.norm(np.diff(edit, axis=0), axis=-1).max(axis=-1)
            steps[f"{column} flips"] = flips(np.asarray(ans.pose))
            steps[f"{column} miss"] = np.asarray(ans.errors)[:, : len(dragged)].max(axis=-1)
        steps["clip flips"] = flips(points)
        out[name] = steps
    return out


def table(rows: dict[str, dict[str, list[np.ndarray]]]) -> list[str]:
    """Markdown lines: per set, the frame steps, the motion's p99 and max (mm) and the
    clip's own flips; per column the edit's largest step (mm), the jumps (steps beyond
    :data:`JUMP` and :data:`GAIN` times the motion), the flips (:func:`flips`) and the
    dragged targets' miss: its mean (mm) and the frames missing by more than 1 cm."""
    cols = [c for c, _ in METHODS]
    head = ["set", "frame steps", "motion p99 / max mm", "clip flips",
            *(f"{c}: step max mm / jumps / flips / miss mm / > 1 cm" for c in cols)]  # fmt: skip
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, per in rows.items():
        motion = np.concatenate(per["motion"])
        p99, most = np.percentile(motion, 99) * 1000, motion.max() * 1000
        cells = [str(len(motion)), f"{p99:.1f} / {most:.1f}",
                 str(int(np.concatenate(per["clip flips"]).sum()))]  # fmt: skip
        for c in cols:
            s = np.concatenate(per[c])
            jumps = int(((s > JUMP) & (s > GAIN * motion)).sum())
            flipped = int(np.concatenate(per[f"{c} flips"]).sum())
            miss = np.concatenate(per[f"{c} miss"])
            cells.append(f"{s.max() * 1000:.0f} / {jumps} / {flipped} / "
                         f"{miss.mean() * 1000:.1f} / {int((miss > 0.01).sum())}")  # fmt: skip
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def score(engine: Any, todo: Sequence[tuple[Path, str | float | None, str]], frames: int,
          seed: int) -> dict[str, dict[str, list[np.ndarray]]]:  # fmt: skip
    """Every file's edit steps, pooled per set and column."""
    rng = np.random.default_rng(seed)
    rows: dict[str, dict[str, list[np.ndarray]]] = {}
    for path, units, root in todo:
        with unreadable(path):
            points = clip_points(path, units, root, frames)
        if len(points) < 2:
            raise typer.BadParameter(f"{path}: {len(points)} frame; a clip needs 2 or more",
                                     param_hint="FILES")  # fmt: skip
        assert points.shape[1:] == (NUM_JOINTS, 3)
        for name, steps in edit_steps(engine, points, rng).items():
            for column, s in steps.items():
                rows.setdefault(name, {}).setdefault(column, []).append(s)
    return rows


@app.command()
def main(
    files: Files = None,
    mocap: Mocap = Path("../shared/mocap"),
    models: Models = Path("models"),
    frames: Annotated[int, typer.Option(min=3, max=100_000, help="frames per clip")] = 240,
    seed: Annotated[int, typer.Option(help="seed of the offset paths")] = 0,
    serving: Serving = None,
) -> None:
    from bench.characters import extract
    from bench.heldout import engine_for

    engine = engine_for(models, serving)
    with tempfile.TemporaryDirectory() as tmp:
        todo = [(p, None, "replace") for p in files] if files else extract(mocap, Path(tmp))
        rows = score(engine, todo, frames, seed)
    given = "".join(f" --serving {s}" for s in serving or [])
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    print(f"Written by `python -m bench.clips{given}` ({when}, models {engine.version}).\n")
    print("\n".join(table(rows)))


if __name__ == "__main__":
    app()
