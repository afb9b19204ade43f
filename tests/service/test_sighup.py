"""``SIGHUP`` to a single-worker ``pose-service`` (the image's and the manifest's way to
run it) killed it at once: exit 129, the requests in flight lost, no log line (an ops
audit, 2026-12-07; uvicorn handles SIGINT and SIGTERM only). It is logged and ignored
now (``service.cli``: docs/deploy.md says why not a stop), on a real server process."""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

import pytest

from tests.service.server import REPO, heavy_batch, serve

pytestmark = pytest.mark.slow


def test_sighup_is_logged_and_the_requests_in_flight_are_answered(
    models_dir: Path, tmp_path: Path
) -> None:
    body = (REPO / "docs" / "examples" / "solve.json").read_bytes()
    with serve(models_dir, tmp_path, POSE_DEADLINE_SECONDS="60") as s:
        answers: list[int] = []
        batch = heavy_batch(1024)
        clients = [
            threading.Thread(
                target=lambda: answers.append(s.request("POST", "/v1/solve/batch", batch)[0])
            )
            for _ in range(2)
        ]
        for client in clients:
            client.start()
        time.sleep(0.3)  # (the batches under way)
        busy = s.request("GET", "/metrics")[2].decode()
        assert "pose_requests_in_flight 3.0" in busy, busy  # both batches and the scrape
        s.proc.send_signal(signal.SIGHUP)
        time.sleep(0.2)
        s.proc.send_signal(signal.SIGHUP)
        for client in clients:
            client.join(120)
        assert answers == [200, 200], answers
        assert s.proc.poll() is None  # (it was gone at once, rc 129)
        assert s.request("POST", "/v1/solve", body)[0] == 200
        lines = [e for e in s.log_lines() if e.get("event") == "signal_ignored"]
        assert len(lines) == 2, lines
        assert lines[0]["signal"] == "SIGHUP" and lines[0]["level"] == "warning", lines
        assert "restart the service" in lines[0]["detail"], lines
        s.proc.send_signal(signal.SIGTERM)  # and SIGTERM still stops it
        assert s.proc.wait(30) in (0, -signal.SIGTERM)
