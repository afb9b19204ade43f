"""Which joint a character's target or pin names (service/joint_names.py), through the real
routes on the docs' character: the client's mapped joints and the canonical names as
before; a name that is both a joint of the skeleton and a canonical name that joint is not
mapped to is a 422 naming it (was: read as the canonical joint, reported reached while the
client's own joint of that name ended 8 cm away: an audit, 2026-12-06)."""

from __future__ import annotations

import copy
import json
from typing import Any

import numpy as np

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
    assert client.post("/v1/solve", json=canonical).content == own.content
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
    got, want = r.json(), own.json()
    assert got["joint_map"] == {c: c for c in want["joint_map"]}
    assert got["targets"] == want["targets"] and got["pins"] == want["pins"]
    for name, xyz in want["positions"].items():
        np.testing.assert_allclose(got["positions"][names.get(name, name)], xyz, atol=1e-12)
