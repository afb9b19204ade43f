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
from typing import Any, NoReturn

from pydantic import ValidationError
from pydantic_settings import SettingsError

from core import CacheDirError


def refuse(*details: str) -> NoReturn:
    """A start refused: each reason one JSON line on stderr, as every line the service
    writes (docs/deploy.md; a crash loop shows only these), and exit 2."""
    for detail in details:
        print(json.dumps({"event": "start_refused", "detail": detail}), file=sys.stderr)
    raise SystemExit(2)


try:  # importing the settings imports the kernels: their cache folder is chosen then
    from service.logs import log_config
    from service.settings import SECRET_SETTINGS, SHARED_DIR, Settings, unknown_variables
except CacheDirError as exc:  # one line, not a traceback
    refuse(f"pose-service: {exc}")


def _shown(error: Any) -> str:
    """What a refused setting's line says of the value it got: never a secret's (the
    line goes to the logs; ``SECRET_SETTINGS``), whose length alone is told."""
    got = error.get("input")
    if error["loc"] and error["loc"][0] in SECRET_SETTINGS:
        return f"not shown: a secret, {len(str(got))} characters"
    return f"got {got!r}"


def _workers(text: str) -> int:
    n = int(text)
    if n < 1:
        raise argparse.ArgumentTypeError(f"{n}: at least 1")
    return n


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="pose-service",
        description="Serve /v1/solve and friends; settings come from POSE_* environment "
        "variables, options override them.",
    )
    p.add_argument("--host", help="Bind address (POSE_HOST).")
    p.add_argument("--port", type=int, help="Port (POSE_PORT).")
    p.add_argument("--models-dir", type=Path, help="Models (POSE_MODELS_DIR).")
    p.add_argument("--workers", type=_workers, default=1, help="Worker processes (>= 1).")
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
        refuse(*(
            f"POSE_{'_'.join(str(x) for x in e['loc']).upper()}: {e['msg']} "
            f"({_shown(e)})"
            for e in exc.errors(include_url=False)
        ))  # fmt: skip
    except SettingsError as exc:  # a list setting that is not JSON (POSE_CORS_ORIGINS)
        refuse(f"{exc}: a list setting is JSON, e.g. POSE_CORS_ORIGINS='[\"http://x\"]'")
    if not (settings.models_dir / "manifest.json").is_file():
        refuse(
            f"no models at {settings.models_dir} (manifest.json missing): train them with "
            "`pose-trainer train` or set POSE_MODELS_DIR"
        )
    folder = os.environ.get(SHARED_DIR)
    if folder and not Path(folder).is_dir():  # (its metrics are files opened at import)
        refuse(f"{SHARED_DIR}={folder!r} is no folder: make it (empty) or unset it")
    from service.metrics import shared  # (after that check: it opens the metrics' files)

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


if __name__ == "__main__":  # `python -m service.cli`: as `pose-service`
    main()
