"""Joint maps (core/characters_maps.py) through the real routes: what counts as a zero-length
canonical bone is measured on the body the map uses, not on the whole skeleton."""

from __future__ import annotations

import copy
import json
from typing import Any

import numpy as np

from tests.conftest import REPO_ROOT

EXAMPLES = REPO_ROOT / "docs" / "examples"


def _example(name: str) -> dict[str, Any]:
    body: dict[str, Any] = json.loads((EXAMPLES / f"{name}.json").read_text())
    return body


def test_a_far_unmapped_joint_leaves_a_character_as_it_was(client: Any) -> None:
    """A joint the map does not use, far from the body (a prop, a long end bone: the docs'
    character with ``LeftHandIndex1`` 300 m out) was a 422 "spine1 (Spine) sits on pelvis
    (Hips)": the zero-length tolerance was a thousandth of the whole skeleton's extent, so
    the 12 cm pelvis -> spine bone counted as zero (an audit, 2026-12-06). Now the body's
    own size sets it: the same map and, for the mapped joints, the same answer."""
    body = _example("solve_character")
    far = copy.deepcopy(body)
    joints = far["character"]["joints"]
    assert joints[9]["name"] == "LeftHandIndex1"
    joints[9]["offset"] = [300.0, 0.0, 0.0]
    near, away = client.post("/v1/solve", json=body), client.post("/v1/solve", json=far)
    assert near.status_code == 200, near.text
    assert away.status_code == 200, away.text
    a, b = near.json(), away.json()
    assert a["joint_map"] == b["joint_map"]
    mapped = set(a["joint_map"].values())
    assert {"Hips", "Spine", "LeftShoulder", "RightShoulder"} <= mapped
    for name in mapped:
        np.testing.assert_allclose(b["positions"][name], a["positions"][name], atol=1e-9)
        np.testing.assert_allclose(b["rotations"][name], a["rotations"][name], atol=1e-9)
    assert b["targets"][0]["reached"] and a["targets"][0]["reached"]


def _with_prop(text: str, z_cm: float) -> str:
    """``text`` with a second ROOT (a prop, 6 channels) ``z_cm`` from the origin."""
    prop = (
        f"ROOT Prop\n{{\n\tOFFSET 0 0 {z_cm:g}\n"
        "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "\tEnd Site\n\t{\n\t\tOFFSET 0 1 0\n\t}\n}\nMOTION"
    )
    lines = text.replace("MOTION", prop, 1).split("\n")
    motion = lines.index("MOTION")
    frames = int(lines[motion + 1].split()[1])
    for f in range(frames):
        lines[motion + 3 + f] += " 1 2 3 0 0 0"
    return "\n".join(lines)


def _frame(text: str, frame: int) -> list[float]:
    lines = text.split("\n")
    return [float(v) for v in lines[lines.index("MOTION") + 3 + frame].split()]


def test_a_far_prop_root_in_a_bvh_leaves_the_body_as_it_was(client: Any) -> None:
    """A second ROOT (a prop) 500 m from the body made the docs' BVH a 422 "spine1 (Spine)
    sits on pelvis (Hips)" (at 50 m it was answered): now the same map and, for the body's
    channels, the same frame written; the prop's channels come back as they were."""
    body = _example("bvh_solve")
    plain = client.post("/v1/bvh/solve", json=body)
    assert plain.status_code == 200, plain.text
    for z_cm in (5000.0, 50000.0):
        r = client.post("/v1/bvh/solve", json={**body, "bvh": _with_prop(body["bvh"], z_cm)})
        assert r.status_code == 200, (z_cm, r.text)
        assert r.json()["joint_map"] == plain.json()["joint_map"]
        got, want = _frame(r.json()["bvh"], body["frame"]), _frame(plain.json()["bvh"], 1)
        assert got[-6:] == [1.0, 2.0, 3.0, 0.0, 0.0, 0.0]
        np.testing.assert_allclose(got[:-6], want, atol=1e-3)


def _map_error(client: Any, path: str, body: dict[str, Any]) -> dict[str, str]:
    r = client.post(path, json=body)
    assert r.status_code == 422, r.text
    (error,) = r.json()["errors"]
    assert r.json()["detail"] == f"{error['location']}: {error['message']}"
    return dict(error)


def test_an_unknown_canonical_key_is_located_at_the_key(client: Any) -> None:
    """``joint_map: {"tail": ...}`` was located at ``joint_map`` while an unknown joint of
    the skeleton is at ``joint_map.<canonical>`` (an audit, 2026-12-06): now at the key, in
    every form that takes a map (a key that is no field name too)."""
    body = _example("solve_character")
    for key in ("tail", "Left Tail: 2"):
        body["joint_map"] = {key: "Hips"}
        error = _map_error(client, "/v1/solve", body)
        assert error["location"] == f"joint_map.{key}", error
        assert f"unknown canonical joint '{key}'; joints are pelvis, spine1" in error["message"]
    error = _map_error(client, "/v1/solve/batch", {"items": [_example("solve"), body]})
    assert error["location"] == "items[1].joint_map.Left Tail: 2", error
    bvh = {**_example("bvh_solve"), "joint_map": {"tail": "Hips"}}
    assert _map_error(client, "/v1/bvh/solve", bvh)["location"] == "joint_map.tail"


def test_a_point_along_a_bone_that_is_no_bone_is_named(client: Any) -> None:
    """``{"spine2": "0.35 of Neck->Spine2"}`` (the bone reversed) was read as the joint
    ``Neck`` and refused as "left_collar -> 'LeftShoulder' is not below spine2 -> 'Neck'"
    (an audit, 2026-12-06): now the point itself is named, and why; so is a point whose
    end the skeleton has not. A point the answer's map writes is still taken back."""
    body = _example("solve_character")
    body["joint_map"] = {"spine2": "0.35 of Neck->Spine2"}
    error = _map_error(client, "/v1/solve", body)
    assert error["location"] == "joint_map.spine2", error
    for needle in (
        "'0.35 of Neck->Spine2' is no point along a bone",
        "'Spine2' is not below 'Neck'",
        "(reversed: 'Neck' is below it)",
    ):
        assert needle in error["message"], error["message"]
    body["joint_map"] = {"spine2": "0.35 of Spine2->Nope"}
    error = _map_error(client, "/v1/solve", body)
    assert error["location"] == "joint_map.spine2", error
    assert "'0.35 of Spine2->Nope': the skeleton has no joint 'Nope'" in error["message"]
    # a chest on its spine joint (Spine2 moved onto Spine): the map slides it, and takes
    # the point it writes back
    body = _example("solve_character")
    joints = body["character"]["joints"]
    joints[2]["offset"], joints[3]["offset"] = [0.0, 0.0, 0.0], [0.0, 0.42, 0.0]
    first = client.post("/v1/solve", json=body)
    assert first.status_code == 200, first.text
    assert first.json()["joint_map"]["spine2"] == "0.35 of Spine2->Neck"
    again = client.post("/v1/solve", json={**body, "joint_map": first.json()["joint_map"]})
    assert again.status_code == 200, again.text
