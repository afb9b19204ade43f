"""Cross-field checks of the options (service/validation.py ``check_options``) through the
real routes, in every request form: ``preserve_bone_lengths: false`` beside what keeps the
bone lengths by construction is a 422 naming both fields (was: silently ignored, the
answer byte for byte that of ``true``: an audit, 2026-12-06)."""

from __future__ import annotations

import copy
import json
from typing import Any

import pytest

from core.rest import rest_pose
from core.skeleton import JOINT_NAMES
from tests.conftest import REPO_ROOT
from tests.service.test_api import assert_problem

EXAMPLES = REPO_ROOT / "docs" / "examples"
RAW = {"preserve_bone_lengths": False}


def _example(name: str) -> dict[str, Any]:
    body: dict[str, Any] = json.loads((EXAMPLES / f"{name}.json").read_text())
    return body


def _refused(client: Any, path: str, body: dict[str, Any], where: str, *against: str) -> None:
    r = client.post(path, json=body)
    assert_problem(r, 422)
    (error,) = r.json()["errors"]
    assert error["location"] == f"{where}options.preserve_bone_lengths", r.text
    for field in against:
        assert field in error["message"], r.text
    assert "by construction" in error["message"]


#: (options beside ``preserve_bone_lengths: false``, pins, the fields named)
CONFLICTS = [
    ({}, ["left_ankle"], ("pins",)),
    ({"reach": "exact"}, [], ('options.reach "exact"',)),
    ({"method": "fabrik"}, [], ('options.method "fabrik"',)),
    ({"method": "fabrik", "reach": "exact"}, ["left_ankle"],
     ('options.method "fabrik"', 'options.reach "exact"', "pins")),
]  # fmt: skip


def _single(options: dict[str, Any], pins: list[str]) -> dict[str, Any]:
    body = _example("solve")
    body["options"], body["pins"] = {**options, **RAW}, pins
    return body


@pytest.mark.parametrize(("options", "pins", "against"), CONFLICTS)
def test_raw_answer_beside_what_keeps_bones_is_refused_in_the_pose_forms(
    client: Any, options: dict[str, Any], pins: list[str], against: tuple[str, ...]
) -> None:
    """The single pose form, the batch's item list (naming the item) and the columnar
    batch (one ``options`` for every item)."""
    body = _single(options, pins)
    _refused(client, "/v1/solve", body, "", *against)
    items = [_example("solve"), body]
    _refused(client, "/v1/solve/batch", {"items": items}, "items[1].", *against)
    pose = [v for n in JOINT_NAMES for v in body["pose"][n]]
    columns = {
        "poses": [pose, pose],
        "targets": {"joints": ["left_wrist"], "positions": [body["targets"][0]["position"]] * 2},
        "options": body["options"],
        **({"pins": pins} if pins else {}),
    }
    _refused(client, "/v1/solve/batch", columns, "", *against)


@pytest.mark.parametrize(("options", "pins", "against"), CONFLICTS)
def test_raw_answer_beside_what_keeps_bones_is_refused_in_the_character_forms(
    client: Any, options: dict[str, Any], pins: list[str], against: tuple[str, ...]
) -> None:
    """A character (its own joint names for the pins), in ``/v1/solve`` and its alias
    route, as a batch item, and a BVH file."""
    names = {"left_ankle": "LeftFoot"}
    body = _example("solve_character")
    body["options"], body["pins"] = {**options, **RAW}, [names[p] for p in pins]
    _refused(client, "/v1/solve", body, "", *against)
    _refused(client, "/v1/character/solve", body, "", *against)
    _refused(client, "/v1/solve/batch", {"items": [_example("solve"), body]}, "items[1].", *against)
    bvh = _example("bvh_solve")
    bvh["options"], bvh["pins"] = {**options, **RAW}, [names[p] for p in pins]
    _refused(client, "/v1/bvh/solve", bvh, "", *against)


def test_the_raw_answer_and_the_kept_bones_are_answered_as_before(client: Any) -> None:
    """``false`` with the neural method, soft reach and no pins is the raw answer (its
    bones not kept); ``true`` beside pins, exact reach or FABRIK is answered as it was."""
    raw = client.post("/v1/solve", json=_single({"reach": "soft"}, []))
    assert raw.status_code == 200, raw.text
    kept = client.post("/v1/solve", json={**_single({"reach": "soft"}, []), "options": {}})
    assert kept.status_code == 200, kept.text
    assert raw.json()["max_bone_length_error"] > 1e-3 > kept.json()["max_bone_length_error"]
    for options, pins, _ in CONFLICTS:
        body = _single(options, pins)
        body["options"]["preserve_bone_lengths"] = True
        r = client.post("/v1/solve", json=body)
        assert r.status_code == 200, r.text
        assert r.json()["max_bone_length_error"] < 1e-9
    for name in ("solve", "batch", "solve_character", "character_solve", "bvh_solve"):
        path = {"batch": "/v1/solve/batch", "character_solve": "/v1/character/solve"}
        body = copy.deepcopy(_example(name))
        r = client.post(path.get(name, "/v1/bvh/solve" if name == "bvh_solve" else "/v1/solve"),
                        json=body)  # fmt: skip
        assert r.status_code == 200, (name, r.text)


@pytest.mark.parametrize("path", ["/v1/solve", "/v1/solve/batch", "/v1/complete", "/v1/bvh/solve"])
@pytest.mark.parametrize(("raw", "what"), [("null", "null"), ("[]", "an array"),
                                           ("3", "a number"), ('"x"', "a string")])  # fmt: skip
def test_a_body_that_is_no_json_object_is_told_so(
    client: Any, path: str, raw: str, what: str
) -> None:
    """Told in JSON's words, not pydantic's Python class names ('a valid dictionary or
    instance of BatchRequest', which named only the item list: an API audit); a batch
    is told both of its forms."""
    resp = client.post(path, content=raw, headers={"content-type": "application/json"})
    assert_problem(resp, 422, "body: a JSON object", f"is required, not {what}")
    assert ("columnar form" in resp.json()["detail"]) == (path == "/v1/solve/batch")


def test_a_batch_is_told_every_items_cross_field_errors(client: Any) -> None:
    """An item list whose items break cross-field checks (a pin on a target, a pin twice):
    every bad item is named, in order, as field errors are (only the first was, and a
    batch client fixed one item a round trip: an API audit, 2026-12-06); past 20, the
    count."""
    pose = dict(zip(JOINT_NAMES, rest_pose().tolist(), strict=True))
    target = [{"joint": "left_wrist", "position": [0.5, 1.2, 0.3]}]

    def item(pins: list[str]) -> dict[str, Any]:
        return {"pose": pose, "targets": target, "pins": pins}

    good, on_target, twice = item([]), item(["left_wrist"]), item(["left_foot", "left_foot"])
    resp = client.post("/v1/solve/batch", json={"items": [on_target, good, twice, on_target]})
    assert_problem(resp, 422, "items[0].pins[0]", "items[2].pins[1]", "items[3].pins[0]")
    assert [e["location"] for e in resp.json()["errors"]] == [
        "items[0].pins[0]", "items[2].pins[1]", "items[3].pins[0]"
    ]  # fmt: skip
    assert resp.json()["errors"][1]["message"] == "joint 'left_foot' is pinned twice"
    resp = client.post("/v1/solve/batch", json={"items": [on_target] * 30})
    assert len(resp.json()["errors"]) == 20 and resp.json()["detail"].endswith("; and 27 more")
    one = client.post("/v1/solve/batch", json={"items": [good, twice]})
    assert one.json()["detail"] == "items[1].pins[1]: joint 'left_foot' is pinned twice"
