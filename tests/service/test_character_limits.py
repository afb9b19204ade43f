"""The character routes keep the solve routes' limits: the deadline (504) checked before each
stage, the admission bound (429), the work in worker threads under the compute limiter,
``X-Compute-Time`` on the answer."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pytest

from service import characters
from service.character_bvh import read_request_bvh
from service.characters import solve_character
from service.routes import characters as routes
from tests.conftest import REPO_ROOT, make_client
from tests.service.test_api import assert_problem

EXAMPLES = REPO_ROOT / "docs" / "examples"
ROUTES = ["/v1/character/solve", "/v1/bvh/solve", "/v1/bvh/inspect"]


def example(route: str) -> dict[str, Any]:
    if route == "/v1/character/solve":
        body: dict[str, Any] = json.loads((EXAMPLES / "character_solve.json").read_text())
        return body
    body = json.loads((EXAMPLES / "bvh_solve.json").read_text())
    if route == "/v1/bvh/inspect":
        return {"bvh": body["bvh"], "frame": body["frame"]}
    return body


@pytest.mark.parametrize("route", ROUTES)
def test_past_the_deadline_is_a_504_problem(models_dir: Path, route: str) -> None:
    with make_client(models_dir, unchecked={"deadline_seconds": 0.001}) as c:
        resp = c.post(route, json=example(route))
        assert_problem(resp, 504, "0.001 s deadline", "before ")
        assert resp.headers["retry-after"] == "1"
        metrics = c.get("/metrics").text
        assert f'pose_rejections_total{{reason="deadline-exceeded",route="{route}"}}' in metrics


def test_the_deadline_is_checked_between_reading_and_solving(
    models_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def read(text: str, frame: int | None = None) -> Any:
        time.sleep(0.6)
        return read_request_bvh(text, frame)

    solved: list[int] = []
    monkeypatch.setattr(routes, "read_request_bvh", read)
    monkeypatch.setattr(routes, "solve_character", lambda *a: solved.append(1))
    with make_client(models_dir, deadline_seconds=0.5) as c:
        resp = c.post("/v1/bvh/solve", json=example("/v1/bvh/solve"))
        assert_problem(resp, 504, "0.5 s deadline", "before the solve")
    assert not solved  # stopped before computing an answer nobody would read


@pytest.mark.parametrize("route", ROUTES)
def test_past_the_admission_bound_is_a_429_problem(
    models_dir: Path, route: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    from tests.service.test_hardening import BUDGET, holding

    holding(monkeypatch)  # (an idle worker admits any body the body limit admits)
    with make_client(models_dir, **BUDGET) as c:
        body = example(route)
        if route == "/v1/character/solve":  # the example is small: pad it past the bound
            body["pad"] = " " * 4096
        resp = c.post(route, content=json.dumps(body), headers={"content-type": "application/json"})
        assert_problem(resp, 429, "body bytes in flight")
        assert resp.headers["retry-after"] == "1"


def test_the_work_runs_under_the_compute_limiter(
    models_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    borrowed: list[float] = []

    def solve(*args: Any) -> Any:
        borrowed.append(app.state.compute_limiter.borrowed_tokens)
        return solve_character(*args)

    def solve_prepared(*args: Any) -> Any:  # the character route's (and /v1/solve's) solve
        borrowed.append(app.state.compute_limiter.borrowed_tokens)
        return characters.solve_prepared(*args)

    monkeypatch.setattr(routes, "solve_character", solve)
    monkeypatch.setattr(routes, "solve_prepared", solve_prepared)
    with make_client(models_dir, compute_threads=1) as c:
        app = c.app
        for route in ROUTES[:2]:
            resp = c.post(route, json=example(route))
            assert resp.status_code == 200, resp.text
            assert resp.headers["x-compute-time"].endswith("ms")
            assert float(resp.headers["x-compute-time"][:-2]) > 0
    assert borrowed == [1, 1]


def test_a_mixed_batch_past_its_deadline_says_what_it_counted(models_dir: Path) -> None:
    """The pose items of a mixed batch run first, its characters after: a 504 among the
    pose items counts them as pose items (it said "N of 600 items" of a 602-item batch)."""
    pose_form = json.loads((EXAMPLES / "solve.json").read_text())
    heavy = {"reach": "exact", "passes": 4, "turn_search": True}
    five = ["head", "left_wrist", "right_wrist", "left_elbow", "right_knee"]
    targets = [{"joint": j, "position": [c + 0.2 for c in pose_form["pose"][j]]} for j in five]
    item = {"pose": pose_form["pose"], "targets": targets, "options": heavy}
    char = example("/v1/character/solve")
    char["character"] = char.pop("skeleton")  # (the batch's name of the alias route's key)
    items = [item] * 600 + [char] * 2
    with make_client(models_dir, deadline_seconds=0.5) as c:
        resp = c.post("/v1/solve/batch", json={"items": items})
        body = assert_problem(resp, 504, "0.5 s deadline")
        assert "of 600 pose items (then 2 character items) done" in body["detail"], body


def test_a_character_batch_its_own_work_took_past_the_deadline_counts_and_says_no_retry(
    models_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A batch of character items, each solved in a stage of its own, its own work past the
    deadline: the 504 counts the items done, in its detail and as members, and carries no
    ``Retry-After`` (it said "retry" with ``Retry-After: 1`` and no counts, so a client that
    obeys it sent the same 600 items again every second: a user's audit, 2026-12-06).
    Each solve here takes 100 ms more than its own, the deadline 1 s (40 ms of 0.4 s: at a
    load of 6-8 on 2 cores, pytest-xdist's other worker and other suites, the items'
    preparing took 0.34 s, and the deadline passed before the first was solved)."""

    def slow(*args: Any) -> Any:
        time.sleep(0.1)
        return characters.solve_prepared(*args)

    monkeypatch.setattr(routes, "solve_prepared", slow)
    char = example("/v1/character/solve")
    char["character"] = char.pop("skeleton")  # (the batch's name of the alias route's key)
    with make_client(models_dir, deadline_seconds=1.0) as c:
        resp = c.post("/v1/solve/batch", json={"items": [char] * 20})
        body = assert_problem(resp, 504, "1 s deadline (before solving items[")
        assert "retry-after" not in resp.headers
        assert 0 < body["done"] < body["total"] == 20, body
        assert f"{body['done']} of 20 items done" in body["detail"]
        assert "s of its own compute); send a smaller request" in body["detail"]
