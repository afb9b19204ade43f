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
