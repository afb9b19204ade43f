"""``service.field_names``: the object an unknown key is in, found by walking the request
model along its location (the body choosing a union's member), and the field it is a slip
of. Through the routes: ``tests/service/test_problem_wording.py``."""

from __future__ import annotations

import json
from typing import Any

from service.bvh_models import BVHBatchRequest
from service.characters import SolveBody
from service.field_names import fields_at, offered
from service.routes.solve import BatchBody
from tests.conftest import REPO_ROOT

EXAMPLES = REPO_ROOT / "docs" / "examples"


def _example(name: str) -> dict[str, Any]:
    body: dict[str, Any] = json.loads((EXAMPLES / f"{name}.json").read_text())
    return body


def test_the_object_at_a_location_is_found_through_unions_lists_and_dicts() -> None:
    pose, character = _example("solve"), _example("solve_character")
    assert "tolerance" in fields_at(SolveBody, pose, ("options",))
    assert "position" in fields_at(SolveBody, pose, ("targets", 0))
    assert "rotations" in fields_at(SolveBody, character, ())  # the character form's
    assert "pose" in fields_at(SolveBody, pose, ())  # the pose form's
    assert "parent" in fields_at(SolveBody, character, ("character", "joints", 3))
    batch = {"items": [pose, character]}
    assert "pins" in fields_at(BatchBody, batch, ("items", 0))
    assert "rotations" in fields_at(BatchBody, batch, ("items", 1))
    clip = _example("bvh_solve_batch")
    assert "frame" in fields_at(BVHBatchRequest, clip, ("edits", 0))
    assert fields_at(SolveBody, pose, ("nowhere", 3, "deep")) == []  # lost: nothing


def test_only_a_slip_of_its_own_object_s_field_is_offered() -> None:
    body = {**_example("solve"), "options": {"tolerence": 1, "frame": 0, "zzz": 1}}
    errors: list[Any] = [
        {"type": "extra_forbidden", "loc": ("options", key), "msg": "", "input": 1}
        for key in ("tolerence", "frame", "zzz")
    ]
    offered(errors, SolveBody, body)
    assert [e.get("ctx", {}).get("meant") for e in errors] == ["tolerance", None, None]


def test_a_slip_of_an_earlier_name_is_offered_it(client: Any) -> None:
    """``/v1/character/solve`` still takes the character under its earlier name
    ``skeleton``: ``skeletn`` was offered nothing (an API audit, 2026-12-07)."""
    from service.characters import CharacterAliasRequest

    body = _example("character_solve")
    body["skeletn"] = body.pop("skeleton")
    assert "skeleton" in fields_at(CharacterAliasRequest, body, ())
    r = client.post("/v1/character/solve", json=body)
    assert r.status_code == 422
    got = {e["location"]: e["message"] for e in r.json()["errors"]}
    assert "did you mean 'skeleton'?" in got["skeletn"], got


def test_a_columnar_batch_without_poses_is_told_so_and_no_key_is_offered_itself(
    client: Any,
) -> None:
    """An API audit (2026-12-08): ``{"pins": [], "targets": {}}`` was read as the item list
    and told "pins: Extra inputs are not permitted (did you mean 'pins'?)". Now a body with
    the columnar form's keys and no ``items`` is read as that form, and a key unknown where
    it is is never offered its own name."""
    from service.field_names import slip_of

    assert slip_of("pins", ["poses", "targets", "pins"]) is None
    for body in ({"pins": [], "targets": {}}, {"targets": {"joints": ["head"]}}):
        r = client.post("/v1/solve/batch", json=body)
        assert r.status_code == 422, r.text
        got = {e["location"]: e["message"] for e in r.json()["errors"]}
        assert got["poses"] == "Field required", got
        assert "items" not in got and "did you mean" not in r.text, got
    r = client.post("/v1/solve/batch", json={"items": [], "pins": []})  # both: as before
    assert "a batch takes one form, not both" in r.json()["detail"], r.text
