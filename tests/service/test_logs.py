"""What an operator reads and acts on (an ops audit of 2026-12-06): every log line's
``level`` and ``time`` (``service.logs``), a corrupt model file named with its entry
(``service.runtime``), a load that failed for good told apart from one under way
(``service.repository``: no ``Retry-After``), and the exit status after SIGTERM."""

from __future__ import annotations

import hashlib
import json
import logging
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from core.rest import rest_pose
from core.skeleton import JOINT_NAMES
from service.logs import JSONLines
from tests.conftest import REPO_ROOT, make_client
from tests.service.server import Server, serve

#: RFC 3339, UTC, milliseconds
TIME = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z")
LEVELS = {"trace", "debug", "info", "warning", "error", "critical"}
SOLVE = json.dumps(
    {
        "pose": dict(zip(JOINT_NAMES, rest_pose().tolist(), strict=True)),
        "targets": [{"joint": "left_wrist", "position": [0.5, 1.2, 0.3]}],
    }
).encode()


def _line(level: int, message: str, exc: bool = False) -> dict[str, Any]:
    record = logging.LogRecord("service", level, __file__, 1, message, (), None)
    record.created = 1796540462.3456  # 2026-12-06T07:01:02.345Z
    if exc:
        try:
            raise ValueError("boom")
        except ValueError:
            record.exc_info = sys.exc_info()
    text = JSONLines().format(record)
    assert "\n" not in text  # one object per line, a traceback's too
    line: dict[str, Any] = json.loads(text)
    return line


def test_every_line_has_its_level_and_time_the_services_own_events_too() -> None:
    """The service's own events were passed through without a level (a failed model load,
    logged as an error, had none: an alert on level=error missed it) and no line had a
    time."""
    event = '{"event": "models_not_ready", "models_dir": "m", "reason": "x.onnx: bad"}'
    own = _line(logging.ERROR, event)
    assert own == {
        "time": "2026-12-06T07:01:02.345Z",
        "level": "error",
        "event": "models_not_ready",
        "models_dir": "m",
        "reason": "x.onnx: bad",
    }
    assert list(own)[:3] == ["time", "level", "event"]
    wrapped = _line(logging.WARNING, "Invalid HTTP request received.")
    assert wrapped == {
        "time": "2026-12-06T07:01:02.345Z",
        "level": "warning",
        "event": "log",
        "logger": "service",
        "message": "Invalid HTTP request received.",
    }
    failed = _line(logging.CRITICAL, "failed", exc=True)
    assert failed["level"] == "critical" and "ValueError: boom" in failed["exception"]
    # something that only looks like an object is a message; an event's own field named
    # like ours is kept under another name, never a second key of one object
    assert _line(logging.INFO, "{not json}")["message"] == "{not json}"
    clash = _line(logging.INFO, '{"event": "e", "level": 3, "time": "then"}')
    assert (clash["level"], clash["event_level"], clash["event_time"]) == ("info", 3, "then")


def _corrupt_but_listed(models_dir: Path, to: Path) -> Path:
    """The models with ``encoder.onnx`` cut to 5,000 bytes and its manifest entry made
    to match (a re-export gone wrong, a manifest regenerated over a partial sync)."""
    shutil.copytree(models_dir, to)
    cut = (to / "encoder.onnx").read_bytes()[:5000]
    (to / "encoder.onnx").write_bytes(cut)
    manifest = json.loads((to / "manifest.json").read_text())
    for entry in manifest["models"]:
        if entry["file"] == "encoder.onnx":
            entry["sha256"], entry["bytes"] = hashlib.sha256(cut).hexdigest(), len(cut)
    (to / "manifest.json").write_text(json.dumps(manifest, indent=2))
    return to


