"""A hierarchy read again is parsed once: the last files' hierarchies (``core.bvh.SHARED``,
each at most ``SHARED_TEXT`` characters) share their joints and ``BVH.memo``; a longer one
is read anew each time, so a big hierarchy pins no memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core import bvh as bvh_module
from core.bvh import SHARED, SHARED_TEXT, parse_bvh
from core.bvh_write import pose_of


def _file(joints: int, frames: int = 2, pad: int = 0) -> str:
    """A chain of ``joints`` joints (three rotation channels each, the root six), its
    hierarchy ``pad`` blank characters longer, and ``frames`` frames of distinct values."""
    lines = ["HIERARCHY", "ROOT Hips", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]  # fmt: skip
    for k in range(1, joints):
        lines += [f"JOINT J{k}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * joints
    channels = 6 + 3 * (joints - 1)
    rows = [" ".join(f"{(f + 1) * (c + 1) % 17:g}" for c in range(channels)) for f in range(frames)]
    return (
        "\n".join([*lines, " " * pad, "MOTION", f"Frames: {frames}", "Frame Time: 0.04", *rows])
        + "\n"
    )


def test_a_hierarchy_read_again_shares_its_joints_and_memo_and_its_frames_are_its_own() -> None:
    bvh_module._shared.cache_clear()
    a, b = parse_bvh(_file(5, frames=2), "bvh"), parse_bvh(_file(5, frames=3), "bvh", [2])
    assert a.joints is b.joints and a.memo is b.memo
    # each file's frames are its own: the shared layout reads each file's rows
    assert not np.array_equal(pose_of(a, 1).rotations, pose_of(b, 2).rotations)
    assert "layout" in a.memo and a.memo["layout"] is b.memo["layout"]
    # ... read-only, so no reader changes another file's
    with pytest.raises(ValueError, match="read-only"):
        a.memo["layout"].offsets[0, 0] = 1.0  # type: ignore[attr-defined]
    # another hierarchy, or the same one under another file name (errors name the file), not
    c, d = parse_bvh(_file(6), "bvh"), parse_bvh(_file(5), "other.bvh")
    assert c.memo is not a.memo and d.memo is not a.memo and c.joints is not a.joints


def test_only_the_last_hierarchies_and_only_small_ones_are_kept() -> None:
    bvh_module._shared.cache_clear()
    first = parse_bvh(_file(3), "bvh")
    for k in range(SHARED):  # as many other hierarchies: the first is dropped
        parse_bvh(_file(4 + k), "bvh")
    assert parse_bvh(_file(3), "bvh").memo is not first.memo
    assert bvh_module._shared.cache_info().currsize == SHARED
    # a hierarchy past SHARED_TEXT characters is read anew, and not kept
    big = _file(3, pad=SHARED_TEXT)
    assert parse_bvh(big, "bvh").memo is not parse_bvh(big, "bvh").memo
    assert bvh_module._shared.cache_info().currsize == SHARED


def test_a_real_file_read_from_its_hierarchy_kept_is_read_as_it_was(
    bvh_files: dict[str, Path],
) -> None:
    """Every value of every frame of a real file the same, read cold or warm."""
    text = bvh_files["cmu-daz-salsa"].read_text()
    bvh_module._shared.cache_clear()
    cold = parse_bvh(text, "bvh")
    warm = parse_bvh(text, "bvh")
    assert warm.joints is cold.joints
    assert np.array_equal(cold.motion, warm.motion)
    assert [j.name for j in warm.joints] == [j.name for j in cold.joints]
