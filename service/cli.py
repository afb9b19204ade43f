"""`pose-service`: serve the models over HTTP with uvicorn.

argparse, not typer: typer pulls rich, and the service install carries neither (the
trainer's and the bench's CLIs use typer)."""

from __future__ import annotations

import argparse
import errno
import json
import logging
import logging.config
import os
import re
import signal
import socket
import sys
import tempfile
from pathlib import Path
from typing import Any, NoReturn

from pydantic import ValidationError
from pydantic_settings import SettingsError

from core import CacheDirError
from service.logs import event_line  # (logging, time and orjson only: no kernels imported)


def refuse(*details: str) -> NoReturn:
    """A start refused: each reason one JSON line on stderr, as every line the service
    writes (docs/deploy.md; a crash loop shows only these), and exit 2."""
    for detail in details:
        print(event_line("error", {"event": "start_refused", "detail": detail}), file=sys.stderr)
    raise SystemExit(2)


try:  # importing the settings imports the kernels: their cache folder is chosen then
    from service.logs import log_config
    from service.settings import (
        SECRET_SETTINGS,
        SHARED_DIR,
        Settings,
        misspelt_variables,
        unknown_variables,
    )
except CacheDirError as exc:  # one line, not a traceback
    refuse(f"pose-service: {exc}")


def _shown(error: Any) -> str:
    """What a refused setting's line says of the value it got: never a secret's (the
    line goes to the logs; ``SECRET_SETTINGS``), whose length alone is told."""
    got = error.get("input")
    if error["loc"] and error["loc"][0] in SECRET_SETTINGS:
        return f"not shown: a secret, {len(str(got))} characters"
    return f"got {got!r}"


#: Most worker processes ``--workers`` takes. Each loads every model (~310 MiB once
#: ready, up to ~520 MiB at peak under the heaviest loads the default limits admit:
#: docs/deploy.md), so 32 is already ~8.6 GiB at rest; more is a typo.
MAX_WORKERS = 32
#: A worker's memory once ready (MiB; deploy/k8s/deployment.yaml, SMOKE rss_mib_ready: 281
#: in the container check of 2026-12-06, 12:55 UTC; 307 before the networks stopped holding
#: their files' bytes).
WORKER_MIB = 285


def _whole(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None


def _workers(text: str) -> int:
    n = _whole(text)
    if n < 1:
        raise argparse.ArgumentTypeError(f"{n}: at least 1")
    if n > MAX_WORKERS:
        raise argparse.ArgumentTypeError(
            f"{n}: at most {MAX_WORKERS} (each worker loads every model, ~{WORKER_MIB} MiB "
            "once ready; scale with replicas)"
        )
    return n


class _Parser(argparse.ArgumentParser):
    """A usage error is a refused start as any other (one JSON line, exit 2; it was
    argparse's plain-text usage, the only lines of a crash loop that were not JSON, an ops
    audit); ``--help`` stays text for a person."""

    def error(self, message: str) -> NoReturn:
        refuse(f"pose-service: {message} (`pose-service --help` lists the options)")


def parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="pose-service",
        description="Serve /v1/solve and friends; settings come from POSE_* environment "
        "variables, options override them. A refused start is one JSON line "
        "(start_refused) and exit 2 (docs/deploy.md).",
    )
    p.add_argument("--host", help="Bind address (POSE_HOST).")
    p.add_argument("--port", type=_whole, metavar="PORT", help="Port (POSE_PORT).")
    p.add_argument("--models-dir", type=Path, help="Models (POSE_MODELS_DIR).")
    p.add_argument(
        "--workers",
        type=_workers,
        default=1,
        metavar="N",
        help=f"Worker processes (1 to {MAX_WORKERS}); each loads every model "
        f"(~{WORKER_MIB} MiB once ready).",
    )
    return p


#: The options that set a setting (the option's name in a refusal: the operator typed it)
OPTIONS = {"host": "--host", "port": "--port", "models_dir": "--models-dir"}


