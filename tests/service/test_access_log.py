"""The access log (service.middleware.context): one JSON line per request at INFO, with
the request id the client sees; nothing at all when the level is above INFO."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import make_client


def test_one_json_line_per_request_with_its_id(client: Any, caplog: pytest.LogCaptureFixture
                                               ) -> None:  # fmt: skip
    with caplog.at_level(logging.INFO, logger="service.access"):
        r = client.get("/v2/health/live", headers={"X-Request-ID": "abc-123"})
    lines = [json.loads(rec.getMessage()) for rec in caplog.records if rec.name == "service.access"]
    assert r.headers["x-request-id"] == "abc-123"
    assert len(lines) == 1
    line = lines[0]
    assert line["event"] == "request" and line["request_id"] == "abc-123"
    assert line["method"] == "GET" and line["path"] == "/v2/health/live"
    assert line["status"] == 200 and line["ms"] >= 0


def test_no_line_above_info(client: Any, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="service.access"):
        client.get("/v2/health/live")
    assert not [rec for rec in caplog.records if rec.name == "service.access"]


def test_a_cors_preflight_has_its_line_too(
    models_dir: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The CORS middleware answers a preflight itself, outside the access log's: it wrote
    no line (noticed at stop 36). Allowed and refused alike now do."""
    with (
        make_client(models_dir, cors_origins=["http://editor.example"]) as c,
        caplog.at_level(logging.INFO, logger="service.access"),
    ):
        for origin in ("http://editor.example", "http://evil.example"):
            ask = {"Origin": origin, "X-Request-ID": origin[7:],
                   "Access-Control-Request-Method": "POST"}  # fmt: skip
            c.options("/v1/solve", headers=ask)
    lines = [json.loads(rec.getMessage()) for rec in caplog.records if rec.name == "service.access"]
    assert [(ln["method"], ln["path"], ln["status"], ln["request_id"]) for ln in lines] == [
        ("OPTIONS", "/v1/solve", 200, "editor.example"),
        ("OPTIONS", "/v1/solve", 400, "evil.example"),
    ]
