"""The access log (service.middleware.context): one JSON line per request at INFO, with
the request id the client sees; nothing at all when the level is above INFO."""

from __future__ import annotations

import json
import logging
from typing import Any

import pytest


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
