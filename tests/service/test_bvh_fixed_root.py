"""A BVH file none of whose joints at or above the pelvis has three position channels (a
root of rotations alone) cannot move its body: a target the body must travel to is met
by turns alone, and the answers' ``root_warning`` says so (it said nothing: a pelvis
dragged 10 cm came back unmoved, ``changed_joints`` empty, ``reached: false``, while the
same skeleton in the JSON form moves its ``root_position``; an API audit, 2026-12-07)."""

from __future__ import annotations

import json
from typing import Any

from tests.conftest import REPO_ROOT

EXAMPLE = json.loads((REPO_ROOT / "docs/examples/bvh_solve.json").read_text())
SIX = "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
SAID = (
    "no joint at or above the pelvis ('Hips') has three position channels: the body cannot "
    "move in this file, so its targets are met by turning its joints alone"
)


def _fixed_root(text: str) -> str:
    """``text`` with its root's position channels (the first three values of a frame)
    taken out: the root's OFFSET places it, as the frames' values did."""
    head, motion = text.split("MOTION", 1)
    head = head.replace(SIX, "CHANNELS 3 Zrotation Xrotation Yrotation", 1)
    lines = motion.split("\n")
    frames = [" ".join(line.split()[3:]) if line.strip() else line for line in lines[3:]]
    return head + "MOTION" + "\n".join(lines[:3] + frames)


def test_a_file_whose_body_cannot_move_is_told_so(client: Any) -> None:
    fixed = _fixed_root(EXAMPLE["bvh"])
    seen = client.post("/v1/bvh/inspect", json={"bvh": fixed, "frame": 1})
    assert seen.status_code == 200, seen.text
    assert seen.json()["root_warning"] == f"root channels: {SAID}; read as asked"
    pelvis = seen.json()["points"]["pelvis"]
    drag = {"joint": "Hips", "position": [pelvis[0] + 10.0, pelvis[1], pelvis[2]]}
    edit = {"frame": 1, "targets": [drag]}
    one = client.post("/v1/bvh/solve", json={"bvh": fixed, **edit})
    assert one.status_code == 200, one.text
    assert one.json()["root_warning"] == f"root channels: {SAID}; solved as asked"
    assert not one.json()["targets"][0]["reached"]
    clip = client.post("/v1/bvh/solve/batch", json={"bvh": fixed, "edits": [edit]})
    assert clip.status_code == 200, clip.text
    assert clip.json()["edits"][0]["root_warning"] == one.json()["root_warning"]
    # a file whose root moves: no word, as before
    for path, body in (("/v1/bvh/solve", EXAMPLE), ("/v1/bvh/inspect", {"bvh": EXAMPLE["bvh"],
                       "frame": 1})):  # fmt: skip
        out = client.post(path, json=body)
        assert out.status_code == 200 and out.json()["root_warning"] is None, out.text
