"""The BVH writer keeps the user's file: an edited frame's values are written where they
stand, whatever the layout of the frames (wrapped over lines, CRLF, a byte order mark,
blank lines), and a value the edit did not move keeps its text (real files; the layouts
made from them here)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from core.bvh import BVH, parse_bvh
from core.bvh_write import DECIMALS, KEPT, pose_of, row_of, splice_frames
from core.characters import Pose
from core.euler import euler_matrices


def raw(path: Path) -> str:
    """A file's text as sent (``read_text`` would turn CRLF into LF)."""
    return path.read_bytes().decode("utf-8")


def relaid(text: str, per_line: int, newline: str = "\n", bom: bool = False) -> str:
    """``text`` with its MOTION block's values ``per_line`` a line (frames wrapped over
    lines, or several on one), lines ended by ``newline``, a byte order mark if ``bom``."""
    time_line = re.search(r"Frame Time:[^\n]*\n", text)
    assert time_line is not None
    head, words = text[: time_line.end()], text[time_line.end() :].split()
    lines = [" ".join(words[i : i + per_line]) for i in range(0, len(words), per_line)]
    out = head.replace("\r\n", "\n") + "\n".join(lines) + "\n"
    return ("\ufeff" if bom else "") + out.replace("\n", newline)


def edited_values(bvh: BVH, frame: int) -> tuple[np.ndarray, list[int]]:
    """Frame ``frame``'s row with a few channels moved by whole degrees (units)."""
    row = bvh.row(frame).copy()
    columns = [0, 4, bvh.num_channels // 2, bvh.num_channels - 1]
    row[columns] += [1.25, -2.5, 3.0, 0.125]
    return row, columns


def assert_only_values_changed(
    old: str, new: str, bvh: BVH, frame: int, columns: list[int]
) -> None:
    """``new`` is ``old`` with the words of ``columns`` of ``frame`` rewritten, and nothing
    else: same bytes before the first and after the last, the same words elsewhere."""
    span = bvh.frame_span(frame)
    assert span is not None
    start, end = span
    grow = len(new) - len(old)
    assert new[:start] == old[:start] and new[end + grow :] == old[end:]
    before, after = old[start:end], new[start : end + grow]
    assert re.split(r"\S+", before) == re.split(r"\S+", after)  # the spacing, line ends too
    old_words, new_words = before.split(), after.split()
    assert len(old_words) == len(new_words) == bvh.num_channels
    assert [
        k for k, (a, b) in enumerate(zip(old_words, new_words, strict=True)) if a != b
    ] == columns


#: name -> (values a line, 0: two frames; line end; a byte order mark)
LAYOUTS: dict[str, tuple[int, str, bool]] = {
    "wrapped-11-crlf-bom": (11, "\r\n", True),
    "wrapped-7-lf": (7, "\n", False),
    "two-frames-a-line": (0, "\r\n", False),
}


@pytest.mark.parametrize("layout", list(LAYOUTS))
@pytest.mark.parametrize("name", ["cmu-daz-salsa", "bandai", "reactidle-6ch"])
def test_a_frame_not_one_a_line_is_spliced_where_it_stands(
    bvh_files: dict[str, Path], name: str, layout: str
) -> None:
    """An audit (2026-12-06, D4): a file whose frames were not one a line (values wrapped
    over lines, CRLF, a byte order mark) came back written whole: LF, no BOM, tabs, every
    OFFSET and every value of every frame in another form. Now only the edited values
    change, and the frame is read alone (bit for bit as a whole read reads it)."""
    per_line, newline, bom = LAYOUTS[layout]
    whole = parse_bvh(raw(bvh_files[name]), name)
    text = relaid(raw(bvh_files[name]), per_line or 2 * whole.num_channels, newline, bom)
    frame = whole.num_frames // 2 + 1
    bvh = parse_bvh(text, name, frames=[frame])
    assert bvh.read == frozenset({frame})  # (it was read whole)
    assert bvh.row(frame).tobytes() == whole.row(frame).tobytes()
    assert bvh.frame_span(frame) == parse_bvh(text, name).frame_span(frame)
    row, columns = edited_values(bvh, frame)
    out = splice_frames(bvh, {frame: (row, columns)})
    assert_only_values_changed(text, out, bvh, frame, columns)
    assert out.startswith("\ufeff") == text.startswith("\ufeff")
    assert out.count("\r\n") == text.count("\r\n") and out.count("\n") == text.count("\n")
    again = parse_bvh(out, name)
    expect = whole.motion.copy()
    expect[frame, columns] = np.round(row[columns], DECIMALS)
    np.testing.assert_array_equal(again.motion, expect)


@pytest.mark.parametrize("layout", ["one-a-line", *LAYOUTS])
@pytest.mark.parametrize("name", ["cmu-daz-salsa", "reactidle-6ch"])
def test_frames_spliced_together_are_frames_spliced_one_by_one(
    bvh_files: dict[str, Path], name: str, layout: str
) -> None:
    """A clip's edits (``/v1/bvh/solve/batch``) are written in one pass over the file, by
    frame spans found in one pass, whether the reader read those frames alone or the whole
    block: the same text as splicing them in one after another, in any order; a frame
    edited by no value is left as it stands."""
    text = raw(bvh_files[name])
    if layout != "one-a-line":
        per_line, newline, bom = LAYOUTS[layout]
        n = parse_bvh(text, name).num_channels
        text = relaid(text, per_line or 2 * n, newline, bom)
    frames = [7, 0, 3, 8, 1]  # (out of order; neighbours, the first)
    alone = parse_bvh(text, name, frames=frames)
    whole = parse_bvh(text, name)
    edits = {f: edited_values(whole, f) for f in frames}
    edits[3] = (whole.row(3), [])  # (nothing to write)
    one_by_one = text
    for f in frames:
        one_by_one = splice_frames(parse_bvh(one_by_one, name, frames=[f]), {f: edits[f]})
    assert splice_frames(alone, edits) == one_by_one
    assert splice_frames(whole, edits) == one_by_one
    assert whole.frame_spans(frames) == alone.frame_spans(frames)
    again = parse_bvh(one_by_one, name).motion
    changed = sorted({f for f, (_, cols) in edits.items() if cols})
    assert sorted(set(np.flatnonzero((again != whole.motion).any(axis=1)))) == changed
    with pytest.raises(IndexError, match="frame 99999 out of range"):
        splice_frames(whole, {**edits, 99999: edits[0]})


def test_blank_lines_among_frames_keep_their_place(bvh_files: dict[str, Path]) -> None:
    text = raw(bvh_files["bandai"])
    at = text.index("Frame Time:")
    lines = text[at:].split("\n")
    body = "\n".join(ln if k % 3 else ln + "\n  \t" for k, ln in enumerate(lines))
    spaced = text[:at] + body
    bvh = parse_bvh(spaced, "spaced", frames=[10])
    assert bvh.read == frozenset({10})
    row, columns = edited_values(bvh, 10)
    out = splice_frames(bvh, {10: (row, columns)})
    assert_only_values_changed(spaced, out, bvh, 10, columns)


def test_a_frame_posed_as_it_stands_writes_nothing(bvh_files: dict[str, Path]) -> None:
    """An audit (2026-12-06, D6): the writer compared the new angles, rounded, with the
    old unrounded ones, so a value of ``-9.35e-15`` (CMU salsa's) always counted as changed
    and was written ``-0.000000``. The frame's own pose, every joint said changed, now
    writes no value, in every real file."""
    for name, path in bvh_files.items():
        bvh = parse_bvh(raw(path), name)
        for frame in (0, 5, bvh.num_frames - 1):
            row, columns = row_of(bvh, frame, pose_of(bvh, frame), set(range(len(bvh.joints))))
            assert columns == [], (name, frame, columns)
            assert row.tobytes() == bvh.row(frame).tobytes()
            assert splice_frames(bvh, {frame: (row, columns)}) == bvh.text


def test_a_value_is_written_when_it_moves_by_more_than_the_rounding(
    bvh_files: dict[str, Path],
) -> None:
    """Half a unit of the written precision: within it, the old text says the new value as
    well as the rewritten one would and is kept; past it, the value is written. A turn of
    a few millionths of a degree is no less written than a large one."""
    bvh = parse_bvh(raw(bvh_files["cmu-daz-salsa"]), "salsa")
    frame = 5
    j = bvh.index("lForeArm")
    joint = bvh.joints[j]
    cols = [joint.channel_start + k for k in range(3)]
    for shift, written in ((0.4 * KEPT, False), (3 * KEPT, True), (2e-3, True)):
        angles = bvh.row(frame)[cols] + [shift, 0.0, 0.0]
        pose = pose_of(bvh, frame)
        rot = pose.rotations.copy()
        rot[j] = euler_matrices(joint.rotation_order, np.deg2rad(angles))
        row, columns = row_of(bvh, frame, Pose(rot, pose.translations), {j})
        assert columns == (cols[:1] if written else []), (shift, columns)
        if written:
            assert row[cols[0]] == float(f"{angles[0]:.{DECIMALS}f}")
        assert row[cols[1:]].tobytes() == bvh.row(frame)[cols[1:]].tobytes()


def _nearest_one(seq: str, matrix: np.ndarray, old: np.ndarray) -> np.ndarray:
    """The writer's Euler angles of one joint as it found them joint by joint until
    2026-12-06 (kept here as the reference of the product over all of a frame's joints):
    both solutions turned towards the old angles, the first that gives the matrix back
    with the least largest change (the first on a tie; the first where neither does)."""
    from core.euler import euler_angles

    first = np.rad2deg(euler_angles(seq, matrix))
    a, b, c = first
    other = np.array([a + 180.0, -b if seq[0] == seq[2] else 180.0 - b, c + 180.0])
    best, best_cost = first, np.inf
    cands = old + (np.stack([first, other]) - old + 180.0) % 360.0 - 180.0
    for cand, back in zip(cands, euler_matrices(seq, np.deg2rad(cands)), strict=True):
        if not (np.abs(back - matrix) <= 1e-9 + 1e-5 * np.abs(matrix)).all():
            continue
        cost = float(np.abs(cand - old).max())
        if cost < best_cost:
            best, best_cost = cand, cost
    return np.asarray(best, dtype=np.float64)


def test_a_frame_s_angles_in_one_product_are_each_joint_s_alone(
    bvh_files: dict[str, Path],
) -> None:
    """``row_of`` finds the Euler angles of all of a frame's changed joints of one channel
    order in one product (``_nearest_euler`` over ``[n, 3, 3]``): bit for bit each joint's
    alone, on real frames of five studios' files turned at random (every joint), and on
    matrices in gimbal lock and next to it in every order (where the two solutions tie,
    or neither gives the matrix back as the tolerance reads it)."""
    from core.bvh_write import _nearest_euler

    rng = np.random.default_rng(7)
    checked = 0
    for name, path in bvh_files.items():
        bvh = parse_bvh(raw(path), name)
        for frame in rng.choice(bvh.num_frames, 6, replace=False):
            row = bvh.row(int(frame))
            for j in bvh.joints:
                seq = j.rotation_order
                if len(seq) != 3:
                    continue
                cols = [j.channel_start + k for k, c in enumerate(j.channels)
                        if c.lower().endswith("rotation")]  # fmt: skip
                turn = euler_matrices(seq, rng.uniform(-np.pi, np.pi, (5, 3)))
                old = np.broadcast_to(row[cols], (5, 3))
                got = _nearest_euler(seq, turn, old)
                want = np.stack([_nearest_one(seq, m, o) for m, o in zip(turn, old, strict=True)])
                assert got.tobytes() == want.tobytes(), (name, j.name)
                checked += 5
    for seq in ("ZXY", "XYZ", "ZYX", "YXZ", "XZY", "YZX", "ZXZ", "XYX"):
        bounds = (
            (0.0, 180.0, 1e-8, 180 - 1e-8, 90.0)
            if seq[0] == seq[2]
            else (90.0, -90.0, 90 - 1e-7, -90 + 1e-9, 45.0)
        )
        angles = np.array([(a, b, c) for b in bounds for a in (-179.9, 0.0, 60.0, 179.99)
                           for c in (-170.0, 0.0, 180.0)])  # fmt: skip
        turn = euler_matrices(seq, np.deg2rad(angles))
        old = angles + 360.0 * rng.integers(-2, 3, angles.shape)
        got = _nearest_euler(seq, turn, old)
        want = np.stack([_nearest_one(seq, m, o) for m, o in zip(turn, old, strict=True)])
        assert got.tobytes() == want.tobytes(), seq
        checked += len(angles)
    assert checked > 1000
