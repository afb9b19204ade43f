"""``service/cli.py``: the module run as a script is the ``pose-service`` entry point."""

from __future__ import annotations

import subprocess
import sys

from tests.conftest import REPO_ROOT


def test_python_m_service_cli_runs_the_entry_point() -> None:
    """``python -m service.cli`` exited 0 at once, starting nothing and saying nothing (no
    ``__main__`` guard: an audit, 2026-12-06); now it is ``pose-service``: ``--help``
    prints its usage, and a bad option is refused as the entry point refuses it."""
    run = [sys.executable, "-m", "service.cli"]
    shown = subprocess.run(
        [*run, "--help"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120
    )
    assert shown.returncode == 0, shown.stderr
    assert shown.stdout.startswith("usage: pose-service"), shown.stdout
    for option in ("--host", "--port", "--models-dir", "--workers"):
        assert option in shown.stdout
    bad = subprocess.run(
        [*run, "--workers", "0"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120
    )
    assert bad.returncode == 2 and "--workers: 0: at least 1" in bad.stderr, bad.stderr
