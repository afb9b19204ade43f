"""`pose-service`: serve the models over HTTP with uvicorn."""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from service.settings import Settings

cli = typer.Typer(add_completion=False, help="Serve Marionette's pose API.")


@cli.command()
def serve(
    host: Annotated[Optional[str], typer.Option(help="Bind address (POSE_HOST).")] = None,  # noqa: UP045
    port: Annotated[Optional[int], typer.Option(help="Port (POSE_PORT).")] = None,  # noqa: UP045
    models_dir: Annotated[Optional[Path], typer.Option(help="Models (POSE_MODELS_DIR).")] = None,  # noqa: UP045
    workers: Annotated[int, typer.Option(help="Worker processes.")] = 1,
) -> None:
    """Serve /v1/solve and friends; settings come from POSE_* environment variables,
    options override them."""
    import os

    import uvicorn

    overrides = {
        k: v for k, v in {"host": host, "port": port, "models_dir": models_dir}.items() if v
    }
    for key, value in overrides.items():  # worker processes read settings from the env
        os.environ[f"POSE_{key.upper()}"] = str(value)
    settings = Settings()
    if not (settings.models_dir / "manifest.json").is_file():
        typer.echo(
            f"no models at {settings.models_dir} (manifest.json missing): train them with "
            "`pose-trainer train` or set POSE_MODELS_DIR",
            err=True,
        )
        raise typer.Exit(code=2)
    logging.basicConfig(level=settings.log_level.upper(), format="%(message)s", stream=sys.stderr)
    uvicorn.run(
        "service.app:create_app",
        factory=True,
        host=settings.host,
        port=settings.port,
        workers=workers,
        log_level=settings.log_level,
        access_log=False,
        timeout_graceful_shutdown=10,
    )


def main() -> None:
    cli()
