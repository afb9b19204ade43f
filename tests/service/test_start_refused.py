"""Starts ``pose-service`` refuses (``service/cli.py``): each one JSON line
``{"event": "start_refused", "detail": ...}`` on stderr naming what is wrong, and exit 2,
before the models load. The real entry point runs in a subprocess; ports 19000-19049."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest

from tests.conftest import REPO_ROOT

PORT = "19031"  # (nothing listens there: a start that got past every check would)


def start(
    argv: list[str], env: dict[str, str] | None = None, script: str = ""
) -> subprocess.CompletedProcess[str]:
    """``main(argv)`` (after ``script``) run to its end in a new interpreter."""
    code = f"{script}\nfrom service.cli import main\nmain({argv!r})"
    environ = {k: v for k, v in os.environ.items() if not k.upper().startswith("POSE_")}
    return subprocess.run(
        [sys.executable, "-c", code], cwd=REPO_ROOT, env={**environ, **(env or {})},
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip


def detail_of(proc: subprocess.CompletedProcess[str]) -> str:
    """The one ``start_refused`` line's detail of a start that ended."""
    assert proc.returncode == 2, proc.stderr
    lines = [json.loads(line) for line in proc.stderr.splitlines()]  # JSON, every one
    assert len(lines) == 1 and lines[0]["event"] == "start_refused", proc.stderr
    assert lines[0]["level"] == "error" and lines[0]["time"].endswith("Z"), lines  # as every line
    detail: str = lines[0]["detail"]
    return detail


def refused(argv: list[str], env: dict[str, str] | None = None, script: str = "") -> str:
    """The one ``start_refused`` line's detail of ``main(argv)`` (after ``script``)."""
    return detail_of(start(argv, env, script))