def _named(loc: tuple[Any, ...], given: set[str]) -> str:
    """The variable (or option) a settings error is about: ``POSE_CORS_ORIGINS[0]`` for an
    entry of a list (it read ``POSE_CORS_ORIGINS_0``, a variable that does not exist)."""
    if not loc:
        return ""
    head = str(loc[0])
    name = f"POSE_{head.upper()}"
    if head in given:
        name = f"{OPTIONS[head]} ({name})"
    return name + "".join(f"[{x}]" for x in loc[1:]) + ": "


def _settings(given: set[str]) -> Settings:
    try:
        return Settings()
    except ValidationError as exc:  # one line per setting, not a traceback
        refuse(*(
            _named(tuple(e["loc"]), given) + e["msg"] + (f" ({_shown(e)})" if e["loc"] else "")
            for e in exc.errors(include_url=False)
        ))  # fmt: skip
    except SettingsError as exc:  # a list setting that is not JSON (POSE_CORS_ORIGINS)
        field = re.search(r'field "(\w+)"', str(exc))  # (its name first, as every refusal)
        name = f"POSE_{field.group(1).upper()}: " if field else ""
        refuse(f"{name}{exc}: a list setting is JSON, e.g. POSE_CORS_ORIGINS='[\"http://x\"]'")


def _check_models(folder: Path) -> None:
    try:
        found = (folder / "manifest.json").is_file()
    except OSError as exc:  # (a PermissionError from stat was a traceback, exit 1)
        refuse(
            f"models at {folder} cannot be read ({exc.strerror}): the folder must be "
            f"readable and searchable (r-x) by this process (uid {os.getuid()}); a volume "
            "written under another uid: chmod a+rx it, or set the pod's fsGroup"
        )
    if not found:
        refuse(
            f"no models at {folder} (manifest.json missing): train them with "
            "`pose-trainer train` or set POSE_MODELS_DIR"
        )


def _check_shared_dir(folder: str) -> None:
    if not Path(folder).is_dir():  # (its metrics are files opened at import)
        refuse(f"{SHARED_DIR}={folder!r} is no folder: make it (empty) or unset it")
    try:  # (the metrics' files are made there: unwritable, a traceback at import, exit 1)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".pose-service-check-")
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        refuse(
            f"{SHARED_DIR}={folder!r} is not writable (a file made there: {exc.strerror}): "
            "the workers write "
            "their metrics' files there; point it at a writable, empty folder (an emptyDir) "
            "or unset it"
        )


def _memory_limit() -> int | None:
    """The memory limit of this process's cgroup (a container's: bytes), None if none."""
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text().strip()
        except OSError:
            continue
        if text.isdigit() and int(text) < 1 << 60:  # ("max", or v1's huge "no limit")
            return int(text)
    return None


