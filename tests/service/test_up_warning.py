"""``up`` left to the service is inferred from the rest pose (docs/characters.md, "Units and
up axis inferred"); where the frame edited stands up along the other axis (a rig whose
Z-up offsets its root turns upright along +Y, or a body lying down in a frame) the answer
says so in ``up_warning``, naming the ``up`` that reads the frame upright. An audit
(2026-12-06) found such a rig solved lying down without a word: 1.1 mm short with exact
reach, up to 7.6 cm from the upright answer."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from core.bvh import parse_bvh
from core.bvh_write import pose_of
from core.euler import euler_angles
from tests.conftest import REPO_ROOT

#: Z-up -> Y-up: a quarter turn about X
TO_Y = Rotation.from_euler("x", -90, degrees=True)


def turned_frame(text: str, frame: int) -> str:
    """``text`` (the Z-up child, its root's channels position then rotation) with frame
    ``frame``'s root turned a quarter turn about X: the same pose standing along +Y."""
    bvh = parse_bvh(text)
    root = bvh.joints[0]
    row = bvh.row(frame).copy()
    m = TO_Y.as_matrix()
    rot = m @ pose_of(bvh, frame).rotations[0]
    pos = [root.channel_start + k for k, c in enumerate(root.channels) if "position" in c]
    angles = [root.channel_start + k for k, c in enumerate(root.channels) if "rotation" in c]
    row[pos] = m @ row[pos]
    row[angles] = np.rad2deg(euler_angles(root.rotation_order, rot))
    lines = text.split("\n")
    at = next(i for i, line in enumerate(lines) if line.startswith("Frame Time")) + 1 + frame
    lines[at] = " ".join(f"{v:.6f}" for v in row)
    return "\n".join(lines)


def test_a_file_turned_upright_by_its_root_is_told_its_up(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """The Z-up child with one frame turned to stand along +Y: ``up`` omitted is read as
    the rest pose says (+Z) and the answers say the frame stands along +Y; ``"up": "+Y"``
    as the warning advises reaches the target with no warning; the frames not turned, and
    the file read right, carry none (inspect, solve, and each edit of a clip)."""
    text = turned_frame(bvh_files["fair1-child-inches-zup"].read_text(), 40)
    bvh = parse_bvh(text)
    hand = bvh.forward_kinematics(["LeftHand"], np.array([40]))[0, 0]
    goal = (hand + np.array([3.0, 2.0, 6.0])).tolist()  # inches
    ask = {"bvh": text, "frame": 40, "units": "in", "pins": ["LeftFoot", "RightFoot"],
           "targets": [{"joint": "LeftHand", "position": goal}],
           "options": {"reach": "exact"}}  # fmt: skip
    said = client.post("/v1/bvh/solve", json=ask).json()
    assert said["up"] == "+Z"
    assert re.search(r"^up: inferred '\+Z' from the rest pose .* stands up along \+Y .* "
                     r'give "up": "\+Y"', said["up_warning"]), said["up_warning"]  # fmt: skip
    looked = client.post("/v1/bvh/inspect", json={"bvh": text, "frame": 40, "units": "in"})
    assert looked.json()["up_warning"] == said["up_warning"]
    upright = client.post("/v1/bvh/solve", json={**ask, "up": "+Y"}).json()
    assert upright["up_warning"] is None and upright["targets"][0]["reached"] is True
    plain = client.post("/v1/bvh/solve", json={**ask, "frame": 41}).json()
    assert plain["up"] == "+Z" and plain["up_warning"] is None
    edits = [{k: ask[k] for k in ("targets", "pins", "options")} | {"frame": f} for f in (40, 41)]
    clip = client.post("/v1/bvh/solve/batch", json={"bvh": text, "units": "in", "edits": edits})
    assert [e["up_warning"] for e in clip.json()["edits"]] == [said["up_warning"], None]


def test_a_json_rig_turned_upright_by_its_root_is_told_its_up(client: Any) -> None:
    """The docs' rig written with Z-up offsets (and local turns) under a root that turns
    it upright along +Y: ``up: null`` reads it as +Z and says so at ``character.up``; ``+Y``
    answers the plain rig's rotations, without a warning."""
    body = json.loads((REPO_ROOT / "docs/examples/solve_character.json").read_text())
    to_z = TO_Y.inv()
    turned = json.loads(json.dumps(body))
    joints = turned["character"]["joints"]
    for j in joints:
        j["offset"] = to_z.apply(j["offset"]).tolist()
        if j["parent"] is None:
            j["parent"] = "Armature"
    joints.insert(0, {"name": "Armature", "parent": None, "offset": [0.0, 0.0, 0.0]})
    turned["rotations"] = {
        name: (to_z * Rotation.from_quat(q) * TO_Y).as_quat().tolist()
        for name, q in body["rotations"].items()
    }
    turned["rotations"]["Armature"] = TO_Y.as_quat().tolist()
    turned["root_position"] = [0.0, 0.0, 0.0]
    turned["character"]["joints"][1]["offset"] = to_z.apply(body["root_position"]).tolist()
    guessed = client.post(
        "/v1/solve", json={**turned, "character": {**turned["character"], "up": None}}
    )
    said = guessed.json()
    assert said["up"] == "+Z", said
    assert said["up_warning"].startswith("character.up: inferred '+Z' from the rest pose"), said
    upright = client.post("/v1/solve", json=turned).json()  # (the form's default: +Y)
    plain = client.post("/v1/solve", json=body).json()
    assert upright["up_warning"] is None and plain["up_warning"] is None
    for name, at in plain["positions"].items():  # the same body, where it stands
        assert np.allclose(upright["positions"][name], at, atol=1e-9), name
    assert [t["reached"] for t in upright["targets"]] == [True]


def test_an_up_the_frame_does_not_stand_along_is_said_where_the_rest_pose_cannot_tell(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """An API audit (2026-12-07): a Bandai-Namco walk (+Y up; its rest pose stands along
    neither axis) sent with ``"up": "+Z"`` was solved lying down without a word. The
    answer now says the frame stands along +Y; ``"+Y"`` stated (or inferred) says nothing."""
    text = bvh_files["bandai"].read_text()
    frame = 30
    for up, told in (("+Z", True), ("+Y", False), (None, False)):
        ask: dict[str, Any] = {"bvh": text, "frame": frame}
        if up is not None:
            ask["up"] = up
        out = client.post("/v1/bvh/inspect", json=ask)
        assert out.status_code == 200, out.text
        warning = out.json().get("up_warning")
        if told:
            assert warning is not None and 'give "up": "+Y"' in warning, warning
            assert "solved lying down" in warning
        else:
            assert warning is None, (up, warning)
