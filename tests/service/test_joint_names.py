"""Which joint a character's target or pin names (service/joint_names.py), through the real
routes on the docs' character: the client's mapped joints and the canonical names as
before; a name that is both a joint of the skeleton and a canonical name that joint is not
mapped to is a 422 naming it (was: read as the canonical joint, reported reached while the
client's own joint of that name ended 8 cm away: an audit, 2026-12-06); a joint of the
skeleton that no canonical joint is mapped to is a 422 saying so, with the ``joint_map``
entry that makes it one (was: "did you mean 'spine1'?" for Mixamo's ``Spine1``, and the
hint moved ``Spine``: an audit, 2026-12-06)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np

from core.text import quoted
from tests.conftest import REPO_ROOT
from tests.service.test_api import assert_problem

EXAMPLES = REPO_ROOT / "docs" / "examples"


def _character() -> dict[str, Any]:
    body: dict[str, Any] = json.loads((EXAMPLES / "solve_character.json").read_text())
    return body


def _renamed(body: dict[str, Any], names: dict[str, str]) -> dict[str, Any]:
    """``body`` with its skeleton's joints renamed (parents, rotations, targets and pins
    too)."""
    out = copy.deepcopy(body)
    for jt in out["character"]["joints"]:
        jt["name"] = names.get(jt["name"], jt["name"])
        jt["parent"] = names.get(jt["parent"], jt["parent"])
    out["rotations"] = {names.get(k, k): v for k, v in out["rotations"].items()}
    for t in out["targets"]:
        t["joint"] = names.get(t["joint"], t["joint"])
    out["pins"] = [names.get(p, p) for p in out["pins"]]
    return out


def _ambiguous(r: Any, where: str, *needles: str) -> None:
    body = assert_problem(r, 422)
    (error,) = body["errors"]
    assert error["location"] == where, body
    for needle in ("is ambiguous", *needles):
        assert needle in error["message"], error["message"]


def test_an_unmapped_joint_named_like_a_canonical_joint_is_ambiguous(client: Any) -> None:
    """The audit's case: the finger ``LeftHandIndex1`` renamed ``left_wrist`` (canonical
    left_wrist is the hand, ``LeftHand``): as a target and as a pin it is refused, naming
    both readings and the client's name of the canonical joint; mapped onto the finger by
    ``joint_map``, the finger is the one that reaches."""
    body = _renamed(_character(), {"LeftHandIndex1": "left_wrist"})
    body["targets"] = [{"joint": "left_wrist", "position": [0.494, 1.328, 0.24]}]
    _ambiguous(
        client.post("/v1/solve", json=body),
        "targets[0].joint",
        "skeleton's joint 'left_wrist' (not in the map)",
        "canonical joint left_wrist, which the map puts on 'LeftHand'",
        "name 'LeftHand' for the canonical joint",
    )
    _ambiguous(
        client.post("/v1/solve/batch", json={"items": [_character(), body]}),
        "items[1].targets[0].joint",
    )
    pinned = {**body, "targets": _character()["targets"], "pins": ["left_wrist"]}
    _ambiguous(client.post("/v1/character/solve", json=pinned), "pins[0]")
    # the client's reading, asked for by the map: its finger reaches the target
    mapped = {**body, "joint_map": {"left_wrist": "left_wrist"}}
    r = client.post("/v1/solve", json=mapped)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["joint_map"]["left_wrist"] == "left_wrist" and out["targets"][0]["reached"]
    gap = np.subtract(out["positions"]["left_wrist"], body["targets"][0]["position"])
    assert float(np.linalg.norm(gap)) <= 1e-3


def test_a_mapped_joint_named_like_another_canonical_joint_is_ambiguous(client: Any) -> None:
    """The hand renamed ``left_elbow`` and mapped to left_wrist: ``left_elbow`` is both that
    joint (canonical left_wrist) and the canonical elbow (``LeftForeArm``)."""
    body = _renamed(_character(), {"LeftHand": "left_elbow"})
    body["joint_map"] = {"left_wrist": "left_elbow"}
    body["targets"] = [{"joint": "left_elbow", "position": [0.494, 1.328, 0.24]}]
    _ambiguous(
        client.post("/v1/solve", json=body),
        "targets[0].joint",
        "skeleton's joint 'left_elbow' (mapped to left_wrist)",
        "canonical joint left_elbow, which the map puts on 'LeftForeArm'",
    )
    body["targets"][0]["joint"] = "left_wrist"  # the canonical name of that joint
    assert client.post("/v1/solve", json=body).status_code == 200


def test_mapped_and_canonical_names_resolve_as_before(client: Any) -> None:
    """The client's mapped name and the canonical name give one answer; a skeleton whose
    joints are named by their canonical names (each mapped to itself) is answered as the
    same skeleton under its own names."""
    body = _character()
    own = client.post("/v1/solve", json=body)
    assert own.status_code == 200, own.text
    canonical = copy.deepcopy(body)
    canonical["targets"][0]["joint"] = "left_wrist"
    canonical["pins"] = ["left_ankle", "right_ankle"]
    said = client.post("/v1/solve", json=canonical).json()  # the same but the names sent
    assert [t.pop("name") for t in said["targets"] + said["pins"]] == [
        "left_wrist", "left_ankle", "right_ankle"]  # fmt: skip
    mine = own.json()
    assert [t.pop("name") for t in mine["targets"] + mine["pins"]] == [
        "LeftHand", "LeftFoot", "RightFoot"]  # fmt: skip
    assert said == mine
    names = {
        "Hips": "pelvis", "Spine": "spine1", "Spine2": "spine2", "Neck": "neck",
        "Head": "head",
    }  # fmt: skip
    for side, s in (("Left", "left"), ("Right", "right")):
        names |= {
            f"{side}Shoulder": f"{s}_collar", f"{side}Arm": f"{s}_shoulder",
            f"{side}ForeArm": f"{s}_elbow", f"{side}Hand": f"{s}_wrist",
            f"{side}UpLeg": f"{s}_hip", f"{side}Leg": f"{s}_knee",
            f"{side}Foot": f"{s}_ankle", f"{side}ToeBase": f"{s}_foot",
        }  # fmt: skip
    r = client.post("/v1/solve", json=_renamed(body, names))
    assert r.status_code == 200, r.text
    got, want = r.json(), mine
    assert got["joint_map"] == {c: c for c in want["joint_map"]}
    for t in got["targets"] + got["pins"]:
        assert t.pop("name") == t["joint"]  # (its own names are the canonical ones)
    assert got["targets"] == want["targets"] and got["pins"] == want["pins"]
    for name, xyz in want["positions"].items():
        np.testing.assert_allclose(got["positions"][names.get(name, name)], xyz, atol=1e-12)


def _unmapped(r: Any, where: str, name: str, canon: str, on: str) -> None:
    """A 422 at ``where``: ``name`` is the skeleton's joint, no canonical joint is on it,
    ``canon`` (named like it) is on ``on``; the ``joint_map`` entry to give; no "did you
    mean" (it offered ``canon``, which stands for ``on``)."""
    body = assert_problem(r, 422)
    (error,) = body["errors"]
    assert error["location"] == where, body
    assert error["message"].startswith(
        f"{quoted(name)} is a joint of this skeleton that no canonical joint is mapped to; "
        f"the map puts the canonical joint {canon} on {quoted(on)}; "
        f'give "joint_map": {{"{canon}": "{name}"}} to map {canon} onto this joint and '
        "target it; mapped: pelvis (Hips), "
    ), error["message"]
    assert "did you mean" not in body["detail"], body["detail"]