def test_a_corrupt_file_the_manifest_matches_is_named_with_its_entry(
    models_dir: Path, tmp_path: Path
) -> None:
    """onnxruntime's "INVALID_PROTOBUF : Failed to load model because protobuf parsing
    failed." named none of the ~50 files; and a load that failed for good answered
    ``Retry-After: 5``, a retry that never helps (the service does not load again)."""
    broken = _corrupt_but_listed(models_dir, tmp_path / "private" / "models")
    with make_client(broken) as c:
        ready = c.get("/v2/health/ready")
        solve = c.post("/v1/solve", content=SOLVE, headers={"content-type": "application/json"})
    detail = ready.json()["detail"]
    assert ready.status_code == 503 and "retry-after" not in ready.headers, ready.headers
    assert detail.startswith("models failed to load: encoder.onnx: model 'autoencoder'"), detail
    assert "INVALID_PROTOBUF" in detail and "does not retry" in detail
    problem = solve.json()
    assert solve.status_code == 503 and "retry-after" not in solve.headers, solve.headers
    assert problem["type"].endswith("/models-failed") and problem["title"] == (
        "Models failed to load"
    )
    assert "encoder.onnx: model 'autoencoder'" in problem["detail"]
    for text in (ready.text, solve.text):
        assert str(tmp_path) not in text


def test_models_still_loading_keep_their_retry_after(models_dir: Path) -> None:
    from service.errors import ModelsFailed, NotReady
    from service.repository import ModelRepository
    from service.settings import Settings

    repo = ModelRepository(Settings(models_dir=models_dir))
    loading = repo.not_ready()
    assert type(loading) is NotReady and loading.retry_after == 5
    assert loading.detail == "models not ready: loading models"
    repo.failed, repo.reason = True, "x.onnx: bad"
    assert isinstance(repo.not_ready(), ModelsFailed) and repo.not_ready().retry_after is None


def _after(server: Server, path: str, done: str, timeout: float = 60) -> tuple[int, Any, Any]:
    """``path``'s answer once its detail no longer says ``done`` is pending."""
    deadline = time.monotonic() + timeout
    while True:
        status, headers, data = server.request("GET", path)
        if done not in data.decode() or time.monotonic() > deadline:
            return status, headers, json.loads(data)
        time.sleep(0.2)


@pytest.mark.slow
def test_a_real_servers_lines_all_carry_level_and_time_and_name_the_bad_file(
    models_dir: Path, tmp_path: Path
) -> None:
    broken = _corrupt_but_listed(models_dir, tmp_path / "models")
    with serve(broken, tmp_path, ready=False, port=19061, POSE_ESTIMATOR_URL="x") as s:
        status, headers, ready = _after(s, "/v2/health/ready", "loading models")
        assert status == 503 and "retry-after" not in headers, (headers, ready)
        assert "encoder.onnx: model 'autoencoder'" in ready["detail"]
        assert s.request("GET", "/v2/health/live")[0] == 200
        s.proc.send_signal(signal.SIGTERM)
        s.proc.wait(30)
    lines = [json.loads(x) for x in s.log.read_text().splitlines() if x.strip()]
    for line in lines:  # every one: uvicorn's, the access log, the service's events
        assert line["level"] in LEVELS and TIME.fullmatch(line["time"]), line
    by_event = {line["event"]: line for line in lines}
    failed = by_event["models_not_ready"]
    assert failed["level"] == "error" and "encoder.onnx" in failed["reason"], failed
    assert "model 'autoencoder'" in failed["reason"]
    assert by_event["unknown_setting"]["level"] == "warning"
    assert {"request", "log"} <= set(by_event), lines


def _child(pid: int) -> int:
    """The one child of process ``pid`` (``unshare --fork``'s command)."""
    for _ in range(100):
        kids = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
        if kids:
            return int(kids[0])
        time.sleep(0.05)
    raise AssertionError(f"no child of {pid}")


@pytest.mark.slow
def test_sigterm_exit_status_is_143_outside_a_container_and_0_as_pid_1(
    models_dir: Path, tmp_path: Path
) -> None:
    """uvicorn (0.55) handles SIGTERM, drains, then restores the default handler and
    raises the signal again at itself: a process run from a shell, systemd or a
    supervisor dies of it (143, -15 here). As PID 1 of its namespace (a container) the
    kernel drops a signal with the default action that the process sends itself, so it
    returns from main and exits 0 (what ``docker stop`` shows). docs/deploy.md said 0
    everywhere (an ops audit)."""
    with serve(models_dir, tmp_path, port=19062) as s:
        s.proc.send_signal(signal.SIGTERM)
        assert s.proc.wait(30) == -signal.SIGTERM
    wrap = ["unshare", "--user", "--map-root-user", "--pid", "--fork"]
    probe = subprocess.run([*wrap, "true"], capture_output=True, check=False)
    if probe.returncode != 0:
        pytest.skip(f"no unprivileged pid namespace here: {probe.stderr.decode()[:200]}")
    with serve(models_dir, tmp_path, port=19063, wrap=wrap) as s:
        server = _child(s.proc.pid)  # PID 1 inside; a signal from outside reaches its handler
        subprocess.run(["kill", "-TERM", str(server)], check=True)
        assert s.proc.wait(30) == 0
    log = s.log.read_text()
    assert "Application shutdown complete." in log and "Traceback" not in log
    docs = (REPO_ROOT / "docs/deploy.md").read_text()
    assert "exits 143" in docs and "PID 1" in docs