#: (environment, argv, what the refusal says)
CASES: list[tuple[dict[str, str], list[str], str]] = [
    # D3: a budget below the body limit (every chunked body a 429 forever)
    ({"POSE_MAX_INFLIGHT_BYTES": "4096"}, [],
     "POSE_MAX_INFLIGHT_BYTES (4096) is below POSE_MAX_BODY_BYTES (8388608)"),
    ({"POSE_MAX_BODY_BYTES": str(100 << 20)}, [],
     f"POSE_MAX_INFLIGHT_BYTES ({64 << 20}) is below POSE_MAX_BODY_BYTES ({100 << 20})"),
    # D5: a metrics folder that exists but takes no file
    ({"PROMETHEUS_MULTIPROC_DIR": "/proc"}, [], "PROMETHEUS_MULTIPROC_DIR='/proc' is not "
     "writable"),
    # D6: a setting misspelt (/v1 open with POSE_APIKEY)
    ({"POSE_APIKEY": "s3cret"}, [],
     "POSE_APIKEY: no such setting; did you mean POSE_API_KEY?"),
    ({"POSE_API_KEY_FILE": "/run/secrets/key"}, [],
     "POSE_API_KEY_FILE: no such setting; did you mean POSE_API_KEY?"),
    ({"POSE_DEADLINE": "9"}, [], "POSE_DEADLINE: no such setting; did you mean "
     "POSE_DEADLINE_SECONDS?"),
    # (the reason is a general one: it named POSE_APIKEY whatever was misspelt)
    ({"POSE_PROT": PORT}, [], "POSE_PROT: no such setting; did you mean POSE_PORT? "
     "Rename or unset it (a misspelt setting would leave its default in force)"),
    # D9: options given are given (0 and "" were taken for "not given")
    ({"POSE_HOST": "127.0.0.1"}, ["--port", "0"],
     "--port (POSE_PORT): Input should be greater than or equal to 1"),
    ({}, ["--host", "", "--port", PORT],
     "--host (POSE_HOST): String should have at least 1 character"),
    # D10: a key no client can send
    ({"POSE_API_KEY": "clé-secrète"}, [], "POSE_API_KEY: a character that is not "
     "printable ASCII: an HTTP header's value is bytes"),
    # a near miss that shares a word with a setting: warned of, and the default kept
    # (an ops audit, 2026-12-07), while other misspellings (POSE_CONCURRENCY) refused
    ({"POSE_MAX_BODY_SIZE": "100"}, [], "POSE_MAX_BODY_SIZE: no such setting; did you "
     "mean POSE_MAX_BODY_BYTES? Rename or unset it"),
    ({"POSE_DEADLINE_MS": "500"}, [], "POSE_DEADLINE_MS: no such setting; did you mean "
     "POSE_DEADLINE_SECONDS?"),
    ({"POSE_BATCH_SIZE": "10"}, [], "POSE_BATCH_SIZE: no such setting; did you mean "
     "POSE_MAX_BATCH_ITEMS?"),
    ({"POSE_CONCURRENCY": "8"}, [], "POSE_CONCURRENCY: no such setting; did you mean "
     "POSE_MAX_CONCURRENCY?"),
    ({"POSE_TIMEOUT": "30"}, [], "POSE_TIMEOUT: no such setting; did you mean "
     "POSE_IDLE_TIMEOUT_SECONDS or POSE_HEAD_TIMEOUT_SECONDS?"),
    # bounds an audit found open, and nan's message (2026-12-07)
    ({"POSE_DEADLINE_SECONDS": "1e-9"}, [],
     "POSE_DEADLINE_SECONDS: Input should be greater than or equal to 0.01 (got '1e-9')"),
    ({"POSE_DEADLINE_SECONDS": "nan"}, [],
     "POSE_DEADLINE_SECONDS: Input should be a finite number (got 'nan')"),
    ({"POSE_HEAD_TIMEOUT_SECONDS": "inf"}, [],
     "POSE_HEAD_TIMEOUT_SECONDS: Input should be a finite number (got 'inf')"),
    ({"POSE_MAX_BATCH_ITEMS": "100000000"}, [],
     "POSE_MAX_BATCH_ITEMS: Input should be less than or equal to 65536"),
    ({"POSE_LOG_LEVEL": "trace"}, [], "POSE_LOG_LEVEL: Input should be 'debug', 'info', "
     "'warning', 'error' or 'critical' (got 'trace')"),
    # D11: usage errors (plain-text argparse usage; `_workers` leaked)
    ({}, ["--port", "abc"], "pose-service: argument --port: 'abc' is not a whole number"),
    ({}, ["--workers", "abc"], "argument --workers: 'abc' is not a whole number"),
    ({}, ["--workers", "0"], "argument --workers: 0: at least 1"),
    ({}, ["--bogus"], "pose-service: unrecognized arguments: --bogus"),
    # D12: absurd worker counts
    ({}, ["--workers", "99"], "argument --workers: 99: at most 32 (each worker loads"),
    # D14: a host that does not resolve, named
    ({}, ["--host", "no.such.host.invalid", "--port", PORT],
     f"cannot listen on no.such.host.invalid:{PORT}: the host 'no.such.host.invalid' "
     "does not resolve"),
    # D15: origins no browser sends; an entry named by its real variable
    ({"POSE_CORS_ORIGINS": '["http://editor.example/"]'}, [],
     "POSE_CORS_ORIGINS: entry 0 ('http://editor.example/') never matches: a path (even "
     "a trailing '/') is never part of an Origin: write 'http://editor.example'"),
    ({"POSE_CORS_ORIGINS": '["http://a.example", "editor.example"]'}, [],
     "POSE_CORS_ORIGINS: entry 1 ('editor.example') never matches: no scheme"),
    ({"POSE_CORS_ORIGINS": '["http://a.example", 3]'}, [],
     "POSE_CORS_ORIGINS[1]: Input should be a valid string"),
]  # fmt: skip


@pytest.fixture(scope="module")
def starts() -> Iterator[list[Future[subprocess.CompletedProcess[str]]]]:
    """Each case's start (:data:`CASES`, in order), all begun at once, as many at a time
    as there are cores: each is a new interpreter of its own, alone on its port, and its
    test waits for its own (one after another, the 30 starts took 20-40 s, a core idle)."""
    with ThreadPoolExecutor(os.cpu_count() or 1) as pool:
        yield [pool.submit(start, argv, {"POSE_PORT": PORT, **env}) for env, argv, _ in CASES]


