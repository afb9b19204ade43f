"""A rig whose left and right joints are named for the other side (core.sides): solved as
the body it is, its joints keeping their names, and said in ``sides_warning``. Before, the
networks read such a body from behind, its toes and knees backwards: a Bandai-Namco walk
with ``_L`` and ``_R`` swapped had its five end effectors solved 2.39 cm from the real pose
instead of 0.88 (``python -m bench.characters --on-pelvis``, 30 edits)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests.character_files import FILES, other_label, other_side, swapped_file
from tests.conftest import REPO_ROOT


@pytest.mark.parametrize(
    "name", ["bandai", "reactidle-6ch", "cmu-daz-salsa", "fair1-child-inches-zup"]
)
def test_a_file_with_its_sides_named_the_other_way_is_solved_as_the_body_it_is(
    client: Any, bvh_files: dict[str, Path], name: str
) -> None:
    """Four studios' files, every joint renamed for the other side: the same edit (its
    targets and pins renamed so, the same joints of the body) writes the same frame back,
    value for value, with the same report but for the names; the renamed file's answers,
    each of a clip's edits and inspect say why (the hips named), the file as it is says
    nothing. A map the client gives is kept and warned about."""
    _, _, units, frame = FILES[name]
    text = bvh_files[name].read_text()
    other = swapped_file(text)
    read = {"units": units} if units is not None else {}
    read |= {"root_position": "add"} if name == "reactidle-6ch" else {}
    looked = client.post("/v1/bvh/inspect", json={"bvh": text, "frame": frame, **read}).json()
    hand, foot = looked["joint_map"]["left_wrist"], looked["joint_map"]["right_ankle"]
    goal = np.add(
        looked["points"]["left_wrist"], np.divide([0.15, 0.1, 0.05], looked["metres_per_unit"])
    )
    ask = {"frame": frame, **read, "options": {"reach": "exact"}}
    mine = client.post("/v1/bvh/solve", json={
        **ask, "bvh": text, "pins": [foot],
        "targets": [{"joint": hand, "position": goal.tolist()}]})  # fmt: skip
    assert mine.status_code == 200, mine.text
    targets = [{"joint": other_side(hand), "position": goal.tolist()}]
    theirs = client.post("/v1/bvh/solve", json={
        **ask, "bvh": other, "pins": [other_side(foot)], "targets": targets})  # fmt: skip
    assert theirs.status_code == 200, theirs.text
    a, b = mine.json(), theirs.json()
    assert a["sides_warning"] is None and looked["sides_warning"] is None
    hips = [a["joint_map"]["left_hip"], a["joint_map"]["right_hip"]]
    assert re.fullmatch(
        "joint_map: this body's left and right joints are named for the other side: .*; solved "
        f"as the body it is, '{hips[0]}' its right hip and '{hips[1]}' its left, .* To "
        "solve its sides as named, give joint_map", b["sides_warning"],
    ), b["sides_warning"]  # fmt: skip
    assert b["joint_map"] == {k: other_label(v) for k, v in a["joint_map"].items()}
    assert b["bvh"].split("MOTION")[1] == a["bvh"].split("MOTION")[1]
    assert [t["error"] for t in b["targets"] + b["pins"]] == [
        t["error"] for t in a["targets"] + a["pins"]]  # fmt: skip
    assert b["changed_joints"] == [other_side(j) for j in a["changed_joints"]]
    inspected = client.post("/v1/bvh/inspect", json={"bvh": other, "frame": frame, **read})
    assert inspected.json()["sides_warning"] == b["sides_warning"]
    edits = [{"frame": frame, "targets": targets}]
    clip = client.post("/v1/bvh/solve/batch", json={"bvh": other, **read, "edits": edits})
    assert clip.json()["edits"][0]["sides_warning"] == b["sides_warning"], clip.text
    given = a["joint_map"]  # the map the names say (the other side of the body's)
    kept = client.post("/v1/bvh/solve", json={
        **ask, "bvh": other, "targets": targets, "joint_map": given}).json()  # fmt: skip
    assert kept["joint_map"] == given, kept
    assert kept["sides_warning"].startswith("joint_map: this body's left and right look swapped")


def test_a_json_rig_with_its_sides_named_the_other_way_is_solved_as_the_body_it_is(
    client: Any,
) -> None:
    """The docs' JSON rig with every joint renamed for the other side (its rotations and
    target too): the same rotations and positions come back under the other names, with
    ``sides_warning``; the rig as the docs have it gets none."""
    body = json.loads((REPO_ROOT / "docs/examples/solve_character.json").read_text())
    other = json.loads(json.dumps(body))
    for j in other["character"]["joints"]:
        j["name"] = other_side(j["name"])
        j["parent"] = j["parent"] and other_side(j["parent"])
    other["rotations"] = {other_side(k): q for k, q in body["rotations"].items()}
    other["targets"] = [{**t, "joint": other_side(t["joint"])} for t in body["targets"]]
    a, b = (client.post("/v1/solve", json=x).json() for x in (body, other))
    assert a["sides_warning"] is None
    assert b["sides_warning"].startswith(
        "joint_map: this body's left and right joints are named for the other side"), b  # fmt: skip
    assert b["positions"] == {other_side(k): v for k, v in a["positions"].items()}
    assert b["rotations"] == {other_side(k): v for k, v in a["rotations"].items()}
