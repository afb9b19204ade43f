"""Every request body in ``docs/examples`` (the README's API tour and docs/characters.md
post them with curl) runs against the real app with the shipped models and gets the answer
the docs say: an example added without a route here fails the suite."""

from __future__ import annotations

import json
from typing import Any

import pytest

from tests.conftest import REPO_ROOT

EXAMPLES = REPO_ROOT / "docs" / "examples"
#: file -> (route, status)
ROUTES: dict[str, tuple[str, int]] = {
    "solve.json": ("/v1/solve", 200),
    "solve_character.json": ("/v1/solve", 200),
    "character_solve.json": ("/v1/character/solve", 200),
    "complete.json": ("/v1/complete", 200),
    "batch.json": ("/v1/solve/batch", 200),
    "bvh_solve.json": ("/v1/bvh/solve", 200),
    "bvh_solve_batch.json": ("/v1/bvh/solve/batch", 200),
    "bad.json": ("/v1/solve", 422),
}


def load(name: str) -> Any:
    return json.loads((EXAMPLES / name).read_text(encoding="utf-8"))


def test_every_example_has_a_route() -> None:
    assert sorted(p.name for p in EXAMPLES.glob("*.json")) == sorted(ROUTES)


@pytest.mark.parametrize("name", list(ROUTES))
def test_example_runs(client: Any, name: str) -> None:
    route, status = ROUTES[name]
    r = client.post(route, json=load(name))
    assert r.status_code == status, r.text
    if status == 200:
        assert r.headers["content-type"] == "application/json"
        assert r.headers["x-compute-time"].endswith("ms")


@pytest.mark.parametrize("name", [n for n, (_, status) in ROUTES.items() if status == 200])
def test_example_is_valid_by_the_contract(name: str) -> None:
    """Each example is a body openapi.yaml allows for its route (a contract audit: the
    alias's example, with the earlier field name ``skeleton``, was answered 200 but invalid
    by the schema, so a client generated from it could not send it); the alias with both
    names is not."""
    import jsonschema_rs
    import yaml

    spec = yaml.safe_load((REPO_ROOT / "openapi.yaml").read_text(encoding="utf-8"))
    route, _ = ROUTES[name]
    body_schema = spec["paths"][route]["post"]["requestBody"]["content"]["application/json"]
    validator = jsonschema_rs.validator_for({**body_schema["schema"], **spec})  # refs: #/...
    body = load(name)
    assert validator.is_valid(body), [e.message for e in validator.iter_errors(body)]
    if "skeleton" in body:
        assert not validator.is_valid({**body, "character": body["skeleton"]})


def test_character_examples_answer_alike(client: Any) -> None:
    """``solve_character.json`` (the character form of /v1/solve) and
    ``character_solve.json`` (the alias, with the earlier field name ``skeleton``) are one
    request: the same answer, byte for byte, reaching the target (exact reach)."""
    new, old = load("solve_character.json"), load("character_solve.json")
    assert new == {("character" if k == "skeleton" else k): v for k, v in old.items()}
    r = client.post("/v1/solve", json=new)
    assert r.content == client.post("/v1/character/solve", json=old).content
    out = r.json()
    assert set(out["rotations"]) == {j["name"] for j in new["character"]["joints"]}
    assert len(out["pins"]) == 2  # feet pinned on legs almost straight: every one held
    assert all(t["reached"] for t in out["targets"] + out["pins"]), out["pins"]
    assert out["scheme"] == "mixamo"