@pytest.mark.parametrize(("env", "argv", "said"), CASES)
def test_a_refused_start_is_one_json_line_naming_what_is_wrong(
    env: dict[str, str], argv: list[str], said: str,
    starts: list[Future[subprocess.CompletedProcess[str]]],
) -> None:  # fmt: skip
    """Each of these started the service (D3, D6, D9, D10, D15: an ops audit, 2026-12-06),
    or was a traceback (D5), plain-text usage (D11) or uvicorn's exit 3 (D14)."""
    detail = detail_of(starts[CASES.index((env, argv, said))].result())
    assert said in detail, detail
    assert "_workers" not in detail and "clé" not in detail and "s3cret" not in detail


def test_a_port_in_use_is_refused_naming_it() -> None:
    """It was uvicorn's error line and exit 3, after the models had loaded (D14)."""
    with socket.socket() as busy:
        busy.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        busy.bind(("127.0.0.1", 19032))
        busy.listen()
        detail = refused(["--host", "127.0.0.1", "--port", "19032"])
    assert detail.startswith("cannot listen on 127.0.0.1:19032 (Address already in use): "
                             "another process listens there"), detail  # fmt: skip


def test_an_unreadable_models_folder_is_refused_naming_it(tmp_path: Path) -> None:
    """A models folder this uid may not search was a PermissionError traceback from
    ``Path.is_file``, exit 1 (D4). (The tests run as root, whom modes do not stop: the
    error is raised as the kernel raises it for another uid.)"""
    folder = tmp_path / "models"
    folder.mkdir()
    script = (
        "import os\n"
        "real = os.stat\n"
        "def stat(path, *args, **kwargs):\n"
        f"    if str(path).startswith({str(folder)!r}):\n"
        "        raise PermissionError(13, 'Permission denied', str(path))\n"
        "    return real(path, *args, **kwargs)\n"
        "os.stat = stat\n"
    )
    detail = refused(["--models-dir", str(folder), "--port", PORT], script=script)
    assert detail.startswith(f"models at {folder} cannot be read (Permission denied): "
                             "the folder must be readable and searchable"), detail  # fmt: skip


def test_more_workers_than_the_memory_limit_holds_are_refused() -> None:
    """Each worker loads every model (~285 MiB once ready): 3 in the manifest's 768 Mi pod
    are killed for memory (D12). The cgroup's limit is stood in for."""
    script = "import service.cli\nservice.cli._memory_limit = lambda: 768 * 2**20\n"
    detail = refused(["--workers", "3", "--port", PORT], script=script)
    assert detail.startswith("--workers 3: each worker loads every model (~285 MiB once "
                             "ready), 855 MiB in all, past this container's memory limit "
                             "(768 MiB)"), detail  # fmt: skip


def test_help_stays_text() -> None:
    shown = subprocess.run(
        [sys.executable, "-m", "service.cli", "--help"], cwd=REPO_ROOT, capture_output=True,
        text=True, timeout=120,
    )  # fmt: skip
    assert shown.returncode == 0 and shown.stdout.startswith("usage: pose-service"), shown
    assert "--workers N" in shown.stdout and "_workers" not in shown.stdout