def _cpus() -> int:
    """CPUs this process may use: its affinity, and its cgroup's quota (a container's
    ``limits.cpu``, rounded up) when lower."""
    n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    try:
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()
        if quota != "max":
            n = min(n, max(1, -(-int(quota) // int(period))))
    except (OSError, ValueError):
        pass
    return n


def _check_workers(workers: int) -> None:
    limit = _memory_limit()
    if workers > 1 and limit is not None and workers * WORKER_MIB * 2**20 > limit:
        refuse(
            f"--workers {workers}: each worker loads every model (~{WORKER_MIB} MiB once "
            f"ready), {workers * WORKER_MIB} MiB in all, past this container's memory "
            f"limit ({limit // 2**20} MiB): the workers would be killed for memory; run "
            "fewer (one per pod, as deploy/k8s does) and scale with replicas"
        )


def _where(host: str, port: int) -> str:
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


_BIND_HINTS = {
    "EADDRINUSE": "another process listens there: stop it, or choose another port",
    "EADDRNOTAVAIL": "no interface of this machine has that address: 0.0.0.0 listens on "
    "every one, 127.0.0.1 on this machine only",
    "EACCES": "ports below 1024 need a privilege the service does not have: use 1024 or above",
}


def _check_bind(host: str, port: int) -> None:
    """Refuse a start whose address cannot be listened on, before the models load: uvicorn
    logged the error (an unresolvable host without its name) and exited 3 after loading
    them (an ops audit). The socket is bound as asyncio binds it, then closed; a port taken
    between this and uvicorn's own bind is still uvicorn's exit 3."""
    try:
        found = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        refuse(
            f"cannot listen on {_where(host, port)}: the host {host!r} does not resolve "
            f"({reason}); give an address of this machine (POSE_HOST or --host: 0.0.0.0 "
            "for every interface, 127.0.0.1 for this machine only)"
        )
    for family, kind, proto, _, address in found:
        with socket.socket(family, kind, proto) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:
                sock.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            try:
                sock.bind(address)
            except OSError as exc:
                code = next((n for n in _BIND_HINTS if exc.errno == getattr(errno, n)), "")
                hint = f": {_BIND_HINTS[code]}" if code else ""
                refuse(f"cannot listen on {_where(host, port)} ({exc.strerror}){hint}")


def main(argv: list[str] | None = None) -> None:
    args = parser().parse_args(argv)
    overrides = {"host": args.host, "port": args.port, "models_dir": args.models_dir}
    given = {key for key, value in overrides.items() if value is not None}
    for key in given:  # worker processes read settings from the env
        # (given as given: `--port 0` and `--host ""` were taken for "not given", an ops audit)
        os.environ[f"POSE_{key.upper()}"] = str(overrides[key])
    settings = _settings(given)
    misspelt = misspelt_variables(dict(os.environ))
    if misspelt:  # (POSE_APIKEY=... served /v1 to anyone, a warning its only sign)
        refuse(*(
            f"{key}: no such setting; did you mean {' or '.join(meant)}? Rename or unset "
            "it (a misspelt setting would leave its default in force)"
            for key, meant in misspelt.items()
        ))  # fmt: skip
    _check_models(settings.models_dir)
    folder = os.environ.get(SHARED_DIR)
    if folder:
        _check_shared_dir(folder)
    _check_workers(args.workers)
    _check_bind(settings.host, settings.port)
    from service.metrics import shared  # (after those checks: it opens the metrics' files)

    config = log_config(settings.log_level)
    logging.config.dictConfig(config)
    log = logging.getLogger("service")
    for name in unknown_variables(dict(os.environ)):
        log.warning(json.dumps({"event": "unknown_setting", "variable": name, "detail": "ignored"}))
    cpus = _cpus()
    if args.workers > cpus:
        log.warning(json.dumps({
            "event": "workers_exceed_cpus", "workers": args.workers, "cpus": cpus,
            "detail": "workers past the CPUs share them (no more throughput), and each "
            f"holds every model (~{WORKER_MIB} MiB)",
        }))  # fmt: skip
    with shared(args.workers):  # one /metrics over every worker
        _run(settings, config, args.workers)


#: What a single worker does on SIGHUP (``signal_ignored``): uvicorn handles SIGINT and
#: SIGTERM only, so SIGHUP's default action killed it at once (exit 129, requests in
#: flight lost, no line: an ops audit), while with ``--workers N`` uvicorn's supervisor
#: replaces the workers gracefully. One process cannot replace itself without going
#: unready for its models' load, and it reads its settings only at start: there is nothing
#: to reload, so it goes on serving (docs/deploy.md).
HANGUP = (
    "ignored: one worker reads its settings and models only at start, so there is nothing "
    "to reload; restart the service to apply new ones (SIGTERM stops it gracefully)"
)


def _hangup(signum: int, frame: Any) -> None:
    logging.getLogger("service").warning(
        json.dumps({"event": "signal_ignored", "signal": "SIGHUP", "detail": HANGUP})
    )


def _run(settings: Settings, config: dict[str, Any], workers: int) -> None:
    import uvicorn

    if workers == 1:  # (with several, uvicorn's supervisor restarts them on SIGHUP)
        signal.signal(signal.SIGHUP, _hangup)

    uvicorn.run(
        "service.app:create_app",
        factory=True,
        host=settings.host,
        port=settings.port,
        workers=workers,
        log_level=settings.log_level,
        log_config=config,  # every line JSON (service.logs), uvicorn's too
        access_log=False,
        http="service.transport:PacedHTTPProtocol",  # a floor on how fast answers are taken
        timeout_graceful_shutdown=settings.shutdown_grace_seconds,
    )


if __name__ == "__main__":  # `python -m service.cli`: as `pose-service`
    main()
