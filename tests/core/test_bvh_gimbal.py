"""A joint at gimbal lock turned by next to nothing keeps its angles (``core.bvh_write``).

An audit (2026-12-07) set the FAIR child's ``Spine`` (Xrotation Yrotation Zrotation) to
X 35, Y 90, Z -20 and dragged a wrist 0.01 inch: the polish turned the spine 0.002
degrees, and the nearest exact Euler angles of that rotation were X 119.4, Z -104.4 (at
Y = 90 only X + Z is fixed by the rotation, and just off it each is, ill-conditioned).
Now a turn under ``STILL_TURN`` whose angles would move more than ``LOCKED`` keeps the
old angles; a real turn is written as before.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from core.bvh import parse_bvh
from core.bvh_write import STILL_TURN, pose_of, row_of
from core.euler import euler_matrices
from tests.character_files import FILES
from tests.core.test_bvh_write import raw


def _locked_file(path: Path, frame: int) -> tuple[str, int, list[int]]:
    """The FAIR child's file with its Spine at X 35, Y 90, Z -20 in ``frame``: the text,
    the Spine's index and its rotation columns."""
    text = raw(path)
    bvh = parse_bvh(text)
    spine = next(i for i, j in enumerate(bvh.joints) if j.name == "Spine")
    j = bvh.joints[spine]
    cols = [j.channel_start + k for k, c in enumerate(j.channels) if c.endswith("rotation")]
    assert [j.channels[c - j.channel_start] for c in cols] == [
        "Xrotation",
        "Yrotation",
        "Zrotation",
    ]
    lines = text.split("\n")
    at = lines.index("MOTION") + 3 + frame
    words = lines[at].split()
    for c, v in zip(cols, ("35", "90", "-20"), strict=True):
        words[c] = v
    lines[at] = " ".join(words)
    return "\n".join(lines), spine, cols


def test_a_locked_joint_turned_by_next_to_nothing_keeps_its_angles(
    bvh_files: dict[str, Path],
) -> None:
    frame = FILES["fair1-child-inches-zup"][3]
    text, spine, cols = _locked_file(bvh_files["fair1-child-inches-zup"], frame)
    bvh = parse_bvh(text)
    pose = pose_of(bvh, frame)
    for degrees, kept in [(0.002, True), (0.5 * STILL_TURN, True), (0.5, False), (5.0, False)]:
        turned = pose.copy()
        turn = Rotation.from_rotvec(np.radians(degrees) * np.array([0.6, 0.0, 0.8]))
        turned.rotations[spine] = turned.rotations[spine] @ turn.as_matrix()
        row, columns = row_of(bvh, frame, turned, {spine})
        if kept:  # the old angles, text and all
            assert not set(columns) & set(cols), degrees
            np.testing.assert_array_equal(row[cols], [35.0, 90.0, -20.0])
        else:  # the rotation asked, to the written precision
            assert set(cols) <= set(columns), degrees
            back = euler_matrices("XYZ", np.radians(row[cols]))
            np.testing.assert_allclose(back, turned.rotations[spine], atol=1e-7)
    # an unlocked joint turned 0.002 degrees is written as turned (no angle moves far)
    free = pose_of(parse_bvh(raw(bvh_files["fair1-child-inches-zup"])), frame)
    turned = free.copy()
    turn = Rotation.from_rotvec(np.radians(0.002) * np.array([0.6, 0.0, 0.8]))
    turned.rotations[spine] = turned.rotations[spine] @ turn.as_matrix()
    original = parse_bvh(raw(bvh_files["fair1-child-inches-zup"]))
    row, columns = row_of(original, frame, turned, {spine})
    assert set(cols) & set(columns)
