"""The edit a server's outage interrupted, sent again once it is back (real Chromium, a real
server of the test's own stopped and started again on its port; ``docs/editor-recovery.md``).

A drag whose last solve could not reach the server kept its targets, the pose as before the
drag. Once the server was back the status said "connected" and the banner went, but the kept
targets were never solved: the screen showed targets the pose did not meet, and the user had
to drag again. Now that edit is sent again by itself, once, and lands as a late answer would
(the drag one undo step); not when the user has changed things since (undo, Reset, a
sample), and not a second time when it fails again.

Shared parts: ``tests/service/editor_page.py``.
"""

from __future__ import annotations

import json
import time
from typing import Any

import pytest

from tests.service.editor_page import (
    REPO_ROOT,
    STATUS,
    STEP_MS,
    VIEW,
    WAIT_MS,
    M,
    Outages,
    drag_joint,
    drained,
    found,
    open_file,
    opened,
    pick,
    recorded,
    settle,
    unreachable,
    work,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

#: Longer than the page's liveness period (api.js WATCH_MS, 3 s): what was to be sent is.
QUIET_MS = 4_500


def quiet(*pages: Any) -> None:
    """``QUIET_MS`` of each page's own time passes: its clock is run on ``STEP_MS`` at a
    time, each step firing the timers that fall due in it (the frame loop that sends a
    solve, the liveness check, a Retry-After's end), and what they asked of the server is
    let finish (answered or failed) before the next step; then the pages settle. What was
    to be sent is: as a real wait of ``QUIET_MS`` showed, the server's answers here in no
    time (4.5 s a wait, 8 in this file). ``STEP_MS``: editor_page's."""
    deadline = time.monotonic() + WAIT_MS / 1000  # (a ceiling, as each page wait has)
    for _ in range(QUIET_MS // STEP_MS):
        for page in pages:
            page.clock.run_for(STEP_MS)
        for page in pages:
            drained(page, lambda url: True, deadline)
    for page in pages:
        settle(page)


def sent(page: Any) -> int:
    return int(page.evaluate(f"{M}.solveCount().sent"))


def back(page: Any) -> None:
    """The server found back (the page's liveness check), and whatever that sent settled."""
    found(page)
    settle(page)


def caught(page: Any, held: list[Any]) -> None:
    """Wait until a route a test holds has caught a request (``held`` filled by its handler,
    which runs while Playwright waits)."""
    page.wait_for_function(f"() => {M}.solveCount().inflight")
    while not held:
        page.wait_for_timeout(50)


def holding(page: Any) -> list[Any]:
    """The page's solves held (the list filled with their routes as they are caught)."""
    held: list[Any] = []
    page.route("**/v1/solve", lambda route: held.append(route))
    return held


@pytest.mark.browser
def test_the_edit_an_outage_interrupted_is_sent_again_once_it_is_back(
    browser: Any, outages: Outages
) -> None:
    with outages.up():
        page = opened(browser, outages.base)
        two = opened(browser, outages.base)  # (the two drags' page, below)
        drag_joint(page, "right_wrist", 30, -40)  # an edit, solved
    try:  # (the server stopped)
        start = work(page, shown=True)
        unreachable(page, "left_knee")
        made = work(page, shown=True)
        assert made["committed"] == start["committed"] and made["pose"] == start["pose"]
        assert "left_knee" in made["targets"]
        assert "sent again once the server is back" in page.evaluate(f"{M}.error().detail")
        count = sent(page)
        # two drags while it is gone (on a page of their own, through the same outage): the
        # state shown (both) is sent; found as it starts, still loading its models (503,
        # Retry-After: 5), it is sent again until they are
        unreachable(two, "left_elbow", 15, 15)
        unreachable(two, "right_knee", -10, 10)
        made_two = work(two, shown=True)
        bodies = recorded(two, lambda url: url.endswith("/v1/solve"))
        with outages.ready(page):
            back(page)  # (no click, no drag)
            now = work(page, shown=True)
            assert page.evaluate(f"{M}.error()") is None
            assert now["committed"] != start["committed"]  # the edit landed
            assert now["pose"] == now["committed"]
            assert now["targets"] == made["targets"] and now["pins"] == made["pins"]
            assert now["history"] == made["history"]  # (the drag one step, as a late answer)
            assert sent(page) == count + 1
            last = page.evaluate(f"{M}.lastSolve()")
            assert {t["joint"] for t in last["request"]["targets"]} == set(made["targets"])
            quiet(page)
            assert sent(page) == count + 1  # once
            # one undo takes the drag, as for any drag
            page.keyboard.press("Control+z")
            page.wait_for_function(f"() => {M}.history().index === {start['history']['index']}")
            assert work(page, shown=True)["committed"] == start["committed"]
            assert "left_knee" not in page.evaluate(f"{M}.targets()")
            page.keyboard.press("Control+y")  # (redo: the drag as solved)
            page.wait_for_function(f"() => {M}.history().index === {made['history']['index']}")
            assert work(page, shown=True)["committed"] == now["committed"]
            # the two drags' page
            found(two)
            moved = f"p => {M}.committedPose().left_elbow.some((v, i) => v !== p[i])"
            two.wait_for_function(moved, arg=made_two["committed"]["left_elbow"])
            settle(two)
            assert bodies and all(b == bodies[0] for b in bodies)  # the one edit
            assert {t["joint"] for t in bodies[0]["targets"]} == set(made_two["targets"])
            now = work(two, shown=True)
            assert two.evaluate(f"{M}.error()") is None
            assert now["committed"] != made_two["committed"]
            assert now["history"] == made_two["history"]
            assert {"left_elbow", "right_knee"} <= set(now["targets"])
    finally:
        page.context.close()
        two.context.close()


@pytest.mark.browser
def test_nothing_stale_is_sent_once_it_is_back(browser: Any, outages: Outages) -> None:
    """Each case on a page of its own, all through one outage (a restart each made the test
    43 s): the kept edit undone, Reset, a sample chosen, and a drag made once the server is
    back before the page's liveness check finds it (that drag's answer does)."""
    changes = ("undo", "reset", "sample", "drag")
    with outages.up():
        pages = {change: opened(browser, outages.base) for change in changes}
        for page in pages.values():
            page.on("dialog", lambda d: d.accept())  # (a sample over edits asks first)
            drag_joint(page, "right_wrist", 30, -40)
    try:
        made, count = {}, {}
        for change, page in pages.items():
            unreachable(page, "left_knee")
            if change == "undo":
                page.keyboard.press("Control+z")
                page.wait_for_function(f"() => !('left_knee' in {M}.targets())")
            elif change == "reset":
                page.click("#reset")
                page.wait_for_function(f"() => Object.keys({M}.targets()).length === 0")
            elif change == "sample":
                page.select_option("#sample", "2")
                page.wait_for_function("document.getElementById('sample').value === '2'")
            else:  # (the page's liveness check kept from finding it: its drag does)
                page.route("**/v2/health/live", lambda route: route.abort())
            made[change], count[change] = work(page, shown=True), sent(page)
        with outages.up():
            for change in changes[:3]:
                back(pages[change])
            # a drag made once it is back, before the page's liveness check finds it (that
            # drag's answer does): its own solves go, and nothing else
            page = pages["drag"]
            drag_joint(page, "left_wrist", 20, -20)
            assert page.evaluate(STATUS) == "connected"
            count["drag"] = sent(page)
            page.unroute("**/v2/health/live")
            quiet(*pages.values())
            for change in changes[:3]:
                page = pages[change]
                assert sent(page) == count[change], change  # nothing sent
                assert work(page, shown=True) == made[change], change
                assert page.evaluate(f"{M}.error()") is None
            page = pages["drag"]
            assert sent(page) == count["drag"]
            assert page.evaluate(f"{M}.history().index") == made["drag"]["history"]["index"] + 1
            joints = {t["joint"] for t in page.evaluate(f"{M}.lastSolve().request.targets")}
            assert {"left_knee", "left_wrist"} <= joints  # (the drag's solve had both)
    finally:
        for page in pages.values():
            page.context.close()


@pytest.mark.browser
def test_an_edit_sent_again_that_fails_again_is_said_and_not_sent_a_third_time(
    browser: Any, outages: Outages
) -> None:
    with outages.up():
        page = opened(browser, outages.base)
    try:
        start = work(page, shown=True)
        unreachable(page, "left_knee")
        count = sent(page)
        page.route("**/v1/solve", lambda route: route.abort())  # (the server back, its solves not)
        with outages.up():
            found(page)
            detail = f"({M}.error() && {M}.error().detail || '')"
            page.wait_for_function(f"() => {detail}.includes('failed again')")
            assert sent(page) == count + 1
            assert work(page, shown=True)["committed"] == start["committed"]
            assert "left_knee" in page.evaluate(f"{M}.targets()")
            found(page)
            quiet(page)
            assert sent(page) == count + 1  # (not a third time)
            assert "failed again" in page.evaluate(detail)  # (still said: test below)
    finally:
        page.context.close()


def failed_again(pages: list[Any], outages: Outages) -> list[int]:
    """On each page, a drag the outage interrupted, sent again once the server is back,
    which finds it gone again (held on its way while the server stops: a real connection
    refused): its "failed again" banner, the status "server unreachable". The solves each
    page sent so far."""
    counts, held = [], []
    for page in pages:
        unreachable(page, "left_knee")
        counts.append(sent(page))
        held.append(holding(page))
    with outages.ready(*pages):
        for page, routes in zip(pages, held, strict=True):
            found(page)
            caught(page, routes)  # (sent again, held)
    for page, routes, count in zip(pages, held, counts, strict=True):
        routes[0].continue_()
        detail = f"({M}.error() || {{detail: ''}}).detail"
        page.wait_for_function(f"() => {detail}.includes('failed again')")
        page.unroute("**/v1/solve")
        assert page.evaluate(STATUS) == "server unreachable"
        assert sent(page) == count + 1
    return [count + 1 for count in counts]


@pytest.mark.browser
def test_the_failed_again_banner_stays_once_the_server_is_back(
    browser: Any, outages: Outages
) -> None:
    """The banner of an edit sent again that failed again stays when the page's liveness
    check finds the server back: the edit is not sent again, and is not applied. It went
    then (the banner of a server unreachable, status 0, goes once it is back), the status
    "connected", no error, the edit never solved. It goes once an edit is solved, or with
    the edit undone (each on a page of its own, through the same outages)."""
    thens = ("drag", "undo")
    with outages.up():
        pages = [opened(browser, outages.base) for _ in thens]
    try:
        made = [work(page, shown=True) for page in pages]
        counts = failed_again(pages, outages)
        with outages.up():
            for page in pages:
                found(page)
            quiet(*pages)
            for then, page, was, count in zip(thens, pages, made, counts, strict=True):
                err = page.evaluate(f"{M}.error()")
                assert err is not None and "failed again" in err["detail"], then
                assert page.locator("#error").is_visible()
                assert sent(page) == count  # (nothing sent since)
                assert work(page)["committed"] == was["committed"]  # (not applied)
                if then == "drag":
                    drag_joint(page, "right_wrist", 20, -20)  # an edit solved
                else:
                    page.keyboard.press("Control+z")  # the edit undone
                    index = was["history"]["index"]
                    page.wait_for_function(f"() => {M}.history().index === {index}")
                assert page.evaluate(f"{M}.error()") is None, then
                assert page.locator("#error").is_hidden()
    finally:
        for page in pages:
            page.context.close()


def example_file() -> str:
    text: str = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    return text


@pytest.mark.browser
def test_a_files_edit_an_outage_interrupted_is_sent_again(browser: Any, outages: Outages) -> None:
    with outages.up():
        page = opened(browser, outages.base)
        open_file(page, example_file(), "walk.bvh")
        drag_joint(page, "left_wrist", 20, -20)
        text = page.evaluate(f"{M}.bvhText()")
    try:
        unreachable(page, "right_wrist", -20, -20)
        made = work(page, shown=True)
        assert page.evaluate(f"{M}.bvhText()") == text  # (the file as before the drag)
        with outages.up():
            back(page)
            now = work(page, shown=True)
            assert page.evaluate(f"{M}.error()") is None
            assert now["committed"] != made["committed"] and now["history"] == made["history"]
            assert page.evaluate(f"{M}.bvhText()") != text  # the file's frame rewritten
            assert page.evaluate(f"{M}.lastSolve().request.frame") == 0
            page.keyboard.press("Control+z")
            page.wait_for_function(f"() => {M}.bvhText() === {json.dumps(text)}")
            assert "right_wrist" not in page.evaluate(f"{M}.targets()")
    finally:
        page.context.close()


@pytest.mark.browser
def test_an_edit_made_while_the_edit_sent_again_is_on_its_way_is_a_step_of_its_own(
    browser: Any, outages: Outages
) -> None:
    """The edit sent again still on its way when the user edits (a target's value typed,
    a joint clicked, another dragged): it lands as the interrupted drag's one step, solved,
    and the new edit is a step of its own on it (a click that changed nothing, none). It
    was left the drag's unsolved step, and the next answer, the drag's and the new edit's,
    one step on it (a click's, the drag's a second step)."""
    hows = ("typed", "clicked", "dragged")  # (each on a page of its own, one outage)
    with outages.up():
        pages = {how: opened(browser, outages.base) for how in hows}
    helds: dict[str, list[Any]] = {how: [] for how in hows}

    def hold(held: list[Any]) -> Any:
        def route(route: Any) -> None:  # (held until let go: then through)
            if held and held[-1] is None:
                route.continue_()
            else:
                held.append(route)

        return route

    try:
        start, made, count = {}, {}, {}
        for how, page in pages.items():
            start[how] = work(page, shown=True)
            unreachable(page, "left_knee")
            made[how], count[how] = work(page, shown=True), sent(page)
            page.route("**/v1/solve", hold(helds[how]))
            # (found only once the models are loaded, and each page in its turn: a held
            # solve is given up after 60 s, api.js NO_ANSWER_MS)
            page.route("**/v2/health/live", lambda route: route.abort())
        with outages.up():
            for how, page in pages.items():
                held = helds[how]
                page.unroute("**/v2/health/live")
                found(page)
                caught(page, held)  # (sent again, held)
                assert len(held) == 1
                if how == "typed":
                    pick(page, "right_wrist")
                    page.fill("#joint-y", "1.2")
                    page.press("#joint-y", "Enter")
                else:
                    xy = page.evaluate(f"{M}.projectJoint('right_wrist')")
                    page.mouse.move(xy["x"], xy["y"])
                    page.mouse.down()
                    if how == "dragged":
                        page.mouse.move(xy["x"] + 20, xy["y"] - 20, steps=4)
                    page.mouse.up()
                    page.wait_for_function(f"() => {M}.selected() === 'right_wrist'")
                held.append(None)  # (let go)
                held[0].continue_()
                settle(page)
                page.unroute("**/v1/solve")
                now = work(page, shown=True)
                assert page.evaluate(f"{M}.error()") is None
                steps = made[how]["history"]["index"] + (0 if how == "clicked" else 1)
                assert now["history"]["index"] == steps, how
                assert now["pose"] == now["committed"]
                if how != "clicked":
                    assert "right_wrist" in now["targets"]
                    if how == "typed":
                        assert now["targets"]["right_wrist"][1] == 1.2
                        assert sent(page) == count[how] + 2  # (sent again; the value typed)
                    page.focus(VIEW)  # (a field's own keys are not the page's undo)
                    page.keyboard.press("Control+z")  # the new edit undone
                    page.wait_for_function(f"() => {M}.history().index === {steps - 1}")
                else:
                    assert now["targets"] == made[how]["targets"]
                    assert sent(page) == count[how] + 1  # (the click asked nothing new)
                # the drag, solved: its one step
                drag = work(page, shown=True)
                assert drag["targets"] == made[how]["targets"], how
                assert drag["committed"] != start[how]["committed"], how
                page.keyboard.press("Control+z")  # and before it
                before = made[how]["history"]["index"] - 1
                page.wait_for_function(f"() => {M}.history().index === {before}")
                assert work(page, shown=True)["committed"] == start[how]["committed"]
                assert "left_knee" not in page.evaluate(f"{M}.targets()")
    finally:
        for page in pages.values():
            page.context.close()