def test_misspelt_variables_are_told_from_others_and_service_links() -> None:
    """D6: close misspellings (refused) against other ``POSE_*`` names (a warning), and
    the variables Kubernetes injects for a Service named ``pose`` or ``pose-<x>`` in the
    namespace (``enableServiceLinks``), which must never refuse a start."""
    from service.settings import misspelt_variables, unknown_variables

    env = dict.fromkeys(
        ["POSE_APIKEY", "POSE_LOGLEVEL", "POSE_PROT", "POSE_KEY", "POSE_WORKERS",
         "POSE_ESTIMATOR_URL", "POSE_HEALTH_PATH", "pose_api_key", "POSE_SERVICE_HOST",
         "POSE_MAX_BODY_SIZE", "POSE_CACHE_DIR",
         "POSE_SERVICE_PORT", "POSE_SERVICE_PORT_HTTP", "POSE_PORT_80_TCP",
         "POSE_PORT_80_TCP_ADDR", "POSE_API_SERVICE_HOST", "POSE_API_PORT",
         "POSE_API_PORT_8000_TCP_PORT"], "x",
    )  # fmt: skip
    assert misspelt_variables(env) == {
        "POSE_APIKEY": ["POSE_API_KEY"],
        "POSE_KEY": ["POSE_API_KEY"],
        "POSE_LOGLEVEL": ["POSE_LOG_LEVEL"],
        "POSE_PROT": ["POSE_PORT"],
        "POSE_MAX_BODY_SIZE": ["POSE_MAX_BODY_BYTES"],  # (a word shared: BODY)
    }
    warned = unknown_variables(env)
    assert "POSE_ESTIMATOR_URL" in warned
    assert any(w.startswith("POSE_CACHE_DIR") for w in warned), warned  # ("DIR": generic)
    workers = "the worker count is the --workers option (`pose-service --workers N`)"
    assert f"POSE_WORKERS ({workers}, no variable)" in warned, warned
    links = [w for w in warned if w.endswith("(a Kubernetes Service's link variable?)")]
    assert len(links) == 8, warned


def test_a_worker_count_in_a_variable_is_pointed_at_the_option() -> None:
    """``POSE_WORKERS=2`` started one worker, its warning asking "did you mean POSE_PORT?";
    POSE_WEB_CONCURRENCY (the name uvicorn's and gunicorn's own variable bears) was
    refused as POSE_MAX_CONCURRENCY misspelt (a new-user audit). The worker count is the
    ``--workers`` option: each is named in a warning saying so."""
    from service.settings import misspelt_variables, unknown_variables

    env = dict.fromkeys(["POSE_WORKERS", "pose_workers", "POSE_WEB_CONCURRENCY"], "2")
    assert misspelt_variables(env) == {}
    warned = unknown_variables(env)
    assert len(warned) == 3 and all("the --workers option" in w for w in warned), warned
    assert not any("did you mean" in w for w in warned), warned


def test_origins_are_checked_as_browsers_send_them() -> None:
    from service.settings import origin_problem

    for good in ("*", "http://editor.example", "https://editor.example:8443",
                 "http://127.0.0.1:5173", "http://[::1]:8080"):  # fmt: skip
        assert origin_problem(good) is None, good
    for bad, fix in [
        ("http://editor.example/", "write 'http://editor.example'"),
        ("https://editor.example/app", "write 'https://editor.example'"),
        ("editor.example", "no scheme"),
        ("HTTPS://Editor.example", "write 'https://editor.example'"),
        ("https://editor.example:443", "write 'https://editor.example'"),
        ("null", "allows anyone"),
    ]:
        problem = origin_problem(bad)
        assert problem and fix in problem, (bad, problem)


def test_every_level_the_docs_list_is_taken() -> None:
    """docs/deploy.md lists ``critical`` among the log's levels, and POSE_LOG_LEVEL=critical
    was refused (an ops audit): each level listed is taken, in any case, and uvicorn runs at
    it (its level names: ``uvicorn.config.LOG_LEVELS``)."""
    from typing import get_args

    from uvicorn.config import LOG_LEVELS

    from service.logs import log_config
    from service.settings import Settings

    docs = (REPO_ROOT / "docs/deploy.md").read_text()
    said = docs.split("`POSE_LOG_LEVEL` takes any case:", 1)[1].split(" (the", 1)[0]
    levels = get_args(Settings.model_fields["log_level"].annotation)
    assert len(levels) == 5 and "critical" in levels, levels
    assert all(f"`{level}`" in said for level in levels), (said, levels)
    for level in levels:
        assert Settings(log_level=level.upper()).log_level == level
        assert level in LOG_LEVELS and log_config(level)["root"]["level"] == level.upper()
