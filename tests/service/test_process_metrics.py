"""What ``/metrics`` tells of the process and of requests the other series missed (an ops
audit, 2026-12-07): no ``process_*`` series (the app's own registry had no process
collector), no gauge of requests under way, the not-ready refusal counted as
``reason="503"`` on ``/v2/health/ready`` but ``"not-ready"`` on ``/v1``, CORS preflights
in no count (answered outside the metrics layer), and ``pose_request_seconds`` buckets
that stopped at 5 s under a deadline that may be 600 s. With ``--workers N``:
``tests/service/test_workers.py``."""

from __future__ import annotations

import http.client
import json
import threading
from pathlib import Path

import pytest

from tests.service.server import REPO, Server, heavy_batch, serve
from tests.service.test_logs import _after, _corrupt_but_listed

pytestmark = pytest.mark.slow

ORIGIN = "http://editor.example"


def _value(text: str, series: str) -> float:
    (line,) = [x for x in text.splitlines() if x.startswith(series + " ")]
    return float(line.rsplit(" ", 1)[1])


def _preflight(server: Server, origin: str) -> int:
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=10)
    try:
        conn.request("OPTIONS", "/v1/solve", headers={
            "origin": origin, "access-control-request-method": "POST",
        })  # fmt: skip
        return conn.getresponse().status
    finally:
        conn.close()


def test_process_series_in_flight_gauge_preflights_and_long_buckets(
    models_dir: Path, tmp_path: Path
) -> None:
    env = {"POSE_CORS_ORIGINS": json.dumps([ORIGIN]), "POSE_DEADLINE_SECONDS": "60"}
    with serve(models_dir, tmp_path, **env) as s:
        text = s.request("GET", "/metrics")[2].decode()
        rss = _value(text, "process_resident_memory_bytes")
        assert 50 * 2**20 < rss < 4 * 2**30, rss  # a worker with its models: ~300 MiB
        assert _value(text, "process_open_fds") >= 3
        assert _value(text, "process_cpu_seconds_total") > 0
        assert "python_info{" in text and "python_gc_objects_collected_total{" in text
        assert _value(text, "pose_requests_in_flight") == 1.0  # (the scrape itself)

        answers: list[int] = []
        batch = heavy_batch(1024)
        worker = threading.Thread(
            target=lambda: answers.append(s.request("POST", "/v1/solve/batch", batch)[0])
        )
        worker.start()
        seen = 0.0
        while worker.is_alive() and seen < 2:
            seen = _value(s.request("GET", "/metrics")[2].decode(), "pose_requests_in_flight")
        worker.join()
        assert answers == [200] and seen == 2.0, (answers, seen)  # the batch and the scrape

        assert _preflight(s, ORIGIN) == 200
        assert _preflight(s, "http://evil.example") == 400
        assert _preflight(s, "http://evil.example") == 400
        text = s.request("GET", "/metrics")[2].decode()
        assert _value(text, 'pose_cors_preflights_total{result="allowed"}') == 1
        assert _value(text, 'pose_cors_preflights_total{result="refused"}') == 2
        assert _value(text, "pose_requests_in_flight") == 1.0
        buckets = [x for x in text.splitlines() if x.startswith("pose_request_seconds_bucket{")]
        les = {x.split('le="', 1)[1].split('"', 1)[0] for x in buckets}
        assert {"2.5", "10.0", "60.0", "600.0", "+Inf"} <= les, les


def test_a_not_ready_refusal_is_one_reason_on_every_route(models_dir: Path, tmp_path: Path) -> None:
    """Readiness's 503 was ``reason="503"``, /v1's for the same models ``not-ready`` (or
    ``models-failed``): one problem type now, in the metrics and the access log."""
    broken = _corrupt_but_listed(models_dir, tmp_path / "models")
    with serve(broken, tmp_path, ready=False) as s:
        status = _after(s, "/v2/health/ready", "loading models")[0]
        assert status == 503
        body = (REPO / "docs" / "examples" / "solve.json").read_bytes()
        assert s.request("POST", "/v1/solve", body)[0] == 503
        text = s.request("GET", "/metrics")[2].decode()
    rejections = {
        x.split("{", 1)[1].split("}", 1)[0]
        for x in text.splitlines()
        if x.startswith("pose_rejections_total{")
    }
    assert 'reason="models-failed",route="/v2/health/ready"' in rejections, rejections
    assert 'reason="models-failed",route="/v1/solve"' in rejections, rejections
    assert not any('reason="503"' in r for r in rejections), rejections
    lines = [e for e in s.log_lines() if e.get("event") == "request" and e["status"] == 503]
    assert {e.get("outcome") for e in lines} == {"unavailable"}, lines
