"""Problem details worded as what the client sent (an API audit, 2026-12-07): a count of
one is singular ("2 rows for 1 pose", it said "1 poses"); a batch body with ``items`` and a
columnar key says that a batch takes one form, not both (it said "poses: Extra inputs are
not permitted", as if the columnar form's own key were unknown); a 405 names the methods
the path takes, as its ``Allow`` header does (it said "Method Not Allowed" alone)."""

from __future__ import annotations

import base64
import json
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_NAMES
from core.text import shown
from tests.conftest import REPO_ROOT

EXAMPLE = json.loads((REPO_ROOT / "docs/examples/solve.json").read_text())
ROW = [v for n in JOINT_NAMES for v in EXAMPLE["pose"][n]]
GOAL = EXAMPLE["targets"][0]["position"]


def says_one_error(client: Any, cases: list[tuple[str, dict[str, Any], str, str]]) -> None:
    """Each (path, body) is a 422 with one error: at ``where``, saying ``said``."""
    for path, body, where, said in cases:
        out = client.post(path, json=body)
        assert out.status_code == 422, out.text
        (error,) = out.json()["errors"]
        assert (error["location"], error["message"]) == (where, said), (path, error)


def test_a_count_of_one_is_singular(client: Any) -> None:
    cases = [
        ({"joints": ["left_wrist"], "positions": [GOAL, GOAL]}, [ROW], "2 rows for 1 pose: "),
        ({"joints": ["left_wrist"], "positions": [GOAL]}, [ROW, ROW], "1 row for 2 poses: "),
        ({"joints": [["left_wrist"]] * 2, "positions": [GOAL]}, [ROW], "2 rows for 1 pose: "),
        ({"joints": ["left_wrist"], "positions": GOAL}, [ROW, ROW], "a list of 2 rows (one per "
         "pose), not one row of 3 numbers"),
    ]  # fmt: skip
    for targets, poses, said in cases:
        out = client.post("/v1/solve/batch", json={"poses": poses, "targets": targets})
        assert out.status_code == 422, out.text
        assert said in out.json()["detail"], out.json()["detail"]
        assert " 1 poses" not in out.json()["detail"] and " 1 rows" not in out.json()["detail"]


@pytest.mark.parametrize("key", ["poses", "targets", "pins", "options"])
def test_a_batch_in_both_forms_is_told_it_takes_one(client: Any, key: str) -> None:
    item = {"pose": EXAMPLE["pose"], "targets": EXAMPLE["targets"]}
    extra: dict[str, Any] = {
        "poses": [ROW], "targets": {"joints": ["left_wrist"], "positions": [GOAL]},
        "pins": ["left_ankle"], "options": {"reach": "exact"},
    }  # fmt: skip
    out = client.post("/v1/solve/batch", json={"items": [item], key: extra[key]})
    assert out.status_code == 422, out.text
    (error,) = out.json()["errors"]
    assert error["location"] == key, error
    assert error["message"].startswith("a batch takes one form, not both: the item list "), error
    assert "Extra inputs" not in out.json()["detail"], out.json()["detail"]
    # the item list alone, and the columnar form alone, as before
    assert client.post("/v1/solve/batch", json={"items": [item]}).status_code == 200
    columns = {"poses": [ROW], "targets": {"joints": ["left_wrist"], "positions": [GOAL]}}
    assert client.post("/v1/solve/batch", json=columns).status_code == 200


def test_a_405_names_the_methods_the_path_takes(client: Any) -> None:
    for method, path, takes in (
        ("GET", "/v1/solve", "POST"),
        ("DELETE", "/v1/models", "GET and HEAD"),
        ("POST", "/v1/skeleton", "GET and HEAD"),
        ("PUT", "/v1/solve/batch", "POST"),
    ):
        out = client.request(method, path)
        assert out.status_code == 405, out.text
        assert out.json()["title"] == "Method Not Allowed"
        assert out.json()["detail"] == f"{method} is not allowed on {path}: it takes {takes}"
        allow = out.headers["allow"].split(", ")
        assert " and ".join([", ".join(allow[:-1]), allow[-1]] if len(allow) > 1 else allow) == (
            takes
        )


