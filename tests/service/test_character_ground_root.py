"""A ground root above the hips is left as it was: Bandai-Namco's ``joint_Root``.

The studio's files put ``joint_Root`` on the floor above ``Hips`` and leave it the identity
in every frame; the hips carry their own position channels. An audit found 14 of 24
ordinary edits of one clip turning the root, by up to 10.9 degrees (the polish turned
every joint above a target or pin, ``core.reach``). Edits of the real file through the
service: the root's six values are written back as they were, every other frame too.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from core.bvh import parse_bvh
from core.bvh_write import pose_of, skeleton_of
from core.characters import forward_kinematics
from tests.character_files import FILES

#: (joint, move in cm, reach, pins): hands, head and hips, soft and exact, pinned or not
EDITS = [
    ("Hips", (8.0, -12.0, 4.0), "soft", ["Foot_L", "Foot_R"]),
    ("Hips", (-6.0, -8.0, 10.0), "exact", ["Foot_L", "Foot_R", "Toes_L", "Toes_R"]),
    ("Head", (10.0, -5.0, 8.0), "soft", ["Foot_L", "Foot_R"]),
    ("Head", (-8.0, 0.0, 12.0), "exact", []),
    ("Hand_R", (12.0, 10.0, -15.0), "soft", []),
    ("Hand_L", (-15.0, 8.0, 10.0), "exact", ["Foot_L", "Foot_R"]),
]


def test_edits_leave_the_ground_root_as_it_was(client: Any, bvh_files: dict[str, Path]) -> None:
    text = bvh_files["bandai"].read_text()
    frame = FILES["bandai"][3]
    bvh = parse_bvh(text)
    root = bvh.joints[0]
    assert root.name == "joint_Root" and bvh.joints[1].name == "Hips"
    cols = slice(root.channel_start, root.channel_start + len(root.channels))
    assert not bvh.motion[:, 3:6].any()  # the identity in every frame of the clip
    pos = _positions(text, frame)
    turned = 0
    for joint, move, reach, pins in EDITS:
        body = {
            "bvh": text,
            "frame": frame,
            "targets": [{"joint": joint, "position": (pos[joint] + np.array(move)).tolist()}],
            "pins": pins,
            "options": {"reach": reach},
        }
        r = client.post("/v1/bvh/solve", json=body)
        assert r.status_code == 200, r.text
        out = r.json()
        assert "joint_Root" not in out["changed_joints"], (joint, reach)
        new = parse_bvh(out["bvh"])
        assert new.motion[frame, cols].tobytes() == bvh.motion[frame, cols].tobytes()
        assert np.array_equal(np.delete(new.motion, frame, 0), np.delete(bvh.motion, frame, 0))
        assert all(p["reached"] for p in out["pins"])
        turned += "Hips" in out["changed_joints"]
    assert turned == len(EDITS)  # the hips carry the body instead


def _positions(text: str, frame: int) -> dict[str, np.ndarray]:
    """Every joint's world position at ``frame`` (the file's units)."""
    bvh = parse_bvh(text)
    skel = skeleton_of(bvh)
    _, g_pos = forward_kinematics(skel, pose_of(bvh, frame))
    return dict(zip(skel.names, g_pos, strict=True))
