"""The edit an outage interrupted, once the server is back, where something else goes on
(real Chromium, the session's real server; ``docs/editor-recovery.md``). The outage is the
page's own: its solves and its liveness checks aborted (a network failure as the page sees
it: "server unreachable"), then let through. An outage review's defects, 2026-12-07:

- the server found back while a joint is pressed: the edit was not sent again (the press
  under way), and the banner saying it was not solved went, the status "connected": the
  kept targets unsolved, without a word;
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
    settle,
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
def test_the_edit_not_sent_again_as_a_joint_is_pressed_is_still_said(
    server: str, browser: Any
) -> None:
    """Found back while a joint is pressed (a click under way): the edit is not sent again
    then, and the banner says it is not applied (it went, the status "connected", the kept
    targets unsolved); it goes once an edit is solved."""
    page = opened(browser, server)
    try:
        start, made = interrupted(page)
        count = page.evaluate(f"{M}.solveCount().sent")
        page.unroute(SOLVE)
        page.unroute(LIVE)
        press(page, "right_wrist")
        found(page)  # (while pressed)
        page.mouse.up()
        settle(page)
        now = work(page, shown=True)
        assert now == made  # not sent again: the pose as before the drag, its targets kept
        assert page.evaluate(f"{M}.solveCount().sent") == count
        assert now["committed"] == start["committed"] and "left_knee" in now["targets"]
        said = banner(page)
        assert said["shown"] and said["status"] == "connected", said
        assert said["title"] == "Edit not applied"
        assert "not sent again" in said["detail"] and "drag again to retry" in said["detail"]
        page.mouse.move(0, 0)
        found(page)  # (the page's next liveness check: it stays)
        page.clock.run_for(4_000)
        assert banner(page)["shown"]
        page.click("#reset")  # moved on: it goes with the edit
        page.wait_for_function(f"() => {M}.error() === null")
    finally:
        page.context.close()


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
