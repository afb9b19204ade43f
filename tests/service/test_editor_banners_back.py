"""The editor's banner once the server it said was unreachable is back (an editor review,
2026-12-07; real Chromium, a real server of the test's own, stopped and restarted;
``docs/editor-recovery.md``): the status said "connected" again (the page asks its liveness
every 3 s) while the "Server unreachable" banner stayed up until the next solve landed.

Shared parts: ``tests/service/editor_page.py``.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import M, drag_joint, open_editor
from tests.service.server import free_port, serve

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

STATUS = "document.getElementById('status').textContent"


def work(page: Any) -> dict[str, Any]:
    """What the user made: the pose as committed, targets, pins, the undo history."""
    return {
        "committed": page.evaluate(f"{M}.committedPose()"),
        "targets": page.evaluate(f"{M}.targets()"),
        "pins": page.evaluate(f"{M}.pins()"),
        "history": page.evaluate(f"{M}.history()"),
    }


def unreachable(page: Any) -> None:
    """A drag whose solves find no server: its banner and status say so."""
    drag_joint(page, "left_knee", 10, 10)
    err = page.evaluate(f"{M}.error()")
    assert err is not None and err["title"] == "Server unreachable", err
    assert page.evaluate(STATUS) == "server unreachable"


@pytest.mark.browser
def test_the_unreachable_banner_goes_once_the_server_is_back(
    browser: Any, models_dir: Path, tmp_path: Path
) -> None:
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    with contextlib.ExitStack() as first:
        first.enter_context(serve(models_dir, tmp_path, port=port))
        page = open_editor(browser, base)
        drag_joint(page, "right_wrist", 30, -40)  # an edit, solved
    try:  # (the server stopped)
        unreachable(page)
        made = work(page)
        assert "right_wrist" in made["targets"] and "left_knee" in made["targets"]
        with serve(models_dir, tmp_path, port=port):
            # no click, no drag: the page's liveness check finds it, and the banner goes
            page.wait_for_function(f"() => {STATUS} === 'connected'")
            page.wait_for_function(f"() => {M}.error() === null")
            assert page.locator("#error").is_hidden()
            assert work(page) == made  # the user's work as it was
            drag_joint(page, "right_wrist", -10, -10)  # and it edits on
            assert page.evaluate(f"{M}.error()") is None
            assert page.evaluate(f"{M}.lastSolve().response.targets")
        # gone again: Reset (or a sample) replaces the pose, but the server is still
        # unreachable, and the banner saying so stays until it is back
        unreachable(page)
        page.click("#reset")
        assert page.evaluate(f"{M}.targets()") == {}
        assert page.evaluate(f"{M}.error()")["title"] == "Server unreachable"
        assert page.locator("#error").is_visible()
        with serve(models_dir, tmp_path, port=port):
            page.wait_for_function(f"() => {M}.error() === null")
            assert page.evaluate(STATUS) == "connected"
    finally:
        page.context.close()
