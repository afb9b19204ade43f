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
        "solve its sides as named, give joint_map its left_ and right_ entries",
        b["sides_warning"],
    ), b["sides_warning"]  # fmt: skip
    assert b["joint_map"] == {k: other_label(v) for k, v in a["joint_map"].items()}
    assert b["bvh"].split("MOTION")[1] == a["bvh"].split("MOTION")[1]
    assert [t["error"] for t in b["targets"] + b["pins"]] == [
        t["error"] for t in a["targets"] + a["pins"]]  # fmt: skip
    assert b["changed_joints"] == [other_side(j) for j in a["changed_joints"]]
    # each report names the body's own joint and the name sent (LeftHand: the body's right)
    assert [(t["joint"], t["name"]) for t in a["targets"] + a["pins"]] == [
        ("left_wrist", hand), ("right_ankle", foot)]  # fmt: skip
    assert [(t["joint"], t["name"]) for t in b["targets"] + b["pins"]] == [
        ("left_wrist", other_side(hand)), ("right_ankle", other_side(foot))]  # fmt: skip
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
    assert "solved as the joint_map given says" in kept["sides_warning"]
    centre = {"head": a["joint_map"]["head"]}  # a map of centre joints alone: still swapped
    partial = client.post("/v1/bvh/solve", json={
        **ask, "bvh": other, "targets": targets, "joint_map": centre}).json()  # fmt: skip
    assert partial["joint_map"] == b["joint_map"] and partial["sides_warning"], partial
    # every frame of the file read alike (its rest pose decides where it says, else each
    # frame; frames read differently in one clip are refused, naming them)
    assert "(in its rest pose)" in b["sides_warning"] or "(in this frame" in b["sides_warning"]


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


def test_a_rig_named_with_the_canonical_names_is_kept_and_told(client: Any) -> None:
    """The docs' JSON rig renamed to the canonical names (``left_wrist``, ...), sides
    swapped: swapped, each name would read two ways (the review: every side target a 422,
    "ambiguous"); kept as named and told so."""
    from core.characters_maps import resolve_map  # noqa: F401  (the map the names give)

    body = json.loads((REPO_ROOT / "docs/examples/solve_character.json").read_text())
    auto = client.post("/v1/solve", json=body).json()["joint_map"]
    canon = {
        own: c for c, own in auto.items() if own in {j["name"] for j in body["character"]["joints"]}
    }
    flip = {n: other_side(canon[n]) if n in canon else n for n in canon}
    named = {n: flip.get(n, n) for n in [j["name"] for j in body["character"]["joints"]]}
    other = json.loads(json.dumps(body))
    for j in other["character"]["joints"]:
        j["name"], j["parent"] = named[j["name"]], j["parent"] and named[j["parent"]]
    other["rotations"] = {named[k]: q for k, q in body["rotations"].items()}
    other["targets"] = [{**t, "joint": named[t["joint"]]} for t in body["targets"]]
    other["pins"] = [named[p] for p in body.get("pins", [])]
    said = client.post("/v1/solve", json=other)
    assert said.status_code == 200, said.text
    out = said.json()
    assert out["sides_warning"].startswith("joint_map: this body's left and right look swapped")
    assert "solved as its names say" in out["sides_warning"], out["sides_warning"]
    assert out["joint_map"]["left_wrist"] == "left_wrist"


def test_a_clip_whose_frames_read_their_sides_differently_is_refused(
    client: Any, bvh_files: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where the rest pose says nothing (Bandai-Namco's splayed feet) each frame says, and
    one clip's frames that say differently get a 422 naming them (its top-level joint_map
    would be one frame's); frames that agree are solved. (No real frame of the file reads
    swapped: the frame's reading is made to, by ``core.sides.mirrored``.)"""
    import core.sides

    text = bvh_files["bandai"].read_text()
    seen = core.sides.mirrored

    def odd(rest: Any, frame: Any, upright: Any) -> str | None:  # frame 40 reads swapped
        return "this frame" if abs(frame[0, 0] - odd.at) < 1e-9 else seen(rest, frame, upright)

    looked = client.post("/v1/bvh/inspect", json={"bvh": text, "frame": 40}).json()
    odd.at = looked["points"]["pelvis"][0]  # type: ignore[attr-defined]  # (file units, +Y up)
    monkeypatch.setattr(core.sides, "mirrored", odd)
    goal = looked["points"]["left_wrist"]
    edits = [{"frame": f, "targets": [{"joint": "left_wrist", "position": goal}]} for f in (20, 40)]
    r = client.post("/v1/bvh/solve/batch", json={"bvh": text, "edits": edits})
    assert r.status_code == 422, r.text
    assert "the frames edited read it differently, edits[0] (frame 20) with" in r.text, r.text
    alone = client.post("/v1/bvh/solve/batch", json={"bvh": text, "edits": edits[1:]})
    assert alone.status_code == 200 and alone.json()["edits"][0]["sides_warning"], alone.text
