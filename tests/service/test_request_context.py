"""The last-resort answer (service.middleware.context.RequestContext): an app that fails
before it answers gets a 500 problem; one that fails after it started answering is not
answered twice."""

from __future__ import annotations

from typing import Any

from starlette.testclient import TestClient

from service.middleware.context import RequestContext


async def _fails(scope: Any, receive: Any, send: Any) -> None:
    raise RuntimeError("boom")


async def _fails_late(scope: Any, receive: Any, send: Any) -> None:
    await send({"type": "http.response.start", "status": 200, "headers": []})
    await send({"type": "http.response.body", "body": b"partial", "more_body": False})
    raise RuntimeError("boom")


def test_a_failure_before_the_answer_is_a_500_problem() -> None:
    r = TestClient(RequestContext(_fails)).get("/x")
    assert r.status_code == 500
    assert r.headers["content-type"].startswith("application/problem+json")
    assert r.json()["status"] == 500


def test_a_failure_after_the_answer_started_is_not_answered_again() -> None:
    r = TestClient(RequestContext(_fails_late)).get("/x")
    assert r.status_code == 200 and r.content == b"partial"
