"""Joint names and rest poses through the character routes, on a real file (AnimatedDrawings'
fair1 ``dab.bvh``, Mixamo names) changed as a user's tool may change it, and the docs'
character (an audit, 2026-12-06):

- a name is the file's own spelling (``Left  Hand``, ``Right<TAB>Hand``): a map or a target
  that gives it works, inspect returns it, the answer's hierarchy is the file's (D2);
- the automatic map takes a joint named as the scheme writes it over one named so but for
  case or a namespace (a socket ``LEFTHAND`` before the real ``LeftHand``), and refuses two
  joints as good as each other, naming both (D3);
- a rest pose the map cannot be read from is refused for what it is: one offset out of
  proportion (located at that offset), every joint at one point (D5)."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import REPO_ROOT
from tests.core.test_bvh_names import odd_names
from tests.service.test_api import assert_problem

FAIR1 = "fair1-child-inches-zup"
ODD_MAP = {
    "left_wrist": "Left  Hand",
    "right_wrist": "Right\tHand",
    "left_ankle": "Left \x0b\x85Foot",
    "right_ankle": "Right\u3000Foot",
}


@pytest.fixture(scope="module")
def dab(bvh_files: dict[str, Path]) -> str:
    return bvh_files[FAIR1].read_text()


def _inspect(client: Any, text: str, **more: Any) -> Any:
    return client.post("/v1/bvh/inspect", json={"bvh": text, "units": "in", **more})


def _hierarchy(text: str) -> str:
    return text[: text.index("MOTION")]


def test_a_joint_is_named_as_the_file_writes_it(client: Any, dab: str) -> None:
    """D2: ``Left  Hand`` and ``Right<TAB>Hand`` (the automatic map finds no wrist: a map
    is needed): the map that names them as written is taken (was: 422 "the skeleton has no
    joint 'Left  Hand'"), inspect returns them as written, a target names one so, and the
    answer's hierarchy is the file's, byte for byte; the names with one space are refused,
    suggesting the file's."""
    text = odd_names(dab)
    refused = assert_problem(_inspect(client, text), 422, "joint_map: no joint found for [")
    assert "'left_wrist', 'right_wrist'" in refused["detail"]
    r = _inspect(client, text, joint_map=ODD_MAP, frame=120)
    assert r.status_code == 200, r.text
    got = r.json()
    names = [j["name"] for j in got["joints"]]
    for name in ("Left  Hand", "Right\tHand", "Left \x0b\x85Foot", "Right\u3000Foot", "Neck"):
        assert name in names, name
    assert not any("{" in n or "Left Hand" in n for n in names), names
    assert {k: got["joint_map"][k] for k in ODD_MAP} == ODD_MAP
    wrist = got["points"]["left_wrist"]

    body = {
        "bvh": text,
        "frame": 120,
        "units": "in",
        "joint_map": ODD_MAP,
        "targets": [{"joint": "Left  Hand", "position": [wrist[0] + 2, wrist[1], wrist[2] + 2]}],
        "options": {"reach": "exact"},
    }
    r = client.post("/v1/bvh/solve", json=body)
    assert r.status_code == 200, r.text
    answer = r.json()
    assert answer["targets"][0]["reached"], answer["targets"]
    assert _hierarchy(answer["bvh"]) == _hierarchy(text)

    collapsed = {"left_wrist": "Left Hand", "right_wrist": "Right Hand"}
    assert_problem(
        _inspect(client, text, joint_map=collapsed),
        422,
        "joint_map.left_wrist: the skeleton has no joint 'Left Hand' (did you mean 'Left  Hand'?)",
    )


def _with_socket(text: str, socket: str, hand: str = "LeftHand") -> str:
    """``text`` with a joint ``socket`` (no channels: the frames as they are) under
    LeftForeArm, listed before LeftHand, which is renamed ``hand``."""
    at = text.index("JOINT LeftHand\n")
    start = text.rindex("\n", 0, at) + 1
    pad = text[start:at]
    block = [f"JOINT {socket}", "{", "\tOFFSET 3 -1 0", "\tCHANNELS 0", "\tEnd Site", "\t{"]
    block += ["\t\tOFFSET 1 0 0", "\t}", "}"]
    out = text[:start] + "".join(f"{pad}{line}\n" for line in block) + text[start:]
    return out.replace("JOINT LeftHand\n", f"JOINT {hand}\n")


@pytest.mark.parametrize("socket", ["LEFTHAND", "Prop:LeftHand", "mixamorig:LeftHand"])
def test_the_map_takes_a_joint_named_as_written_over_one_named_so_but_for_case(
    client: Any, dab: str, socket: str
) -> None:
    """D3: a socket named as the wrist but for case or a namespace, listed before the real
    ``LeftHand``, was the wrist (edits moved the socket, and said they reached); now the
    name as the scheme writes it wins, and a wrist target moves the hand."""
    text = _with_socket(dab, socket)
    r = _inspect(client, text, frame=120)
    assert r.status_code == 200, r.text
    got = r.json()
    assert got["joint_map"]["left_wrist"] == "LeftHand"
    assert got["anchors"]["left_wrist"]["joint"] == "LeftHand"
    wrist = got["points"]["left_wrist"]
    body = {
        "bvh": text,
        "frame": 120,
        "units": "in",
        "targets": [{"joint": "left_wrist", "position": [wrist[0] + 2, wrist[1], wrist[2] + 2]}],
        "options": {"reach": "exact"},
    }
    r = client.post("/v1/bvh/solve", json=body)
    assert r.status_code == 200, r.text
    assert r.json()["targets"][0]["reached"]
    after = _inspect(client, r.json()["bvh"], frame=120).json()
    moved = after["positions"][[j["name"] for j in after["joints"]].index("LeftHand")]
    assert max(abs(a - b - d) for a, b, d in zip(moved, wrist, (2, 0, 2), strict=True)) < 0.01


@pytest.mark.parametrize(
    ("socket", "hand"), [("LEFTHAND", "lefthand"), ("Prop:LeftHand", "mixamorig:LeftHand")]
)
def test_two_joints_as_good_a_match_are_refused_naming_both(
    client: Any, dab: str, socket: str, hand: str
) -> None:
    """D3: two joints that match the wrist's name equally well (both but for case, both in
    a namespace) are refused, naming both, at joint_map; a map that names one is taken."""
    text = _with_socket(dab, socket, hand)
    problem = assert_problem(
        _inspect(client, text),
        422,
        "joint_map: left_wrist is ambiguous: the joints ",
        f"{socket!r} and {hand!r} both read as 'LeftHand'",
        '"joint_map": {"left_wrist": "<the joint>"}',
    )
    assert problem["errors"][0]["location"] == "joint_map", problem
    r = _inspect(client, text, joint_map={"left_wrist": hand})
    assert r.status_code == 200, r.text
    assert r.json()["joint_map"]["left_wrist"] == hand


def _example(name: str) -> dict[str, Any]:
    body: dict[str, Any] = json.loads(
        (REPO_ROOT / "docs" / "examples" / f"{name}.json").read_text()
    )
    return body


@pytest.mark.parametrize("reverse", [False, True])
def test_an_offset_out_of_proportion_is_named_at_that_offset(client: Any, reverse: bool) -> None:
    """D5a: the docs' character with its Neck offset in the wrong units (170 for 0.17) was
    "joint_map: spine1 (Spine) sits on pelvis (Hips)", located at a joint_map the request
    had not; now it names the Neck's offset, located at it (the joints listed in any
    order)."""
    body = _example("solve_character")
    bad = copy.deepcopy(body)
    joints = bad["character"]["joints"]
    assert joints[3]["name"] == "Neck"
    joints[3]["offset"] = [0, 170, 0]
    if reverse:
        joints.reverse()
    at = f"character.joints[{len(joints) - 4 if reverse else 3}].offset"
    problem = assert_problem(
        client.post("/v1/solve", json=bad),
        422,
        f"{at}: the offset of 'Neck' from 'Spine2', [0.0, 170.0, 0.0], is ",
        "out of proportion",
    )
    assert not problem["detail"].startswith("joint_map"), problem
    assert problem["errors"] == [
        {"location": at, "message": problem["detail"].removeprefix(f"{at}: ")}
    ]
    assert client.post("/v1/solve", json=body).status_code == 200


def test_a_bvh_offset_out_of_proportion_is_named(client: Any, dab: str) -> None:
    """D5a, in a real file: the Neck's OFFSET a thousand times too long."""
    text, n = re.subn(
        r"(JOINT Neck\n\s*\{\n\s*OFFSET) (\S+) (\S+) (\S+)",
        lambda m: f"{m[1]} {m[2]} {float(m[3]) * 1000:g} {float(m[4]) * 1000:g}",
        dab,
    )
    assert n == 1
    problem = assert_problem(_inspect(client, text), 422, "bvh: the offset of 'Neck' from ")
    assert "out of proportion" in problem["detail"] and "joint_map" not in problem["detail"]
    assert problem["errors"][0]["location"] == "bvh"


def _bones_in_channels(text: str) -> str:
    """``text`` with every joint's OFFSET 0 0 0 but the root's, its bone carried by three
    position channels before its rotations instead, in every frame."""
    from core.bvh import parse_bvh

    bvh = parse_bvh(text)
    head, _, motion = text.partition("MOTION")
    lines = head.split("\n")
    joint = -1
    for k, line in enumerate(lines):
        word = line.split()[:1]
        if word in (["ROOT"], ["JOINT"], ["End"]):
            joint += 1
        elif word == ["OFFSET"] and bvh.joints[joint].parent >= 0:
            lines[k] = line[: line.index("OFFSET")] + "OFFSET 0 0 0"
        elif word == ["CHANNELS"] and bvh.joints[joint].parent >= 0:
            rest = line.split()[2:]
            pad = line[: line.index("CHANNELS")]
            lines[k] = f"{pad}CHANNELS {len(rest) + 3} Xposition Yposition Zposition " + " ".join(
                rest
            )
    rows = motion.split("\n")
    first = next(i for i, r in enumerate(rows) if r.startswith("Frame Time")) + 1
    for i in range(first, len(rows)):
        values = rows[i].split()
        if not values:
            continue
        out = []
        for j in bvh.joints:
            part = values[j.channel_start : j.channel_start + len(j.channels)]
            if j.parent >= 0 and j.channels:
                part = [f"{v:g}" for v in j.offset] + part
            out += part
        rows[i] = " ".join(out)
    return "\n".join(lines) + "MOTION" + "\n".join(rows)


@pytest.mark.parametrize("units", [None, "in", "cm"])
def test_a_rest_pose_with_every_joint_at_one_point_is_refused_as_such(
    client: Any, dab: str, units: str | None
) -> None:
    """D5b: a real file whose bones are in position channels, every OFFSET but the root's
    0 0 0, was "joint_map: no joint found for ['spine1']" whatever the units; now it says
    that the rest pose has every joint at one point."""
    text = _bones_in_channels(dab)
    r = client.post("/v1/bvh/inspect", json={"bvh": text, "units": units})
    problem = assert_problem(
        r, 422, "bvh: the rest pose has every joint at one point", "write them as OFFSETs"
    )
    assert problem["errors"][0]["location"] == "bvh"