@pytest.mark.parametrize(
    ("path", "body", "where", "said"),
    [
        ("/v1/solve", {**EXAMPLE, "targets": {"left_wrist": GOAL}}, "targets",
         'an object ({"left_wrist": [1.641, 1.322, -0.913]})'),
        ("/v1/solve", {**EXAMPLE, "pins": "left_ankle"}, "pins", 'a string ("left_ankle")'),
        ("/v1/solve", {**EXAMPLE, "targets": None}, "targets", "null"),
        ("/v1/solve/batch", {"items": {"a": 1}}, "items", 'an object ({"a": 1})'),
        ("/v1/complete", {"keypoints": {"pelvis": [0, 1, 0]}}, "keypoints",
         'an object ({"pelvis": [0, 1, 0]})'),
        ("/v1/solve/batch", {"poses": {"a": 1}, "targets": {"joints": ["left_wrist"],
         "positions": [GOAL]}}, "poses", 'an object ({"a": 1})'),
    ],
)  # fmt: skip
def test_an_array_given_as_something_else_says_what_came(
    client: Any, path: str, body: dict[str, Any], where: str, said: str
) -> None:
    """An array field given an object, a string or null says an array is required and what
    came, as an object field given an array does (`pose`: "a JSON object is required, not an
    array ([1, 2])"); it was pydantic's "Input should be a valid list", naming neither (an
    API audit, 2026-12-07)."""
    out = client.post(path, json=body)
    assert out.status_code == 422, out.text
    (error,) = out.json()["errors"]
    assert error["location"] == where, error
    assert error["message"].startswith("a JSON array is required, not "), error
    assert said in error["message"], error
    assert "valid list" not in out.json()["detail"], out.json()["detail"]


CHARACTER = json.loads((REPO_ROOT / "docs/examples/solve_character.json").read_text())
CLIP = json.loads((REPO_ROOT / "docs/examples/bvh_solve.json").read_text())


@pytest.mark.parametrize("value", [2e7, -1e300])
def test_a_character_number_past_its_bound_is_named(client: Any, value: float) -> None:
    """A character's number past ±1e7 in its own units (an offset, the root position, a
    target, in the JSON and the BVH forms) is named with its value and the bound, as the
    pose form names a coordinate past ±10 km (docs/characters.md, "Bounds": "a 422 names the
    value"); it was pydantic's "Input should be less than or equal to 10000000" (an API
    audit, 2026-12-07)."""
    offset = json.loads(json.dumps(CHARACTER))
    offset["character"]["joints"][1]["offset"][1] = value
    root = {**CHARACTER, "root_position": [0.0, value, 0.0]}
    aim = [{"joint": "left_wrist", "position": [0.0, value, 0.0]}]
    cases = [
        ("/v1/solve", offset, "character.joints[1].offset[1]"),
        ("/v1/solve", root, "root_position[1]"),
        ("/v1/solve", {**CHARACTER, "targets": aim}, "targets[0].position[1]"),
        ("/v1/bvh/solve", {**CLIP, "targets": aim}, "targets[0].position[1]"),
        ("/v1/bvh/solve/batch", {"bvh": CLIP["bvh"], "edits": [{"frame": 0, "targets": aim}]},
         "edits[0].targets[0].position[1]"),
    ]  # fmt: skip
    for path, body, where in cases:
        out = client.post(path, json=body)
        assert out.status_code == 422, out.text
        (error,) = out.json()["errors"]
        assert error["location"] == where, (path, error)
        said = "is beyond ±1e+07: a character's numbers are within ±1e+07 in its own units"
        assert error["message"] == f"{shown(value)} {said}", (path, error)


