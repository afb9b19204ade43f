"""A rig whose joint names no naming scheme knows (a real file with every joint renamed):
the 422 says that no joint name matched a scheme's (not "closest naming scheme: X", which
named the first scheme tried), and lists the file's own joint names, in file order, so that a
client without the editor can write ``joint_map`` (a new-user audit, 2026-12-06)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from core.bvh import parse_bvh
from service.errors import MAX_DETAIL
from tests.service.test_api import assert_problem

_JOINT = re.compile(r"^(\s*(?:ROOT|JOINT) )(.+?)\s*$", re.MULTILINE)


def renamed(text: str) -> str:
    """``text`` with each joint ``Name`` named ``name_jnt`` (no scheme's name)."""
    return _JOINT.sub(lambda m: f"{m.group(1)}{m.group(2).lower()}_jnt", text)


@pytest.mark.parametrize("name", ["bandai", "cmu-daz-salsa"])
def test_a_rig_no_scheme_knows_is_told_so_with_its_joint_names(
    client: Any, bvh_files: dict[str, Path], name: str
) -> None:
    text = renamed(bvh_files[name].read_text())
    names = parse_bvh(text, name, frames=[0]).joint_names
    shown = ", ".join(repr(n) for n in names[:40])
    body = {"bvh": text, "frame": 0}
    details = set()
    for path, more in (
        ("/v1/bvh/inspect", {}),
        ("/v1/bvh/solve", {"targets": [{"joint": "head", "position": [0, 1, 0]}]}),
    ):
        got = assert_problem(client.post(path, json={**body, **more}), 422)
        detail = got["detail"]
        assert got["type"].endswith("/invalid-request"), got["type"]
        assert detail.startswith("joint_map: no joint found for ['pelvis', "), detail
        assert "(no joint name matched a scheme's)" in detail, detail
        assert "closest naming scheme" not in detail, detail
        assert f"naming one of the skeleton's {len(names)} joints: {shown}" in detail, detail
        assert (f"{shown} and {len(names) - 40} more," in detail) == (len(names) > 40), detail
        assert "a point part-way along a bone where the rig has no such joint" in detail
        assert '{"pelvis": "0.25 of <joint>-><its child>"}' in detail, detail
        assert len(detail) <= MAX_DETAIL
        details.add(detail)
    assert len(details) == 1


def test_a_mixamo_rig_with_its_legs_renamed_stays_mixamo(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """A real Mixamo-named file (AnimatedDrawings fair1) with its thighs and shins renamed:
    Rokoko's scheme shares its names, and names Spine1 and Spine3 too, which the structural
    rules find for every scheme: it was "closest naming scheme: rokoko", and with the legs
    given, "rokoko+explicit" with spine1 on Spine1 where the whole file has it on Spine.
    Now the map is Mixamo's, the file's own but for the legs, and the tie is named."""
    text = bvh_files["fair1-child-inches-zup"].read_text()
    legs = {"LeftUpLeg": "thigh_lf", "LeftLeg": "shin_lf", "RightUpLeg": "thigh_rt",
            "RightLeg": "shin_rt"}  # fmt: skip
    renamed = _JOINT.sub(lambda m: f"{m.group(1)}{legs.get(m.group(2), m.group(2))}", text)
    body = {"bvh": renamed, "frame": 0, "units": "in"}
    refused = assert_problem(client.post("/v1/bvh/inspect", json=body), 422)
    assert "(closest naming scheme: mixamo (rokoko as close))" in refused["detail"], refused
    given = {"left_hip": "thigh_lf", "left_knee": "shin_lf", "right_hip": "thigh_rt",
             "right_knee": "shin_rt"}  # fmt: skip
    r = client.post("/v1/bvh/inspect", json={**body, "joint_map": given})
    assert r.status_code == 200, r.text
    whole = client.post("/v1/bvh/inspect", json={**body, "bvh": text}).json()
    assert (whole["scheme"], r.json()["scheme"]) == ("mixamo", "mixamo+explicit")
    assert r.json()["joint_map"] == {**whole["joint_map"], **given}