def test_the_docs_metrics_paragraph_names_every_family(client: Any) -> None:
    """docs/limits.md's Metrics paragraph left out ``pose_connections_closed_total`` and
    the ``_created`` series every family exports (an ops audit)."""
    client.get("/v2/health/live")
    text = client.get("/metrics").text
    families = re.findall(r"^# TYPE (\S+) ", text, flags=re.MULTILINE)
    limits = (REPO_ROOT / "docs/limits.md").read_text()
    paragraph = limits.split("**Metrics.**", 1)[1].split("\n\n", 1)[0]
    own = [f for f in families if not f.endswith("_created")]
    assert "pose_connections_closed_total" in own
    assert [f for f in own if f"`{f}" not in paragraph] == []
    assert any(f.endswith("_created") for f in families) and "`_created`" in paragraph


@pytest.mark.parametrize("workers", [1, 2])
def test_the_closes_counter_has_every_reason_before_the_first_close(
    tmp_path: Path, workers: int
) -> None:
    """``pose_connections_closed_total`` had no series until a connection was closed: a
    dashboard or an alert built by its name found nothing (a new-user audit). Each reason
    is there at 0 from the start, in one process and in multiprocess mode (several
    workers, ``PROMETHEUS_MULTIPROC_DIR``: each worker imports the counter afresh)."""
    import os

    from service.settings import SHARED_DIR
    from service.transport import CLOSE_REASONS

    reasons = {"head-timeout", "idle-timeout", "body-timeout", "too-many-connections", "evicted",
               "malformed-http", "head-too-large"}  # fmt: skip
    assert set(CLOSE_REASONS) == reasons  # (as docs/limits.md lists them)
    env = {k: v for k, v in os.environ.items() if k != SHARED_DIR}
    if workers > 1:
        env[SHARED_DIR] = str(tmp_path)
    code = "from service.metrics import Metrics\nprint(Metrics().exposition().decode())"
    text = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO_ROOT, env=env, capture_output=True, text=True,
        timeout=120, check=True,
    ).stdout  # fmt: skip
    for reason in sorted(reasons):
        assert f'pose_connections_closed_total{{reason="{reason}"}} 0.0' in text, text
    assert "pose_slow_readers_total 0.0" in text, text


def test_the_docs_say_the_idle_timeout_must_outlast_the_proxys() -> None:
    """5 s (uvicorn's keep-alive) under a proxy's 60 s keep-alive is the race of sporadic
    502s: docs/deploy.md did not say so, nor which setting moves it (an ops audit)."""
    deploy = " ".join((REPO_ROOT / "docs/deploy.md").read_text().split())
    note = deploy.split("Behind a proxy that keeps connections to the pods alive", 1)[1][:900]
    assert "`POSE_IDLE_TIMEOUT_SECONDS` above the proxy's own idle timeout" in note
    assert "ingress-nginx" in note and "ALB" in note and "502" in note


def test_a_line_written_without_logging_has_the_same_shape() -> None:
    """``event_line``: for ``service.cli``'s ``start_refused`` lines (written before logging
    is set up; ``service/cli.py`` does not use it yet: REPORT.md of branch logs)."""
    from service.logs import event_line

    line = json.loads(
        event_line("error", {"event": "start_refused", "detail": "d"}, 1796540462.3456)
    )
    assert line == {
        "time": "2026-12-06T07:01:02.345Z", "level": "error", "event": "start_refused",
        "detail": "d",
    }  # fmt: skip
    assert TIME.fullmatch(json.loads(event_line("info", {}))["time"])
