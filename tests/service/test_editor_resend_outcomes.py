"""The edit an outage interrupted, once the server is back, where something else goes on
(real Chromium, the session's real server; ``docs/editor-recovery.md``). The outage is the
page's own: its solves and its liveness checks aborted (a network failure as the page sees
it: "server unreachable"), then let through. An outage review's defects, 2026-12-07:

- the "failed again" banner titled "Server unreachable" under the status "connected".

Shared parts: ``tests/service/editor_page.py``.
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.service.editor_page import (
    STATUS,
    M,
    found,
    opened,
    unreachable,
    work,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

SOLVE, LIVE = "**/v1/solve", "**/v2/health/live"


def gone(page: Any) -> None:
    """The server unreachable for ``page``: its solves and liveness checks aborted."""
    page.route(SOLVE, lambda route: route.abort())
    page.route(LIVE, lambda route: route.abort())


def interrupted(page: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """A drag of the left knee the outage interrupted: the work before it and after."""
    start = work(page, shown=True)
    gone(page)
    unreachable(page, "left_knee")
    return start, work(page, shown=True)


def press(page: Any, joint: str) -> dict[str, float]:
    xy: dict[str, float] = page.evaluate(f"{M}.projectJoint('{joint}')")
    page.mouse.move(xy["x"], xy["y"])
    page.mouse.down()
    return xy


def banner(page: Any) -> dict[str, Any]:
    return {
        "title": page.text_content("#error-title"),
        "detail": page.text_content("#error-detail"),
        "shown": page.locator("#error").is_visible(),
        "status": page.evaluate(STATUS),
    }


@pytest.mark.browser
def test_the_failed_again_banner_says_what_failed_not_the_server_unreachable(
    server: str, browser: Any
) -> None:
    """The edit sent again found no server again: its banner's title says the edit failed
    again, which holds under the status "server unreachable" as under "connected" once the
    server is found back, the banner still up (it said "Server unreachable" under
    "connected")."""
    page = opened(browser, server)
    try:
        interrupted(page)
        page.unroute(LIVE)  # (found back, its solves still aborted: the edit sent fails again)
        found(page)
        page.wait_for_function(f"() => ({M}.error() || {{detail: ''}}).detail.includes('again:')")
        found(page)  # (the page's next liveness check, after the edit failed again)
        said = banner(page)
        assert "failed again" in said["detail"] and "POST /v1/solve failed" in said["detail"]
        assert said["shown"] and said["status"] == "connected"
        assert said["title"] == "Edit failed again"
    finally:
        page.context.close()
