"""`pose-trainer`: build the dataset, train, export and evaluate the pose models."""

from __future__ import annotations

import typer

app = typer.Typer(
    name="pose-trainer",
    help="Marionette trainer: mocap -> canonical pose dataset -> models -> ONNX + manifest.",
    no_args_is_help=True,
    add_completion=False,
)


def main() -> None:
    """Console-script entry point."""
    app()
