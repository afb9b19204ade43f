"""The access log (service.middleware.context): one JSON line per request at INFO, with
the request id the client sees; nothing at all when the level is above INFO."""

from __future__ import annotations

import json
import logging
import sys
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


@pytest.mark.slow
def test_every_line_of_a_real_servers_log_is_json(models_dir: Path, tmp_path: Path) -> None:
    """uvicorn's own lines (start, stop, a client's malformed bytes: "Invalid HTTP request
    received.") and an unexpected error's traceback were plain text among the JSON lines a
    collector reads (an ops audit); now each is a JSON object (``service.logs``)."""
    import socket
    import time

    from service.logs import JSONLines
    from tests.service.server import serve

    # an unknown variable is named in the log (it was ignored without a word; one that
    # misspells a setting, POSE_DEADLINE, now refuses the start: test_start_refused); a
    # level in capitals is taken (it was a traceback)
    env = {"POSE_ESTIMATOR_URL": "http://x", "POSE_LOG_LEVEL": "INFO"}
    with serve(models_dir, tmp_path, **env) as s:
        with socket.create_connection(("127.0.0.1", s.port), timeout=5) as sock:
            sock.sendall(b"NOT HTTP AT ALL\r\n\r\n")
            sock.recv(1 << 16)
        assert s.request("GET", "/v2/health/live")[0] == 200
        s.proc.terminate()
        s.proc.wait(30)
    time.sleep(0.1)
    lines = [x for x in s.log.read_text().splitlines() if x.strip()]
    parsed = [json.loads(x) for x in lines]  # every one, or this raises naming it
    events = {(p.get("event"), p.get("message")) for p in parsed}
    # (uvicorn's line for the refusal is dropped: the protocol's own says more)
    assert ("log", "Invalid HTTP request received.") not in events, lines
    assert any(p.get("reason") == "malformed-http" for p in parsed), lines
    assert any(p.get("event") == "models_ready" for p in parsed), lines
    assert any(p.get("event") == "request" for p in parsed), lines
    (unknown,) = [p for p in parsed if p.get("event") == "unknown_setting"]
    assert unknown["variable"] == "POSE_ESTIMATOR_URL"
    try:
        raise ValueError("boom")
    except ValueError:
        record = logging.LogRecord("service", logging.ERROR, __file__, 1, "failed", (), None)
        record.exc_info = sys.exc_info()
    line = json.loads(JSONLines().format(record))
    assert line["level"] == "error" and "ValueError: boom" in line["exception"]


def test_a_bad_setting_is_one_line_not_a_traceback(tmp_path: Path) -> None:
    import os
    import subprocess

    from tests.conftest import REPO_ROOT

    env = {**os.environ, "POSE_DEADLINE_SECONDS": "soon"}
    proc = subprocess.run(
        [sys.executable, "-c", "from service.cli import main; main()"],
        cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    (line,) = [json.loads(line) for line in proc.stderr.splitlines()]  # JSON, as all lines
    assert line["event"] == "start_refused"
    assert line["detail"].startswith("POSE_DEADLINE_SECONDS: Input should be a valid number")


@pytest.mark.parametrize(
    ("env", "argv", "said"),
    [
        ({"POSE_CORS_ORIGINS": "http://x"}, [], "POSE_CORS_ORIGINS: error parsing value"),
        ({"POSE_HOST": ""}, [], "POSE_HOST: String should have at least 1 character"),
        ({"POSE_API_KEY": ""}, [], "POSE_API_KEY: empty or only blanks (an empty key left"),
        ({"POSE_API_KEY": " \t"}, [], "POSE_API_KEY: empty or only blanks"),
        ({"POSE_API_KEY": "  "}, [], "(not shown: a secret, 2 characters)"),
        ({"POSE_API_KEY": "s3cret\n"}, [], "POSE_API_KEY: blanks or a newline before or after"),
        ({"PROMETHEUS_MULTIPROC_DIR": "/nonexistent-folder"}, [], "is no folder"),
    ],
)
def test_a_start_refused_says_why_in_one_json_line(
    env: dict[str, str], argv: list[str], said: str
) -> None:
    """An ops audit (2026-12-05): a list setting that is not JSON and a multiprocess
    metrics folder that does not exist were 20-line tracebacks (exit 1), an empty
    POSE_HOST bound every interface, and the start's refusals were the only lines on
    stderr that were not JSON. An empty POSE_API_KEY served /v1 with no key (a later
    audit); a blank one would have refused every /v1 request."""
    import os
    import subprocess

    from tests.conftest import REPO_ROOT

    proc = subprocess.run(
        [sys.executable, "-c", f"from service.cli import main; main({argv!r})"],
        cwd=REPO_ROOT, env={**os.environ, **env}, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    lines = [json.loads(line) for line in proc.stderr.splitlines()]
    assert len(lines) == 1 and lines[0]["event"] == "start_refused", proc.stderr
    assert said in lines[0]["detail"], lines
    assert "got" not in lines[0]["detail"] or "POSE_API_KEY" not in lines[0]["detail"]


def test_workers_are_at_least_one_and_the_health_path_is_a_known_variable() -> None:
    """``--workers 0`` (or -1) ran one worker without a word; POSE_HEALTH_PATH, the image's
    health check's, was logged at every start as an unknown setting (an ops audit)."""
    from service.cli import parser
    from service.settings import unknown_variables

    for bad in ("0", "-1"):
        with pytest.raises(SystemExit):
            parser().parse_args(["--workers", bad])
    assert parser().parse_args(["--workers", "2"]).workers == 2
    # (POSE_TIMEOUT, POSE_GRACE: a word of a setting's, so refused as misspelt since an ops
    # audit of 2026-12-07, test_start_refused; before, a warning and the default in force)
    assert unknown_variables({"POSE_HEALTH_PATH": "/x", "POSE_TIMEOUT": "9"}) == []
    assert unknown_variables({"POSE_GRACE": "9", "POSE_ESTIMATOR_URL": "x"}) == [
        "POSE_ESTIMATOR_URL"
    ]


def test_no_folder_for_the_kernels_cache_is_one_line() -> None:
    """A read-only root without its writable /tmp crashed the start with a traceback from
    the temp-folder lookup (an ops audit); now one line saying what to mount, exit 2."""
    import os
    import subprocess

    from tests.conftest import REPO_ROOT

    script = (
        "import tempfile\n"
        "def gone():\n"
        "    raise FileNotFoundError('No usable temporary directory found')\n"
        "tempfile.gettempdir = gone\n"
        "import service.cli\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["MARIONETTE_NUMBA_SEED"] = "/nonexistent-seed"  # as in the image: no core/__pycache__
    proc = subprocess.run(
        [sys.executable, "-c", script], cwd=REPO_ROOT, env=env, capture_output=True, text=True,
        timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert "mount a writable /tmp" in proc.stderr and "Traceback" not in proc.stderr