def test_too_many_items_names_the_setting_and_what_to_send_in_every_form(client: Any) -> None:
    """A batch past ``POSE_MAX_BATCH_ITEMS`` is told the same way in the item list, the
    columnar form (rows as lists or packed) and a clip's edits: the field, the count, the
    setting and what to send instead, as a body past ``POSE_MAX_BODY_BYTES`` is; it said the
    counts alone, with the field on one route only ("edits: 1025 exceed ...", "1025 items
    exceed ...": an API audit, 2026-12-07)."""
    many = 1025
    goal = {"joints": ["left_wrist"], "positions": [GOAL] * many}
    packed = base64.b64encode(np.array([ROW] * many, "<f8").tobytes()).decode()
    edit = {"frame": 0, "targets": CLIP["targets"]}
    for path, body, said in (
        ("/v1/solve/batch", {"items": [EXAMPLE] * many}, "items: 1025 items"),
        ("/v1/solve/batch", {"poses": [ROW] * many, "targets": goal}, "poses: 1025 items"),
        ("/v1/solve/batch", {"poses": packed, "targets": goal}, "poses: 1025 items"),
        ("/v1/bvh/solve/batch", {"bvh": CLIP["bvh"], "edits": [edit] * many}, "edits: 1025 edits"),
    ):
        out = client.post(path, json=body)
        assert out.status_code == 413, out.text
        assert out.json()["detail"] == (
            f"{said} exceed the limit of 1024 per batch (the server's POSE_MAX_BATCH_ITEMS): "
            "send them in several requests of at most 1024"
        ), out.json()["detail"]


def test_a_value_out_of_its_bounds_or_choices_is_quoted(client: Any) -> None:
    """A number past a field's bound and a word none of its choices say what came, as the
    trainer's config errors do (``, got 1.5``), in every form (the columnar weights'
    words are pydantic's too); pydantic's message alone named neither (`options.carry:
    Input should be less than or equal to 1`: an API audit, 2026-12-07)."""
    goal = {"joints": ["left_wrist"], "positions": [GOAL]}
    cases = [
        ("/v1/solve", {**EXAMPLE, "options": {"carry": 2}}, "options.carry",
         "Input should be less than or equal to 1, got 2"),
        ("/v1/solve", {**EXAMPLE, "options": {"reach": "exakt"}}, "options.reach",
         "Input should be 'soft' or 'exact', got \"exakt\""),
        ("/v1/solve/batch", {"poses": [ROW], "targets": goal, "options": {"passes": 9}},
         "options.passes", "Input should be less than or equal to 4, got 9"),
        ("/v1/solve/batch", {"poses": [ROW], "targets": {**goal, "weights": [-0.5]}},
         "targets.weights[0]", "Input should be greater than 0, got -0.5"),
        ("/v1/solve", {**CHARACTER, "character": {**CHARACTER["character"], "up": "Z"}},
         "character.up", "Input should be '+Y' or '+Z', got \"Z\""),
        ("/v1/bvh/solve", {**CLIP, "frame": -1}, "frame",
         "Input should be greater than or equal to 0, got -1"),
        ("/v1/complete", {"keypoints": [{"joint": "pelvis", "position": [0, 1, 0]}],
         "bone_lengths": {"left_wrist": 5}}, "bone_lengths.left_wrist",
         "Input should be less than or equal to 2, got 5"),
    ]  # fmt: skip
    says_one_error(client, cases)