def test_an_unmapped_joint_of_a_file_is_refused_with_the_map_entry_that_targets_it(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """The animated-drawings child (Mixamo names): ``Spine1`` and ``Spine2`` are its joints,
    canonical spine1 is on ``Spine`` and spine2 on ``Spine3``. A target or pin naming them
    is refused saying so (single, batch); with the ``joint_map`` the refusal gives, the file's
    ``Spine1`` reaches the target and ``Spine`` is not moved onto it."""
    text = bvh_files["fair1-child-inches-zup"].read_text()
    file = {"bvh": text, "units": "in"}
    seen = client.post("/v1/bvh/inspect", json={**file, "frame": 5}).json()
    names = [jt["name"] for jt in seen["joints"]]
    before = dict(zip(names, seen["positions"], strict=True))
    goal = np.add(before["Spine1"], [0.0, 0.0, -1.0]).tolist()  # an inch lower (+Z up)
    edit = {"frame": 5, "targets": [{"joint": "Spine1", "position": goal}]}
    r = client.post("/v1/bvh/solve", json={**file, **edit})
    _unmapped(r, "targets[0].joint", "Spine1", "spine1", "Spine")
    two = {**edit, "targets": [{"joint": "Spine2", "position": goal}]}
    r = client.post("/v1/bvh/solve", json={**file, **two})
    _unmapped(r, "targets[0].joint", "Spine2", "spine2", "Spine3")
    pinned = {"frame": 6, "targets": [{"joint": "LeftHand", "position": goal}], "pins": ["Spine1"]}
    r = client.post("/v1/bvh/solve/batch", json={**file, "edits": [edit, pinned]})
    problem = assert_problem(r, 422)
    assert [e["location"] for e in problem["errors"]] == [
        "edits[0].targets[0].joint",
        "edits[1].pins[0]",
    ], problem
    assert 'give "joint_map": {"spine1": "Spine1"}' in problem["errors"][1]["message"]
    # the advice followed: the file's Spine1 is the joint that reaches the target
    r = client.post("/v1/bvh/solve", json={**file, **edit, "joint_map": {"spine1": "Spine1"}})
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["joint_map"]["spine1"] == "Spine1" and out["targets"][0]["reached"], out
    seen = client.post("/v1/bvh/inspect", json={**file, "bvh": out["bvh"], "frame": 5}).json()
    after = dict(zip(names, seen["positions"], strict=True))
    assert float(np.linalg.norm(np.subtract(after["Spine1"], goal))) <= 0.01  # inches
    assert float(np.linalg.norm(np.subtract(after["Spine"], goal))) > 2.0


def test_an_unmapped_joint_of_a_json_skeleton_is_refused_with_the_map_entry(
    client: Any,
) -> None:
    """The docs' character with a ``Spine1`` between ``Spine`` (canonical spine1) and
    ``Spine2``: as a target and as a pin it is refused naming where spine1 is; a misspelt
    name that is no joint keeps its "did you mean"; mapped as the refusal says, ``Spine1``
    reaches the target and, pinned, stays where it was."""
    body = _character()
    joints = body["character"]["joints"]
    joints.insert(2, {"name": "Spine1", "parent": "Spine", "offset": [0.0, 0.12, 0.0]})
    joints[3].update(parent="Spine1", offset=[0.0, 0.13, 0.0])  # Spine2
    goal = [0.05, 1.2, 0.0]
    aimed = {**body, "pins": [], "targets": [{"joint": "Spine1", "position": goal}]}
    r = client.post("/v1/solve", json=aimed)
    _unmapped(r, "targets[0].joint", "Spine1", "spine1", "Spine")
    pinned = {**body, "pins": ["Spine1"]}
    _unmapped(client.post("/v1/character/solve", json=pinned), "pins[0]", "Spine1", "spine1",
              "Spine")  # fmt: skip
    slip = {**aimed, "targets": [{"joint": "LEFTHAND", "position": goal}]}
    assert_problem(client.post("/v1/solve", json=slip), 422, "(did you mean 'LeftHand'?)")
    r = client.post("/v1/solve", json={**aimed, "joint_map": {"spine1": "Spine1"}})
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["joint_map"]["spine1"] == "Spine1" and out["targets"][0]["reached"], out
    assert float(np.linalg.norm(np.subtract(out["positions"]["Spine1"], goal))) <= 1e-3
    assert float(np.linalg.norm(np.subtract(out["positions"]["Spine"], goal))) > 0.05
    r = client.post("/v1/solve", json={**pinned, "joint_map": {"spine1": "Spine1"}})
    assert r.status_code == 200, r.text
    (pin, *_) = r.json()["pins"]  # the pinned Spine1 (canonical spine1) kept where it was
    assert pin["joint"] == "spine1" and pin["reached"] and pin["error"] <= 1e-3, pin


def test_a_slip_in_a_character_s_target_or_pin_is_offered_the_name_meant(client: Any) -> None:
    """A target or pin of the character and BVH forms a letter off a mapped joint or a
    canonical name (``left_wrsit``, ``LeftHnad``) is offered it, as the pose form offers
    ``left_wrist`` for ``left_wrsit``; it was offered only for case (``lefthand``), so the
    two forms worded the same slip differently (an API audit, 2026-12-07). A neighbour is
    not offered (``right_hand`` for ``left_hand``: a typo, not another joint)."""
    body = _character()
    clip = json.loads((EXAMPLES / "bvh_solve.json").read_text())
    for name, meant in (("left_wrsit", "left_wrist"), ("LeftHnad", "LeftHand"),
                        ("lefthand", "LeftHand"), ("RightFot", "RightFoot")):  # fmt: skip
        aim = {**body, "targets": [{"joint": name, "position": [0.494, 1.328, 0.24]}]}
        cases = [
            ("/v1/solve", aim, "targets[0].joint"),
            ("/v1/solve", {**body, "pins": [name]}, "pins[0]"),
            ("/v1/bvh/solve", {**clip, "pins": [name]}, "pins[0]"),
        ]
        for path, sent, where in cases:
            error = assert_problem(client.post(path, json=sent), 422)["errors"][0]
            assert error["location"] == where, error
            assert error["message"].startswith(
                f"{quoted(name)} is neither a mapped joint of this skeleton nor a canonical "
                f"joint (did you mean {quoted(meant)}?); mapped: "
            ), error["message"]
    pin = {**body, "pins": ["Right_Hand_Tip"]}  # no joint near enough: no suggestion
    error = assert_problem(client.post("/v1/solve", json=pin), 422)["errors"][0]
    assert "did you mean" not in error["message"], error["message"]


def test_a_slip_in_a_skeleton_s_or_a_map_s_joint_name_is_offered_the_name_meant(
    client: Any,
) -> None:
    """A joint name a letter off in a ``joint_map`` value, a ``joint_map`` key or a joint's
    ``parent`` is offered the name meant, as a target's and a ``rotations`` key's are; they
    were offered for case alone or not at all ("the skeleton has no joint 'LeftHnad'",
    "unknown canonical joint 'left_wirst'", "unknown joint 'Hip'": an API audit,
    2026-12-07), in the JSON and the BVH forms alike."""
    body = _character()
    clip = json.loads((EXAMPLES / "bvh_solve.json").read_text())
    parent = copy.deepcopy(body)
    parent["character"]["joints"][3]["parent"] = "Spine_2"
    cases = [
        ({**body, "joint_map": {"left_wrist": "LeftHnad"}}, "joint_map.left_wrist",
         "the skeleton has no joint 'LeftHnad' (did you mean 'LeftHand'?)"),
        ({**body, "joint_map": {"left_wirst": "LeftHand"}}, "joint_map.left_wirst",
         "unknown canonical joint 'left_wirst' (did you mean 'left_wrist'?); joints are "),
        (parent, "character.joints[3].parent", "unknown joint 'Spine_2' (did you mean 'Spine2'?)"),
    ]  # fmt: skip
    for sent, where, said in cases:
        for path, form in (("/v1/solve", sent), ("/v1/bvh/solve", {**clip, **sent})):
            if "character" in form and path == "/v1/bvh/solve":
                continue  # (a file's parents are its nesting)
            if path == "/v1/bvh/solve":
                form = {k: v for k, v in form.items() if k not in ("character", "rotations")}
                form.pop("root_position", None)
            error = assert_problem(client.post(path, json=form), 422)["errors"][0]
            assert error["location"] == where, (path, error)
            assert error["message"].startswith(said), (path, error["message"])
    far = {**body, "joint_map": {"left_wrist": "Nope"}}  # nothing near: nothing offered
    error = assert_problem(client.post("/v1/solve", json=far), 422)["errors"][0]
    assert error["message"] == "the skeleton has no joint 'Nope'", error


def test_one_joint_named_twice_by_two_names_says_which_entry_it_is_again(client: Any) -> None:
    """A character's joint targeted or pinned twice under two names (its own and the
    canonical one) names the other entry, as the client named it, where it said only the
    second name ("pins[1]: joint 'left_ankle' is pinned twice": the client sent it once as
    that; an API audit, 2026-12-07). Twice under one name is told as before."""
    body = _character()
    aim = [0.494, 1.328, 0.24]
    cases = [
        ({**body, "pins": ["LeftFoot", "left_ankle"]}, "pins[1]",
         "joint 'left_ankle' is pinned twice: pins[0], 'LeftFoot', is the same joint"),
        ({**body, "targets": [{"joint": "LeftHand", "position": aim},
                              {"joint": "left_wrist", "position": aim}]}, "targets[1]",
         "duplicate target for joint 'left_wrist': targets[0], 'LeftHand', is the same joint"),
        ({**body, "targets": [{"joint": "left_wrist", "position": aim}], "pins": ["LeftHand"]},
         "pins[0]", "joint 'LeftHand' (mapped to 'left_wrist') is both pinned and targeted: "
         "targets[0], 'left_wrist', is the same joint"),
        ({**body, "pins": ["LeftFoot", "LeftFoot"]}, "pins[1]",
         "joint 'LeftFoot' (mapped to 'left_ankle') is pinned twice"),
    ]  # fmt: skip
    for sent, where, said in cases:
        error = assert_problem(client.post("/v1/solve", json=sent), 422)["errors"][0]
        assert (error["location"], error["message"]) == (where, said), error
