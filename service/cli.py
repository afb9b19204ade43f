"""`pose-service`: serve the models over HTTP with uvicorn.

argparse, not typer: typer pulls rich, and the service install carries neither (the
trainer's and the bench's CLIs use typer)."""

from __future__ import annotations

import argparse
import json
import logging
import logging.config
import os
import sys
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from core import CacheDirError

try:  # importing the settings imports the kernels: their cache folder is chosen then
    from service.logs import log_config
    from service.metrics import shared
    from service.settings import Settings, unknown_variables
except CacheDirError as exc:  # one line, not a traceback
    print(f"pose-service: {exc}", file=sys.stderr)
    raise SystemExit(2) from None


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pose-service",
        description="Serve /v1/solve and friends; settings come from POSE_* environment "
        "variables, options override them.",
    )
    p.add_argument("--host", help="Bind address (POSE_HOST).")
    p.add_argument("--port", type=int, help="Port (POSE_PORT).")
    p.add_argument("--models-dir", type=Path, help="Models (POSE_MODELS_DIR).")
    p.add_argument("--workers", type=int, default=1, help="Worker processes.")
    return p


def main(argv: list[str] | None = None) -> None:
    args = parser().parse_args(argv)
    overrides = {"host": args.host, "port": args.port, "models_dir": args.models_dir}
    for key, value in overrides.items():  # worker processes read settings from the env
        if value:
            os.environ[f"POSE_{key.upper()}"] = str(value)
    try:
        settings = Settings()
    except ValidationError as exc:  # one line per setting, not a traceback
        for e in exc.errors(include_url=False):
            name = f"POSE_{'_'.join(str(x) for x in e['loc']).upper()}"
            print(f"{name}: {e['msg']} (got {e.get('input')!r})", file=sys.stderr)
        raise SystemExit(2) from None
    if not (settings.models_dir / "manifest.json").is_file():
        print(
            f"no models at {settings.models_dir} (manifest.json missing): train them with "
            "`pose-trainer train` or set POSE_MODELS_DIR",
            file=sys.stderr,
        )
        raise SystemExit(2)
    config = log_config(settings.log_level)
    logging.config.dictConfig(config)
    for name in unknown_variables(dict(os.environ)):
        logging.getLogger("service").warning(
            json.dumps({"event": "unknown_setting", "variable": name, "detail": "ignored"})
        )
    with shared(args.workers):  # one /metrics over every worker
        _run(settings, config, args.workers)


def _run(settings: Settings, config: dict[str, Any], workers: int) -> None:
    import uvicorn

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
