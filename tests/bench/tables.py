"""Running a benchmark's command line that prints a markdown table."""

from __future__ import annotations

from typing import Any

from typer.testing import CliRunner


def table_of(app: Any, args: list[str]) -> tuple[str, list[str]]:
    """The header line and the rows of the markdown table ``app`` prints for ``args``
    (the command must succeed)."""
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    lines = result.output.strip().splitlines()
    first = next(i for i, ln in enumerate(lines) if ln.startswith("|"))
    end = next((i for i in range(first, len(lines)) if not lines[i].startswith("|")), len(lines))
    header, _, *rows = lines[first:end]  # the first table (a summary may follow)
    return header, rows
