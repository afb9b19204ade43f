"""Several worker processes (``pose-service --workers N``): ``/metrics`` answers the
service's counts, the sum over its workers, whichever worker takes the scrape
(``service.metrics.shared``: prometheus_client's multiprocess mode)."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from tests.service.server import REPO, Server, serve

pytestmark = pytest.mark.slow


def _solves(text: str) -> float:
    """``pose_requests_total`` of ``/v1/solve`` answered 200, in a scrape's text."""
    for line in text.splitlines():
        head = line.startswith("pose_requests_total{")
        if head and 'route="/v1/solve"' in line and 'status="200"' in line:
            return float(line.rsplit(" ", 1)[1])
    return 0.0


def _all_ready(server: Server, times: int = 12) -> None:
    """Readiness is each worker's, and each connection goes to either: ready ``times``
    times in a row on fresh connections."""
    deadline, streak = time.monotonic() + 120, 0
    while streak < times:
        assert time.monotonic() < deadline, "the workers did not all become ready"
        streak = streak + 1 if server.request("GET", "/v2/health/ready")[0] == 200 else 0
        time.sleep(0.05)


def _per_worker(folder: Path) -> list[float]:
    """Each worker's own count of 200 answers to ``/v1/solve``, from its files."""
    from prometheus_client import multiprocess

    out = []
    for f in sorted(folder.glob("counter_*.db")):
        families = multiprocess.MultiProcessCollector.merge([str(f)], accumulate=False)
        out.append(
            sum(
                s.value
                for m in families
                if m.name == "pose_requests"
                for s in m.samples
                if s.labels.get("route") == "/v1/solve" and s.labels.get("status") == "200"
            )
        )
    return out


def test_metrics_are_the_sum_over_the_workers(models_dir: Path, tmp_path: Path) -> None:
    body = (REPO / "docs" / "examples" / "solve.json").read_bytes()
    with serve(models_dir, tmp_path, argv=["--workers", "2"], TMPDIR=str(tmp_path)) as server:
        _all_ready(server)
        (folder,) = tmp_path.glob("marionette-metrics-*")  # pose-service made it
        n = 40
        for _ in range(n):  # a connection each: the kernel hands them to either worker
            assert server.request("POST", "/v1/solve", body)[0] == 200
        texts = [server.request("GET", "/metrics")[2].decode() for _ in range(10)]
        scrapes = [_solves(text) for text in texts]
        each = _per_worker(folder)
    assert scrapes == [float(n)] * 10, (scrapes, each)
    # the closes' series are there at 0 before any close, summed over the workers too
    assert all('pose_connections_closed_total{reason="evicted"} 0.0' in t for t in texts)
    # the process's series (the worker that took the scrape: the workers' files hold none)
    # and the requests under way, summed over the live workers: the scrape itself, and the
    # request before it if its worker had not yet counted it out when the other worker read
    # the files (an ops audit, 2026-12-07: neither series was there)
    for text in texts:
        lines = text.splitlines()
        rss = [x for x in lines if x.startswith("process_resident_memory_bytes ")]
        assert len(rss) == 1 and float(rss[0].split()[1]) > 50 * 2**20, rss
        (busy,) = [x for x in lines if x.startswith("pose_requests_in_flight ")]
        assert busy in ("pose_requests_in_flight 1.0", "pose_requests_in_flight 2.0"), busy
    assert len(each) == 2 and sum(each) == n and min(each) > 0, each  # both answered some
    assert not list(tmp_path.glob("marionette-metrics-*"))  # removed at the end