def test_an_unknown_key_a_slip_of_a_field_is_offered_the_field(client: Any) -> None:
    """A key a letter off one of its object's fields (``tolerence``, ``target``) is offered
    that field, in every route and form, as a joint's name is; only pydantic's "Extra inputs
    are not permitted" was said (an API audit, 2026-12-07). A key near nothing of its object
    is told as before, and never offered a field of another object."""

    def renamed(body: dict[str, Any], old: str, new: str) -> dict[str, Any]:
        return {(new if k == old else k): v for k, v in body.items()}

    aim = {**EXAMPLE["targets"][0]}
    aim["positon"] = aim.pop("position")
    edit = {"frame": 0, "targets": CLIP["targets"], "optoins": {}}
    cases = [
        ("/v1/solve", {**EXAMPLE, "options": {"tolerence": 0.01}}, "options.tolerence",
         "tolerance"),
        ("/v1/solve", renamed(EXAMPLE, "targets", "target"), "target", "targets"),
        ("/v1/solve", {**EXAMPLE, "targets": [aim]}, "targets[0].positon", "position"),
        ("/v1/solve", renamed(CHARACTER, "rotations", "rotation"), "rotation", "rotations"),
        ("/v1/solve/batch", {"items": [renamed(EXAMPLE, "pins", "pin")]}, "items[0].pin",
         "pins"),
        ("/v1/solve/batch", {"item": [EXAMPLE]}, "item", "items"),
        ("/v1/solve/batch", {"poses": [ROW], "target": {}}, "target", "targets"),
        ("/v1/solve/batch", {"poses": [ROW], "targets": {"joints": ["left_wrist"],
         "positions": [GOAL], "weight": [1]}, "options": {"tolerence": 1}}, "targets.weight",
         "weights"),
        ("/v1/solve/batch", {"poses": [ROW], "targets": {"joints": ["left_wrist"],
         "positions": [GOAL]}, "options": {"tolerence": 1}}, "options.tolerence",
         "tolerance"),
        ("/v1/bvh/solve", renamed(CLIP, "frame", "frames"), "frames", "frame"),
        ("/v1/bvh/solve/batch", {"bvh": CLIP["bvh"], "edits": [edit]}, "edits[0].optoins",
         "options"),
        ("/v1/complete", {"keypoint": []}, "keypoint", "keypoints"),
    ]  # fmt: skip
    for path, body, where, meant in cases:
        out = client.post(path, json=body)
        assert out.status_code == 422, out.text
        errors = {e["location"]: e["message"] for e in out.json()["errors"]}
        assert errors.get(where) == (f"Extra inputs are not permitted (did you mean '{meant}'?)"), (
            path,
            errors,
        )
    out = client.post("/v1/solve", json={**EXAMPLE, "options": {"frame": 1}})
    (error,) = out.json()["errors"]  # (`frame` is a field of the BVH routes, not here)
    assert error == {"location": "options.frame", "message": "Extra inputs are not permitted"}


def test_a_404_for_a_slip_of_a_route_s_path_names_the_route(client: Any) -> None:
    """A path a letter or two off a route's (``/v1/slove``, ``/v1/skeleton`` misspelt) is
    answered with the route it may mean, whatever the method or content type, as a route's
    path with a trailing slash names its route; it was "Not Found" alone (an API audit,
    2026-12-07). A path near no route is the plain 404 it was."""
    for method, path, meant in (
        ("POST", "/v1/slove", "/v1/solve"),
        ("POST", "/v1/bvh/slove", "/v1/bvh/solve"),
        ("POST", "/v1/solve/bacth", "/v1/solve/batch"),
        ("GET", "/v1/skeletn", "/v1/skeleton"),
        ("GET", "/v2/health/raedy", "/v2/health/ready"),
    ):
        for headers in ({"content-type": "application/json"},
                        {"content-type": "application/x-www-form-urlencoded"}):  # fmt: skip
            out = client.request(method, path, json=EXAMPLE, headers=headers)
            assert out.status_code == 404, out.text
            assert out.headers["content-type"] == "application/problem+json"
            assert out.json()["detail"] == f"no route {path} (did you mean {meant}?)", out.text
    assert client.get("/nothing-here").json()["detail"] == "Not Found"
    assert client.post("/v1/x", json={}).json()["detail"] == "Not Found"


def test_a_value_of_the_wrong_json_type_says_what_came(client: Any) -> None:
    """A number, a whole number or a boolean given as another JSON type says what is
    required and what came, as an object or an array does, in every form; it was
    pydantic's "Input should be a valid number" (a string "2", a boolean), naming neither
    (an API audit, 2026-12-07)."""
    foot = {**EXAMPLE["pose"], "left_foot": [0.0, 1.0, "2"]}
    row = [*ROW[:4], True, *ROW[5:]]
    goal = {"joints": ["left_wrist"], "positions": [GOAL]}
    cases = [
        ("/v1/solve", {**EXAMPLE, "pose": foot}, "pose.left_foot[2]",
         'a number is required, not a string ("2")'),
        ("/v1/solve/batch", {"poses": [row], "targets": goal}, "poses[0][4]",
         "a number is required, not a boolean (true)"),
        ("/v1/solve", {**EXAMPLE, "options": {"mirror": "yes"}}, "options.mirror",
         'true or false is required, not a string ("yes")'),
        ("/v1/bvh/solve", {**CLIP, "frame": "3"}, "frame",
         'a whole number is required, not a string ("3")'),
        ("/v1/bvh/solve", {**CLIP, "frame": None}, "frame",
         "a whole number is required, not null"),
    ]  # fmt: skip
    says_one_error(client, cases)
