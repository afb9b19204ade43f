"""The hover label (and the joint lit) under a still pointer, when the pose moves under it:
another frame typed in the frame box, an undo, another file opened. The label stayed where it
was, naming the joint that had been under the pointer, over empty space, and over another
file's body with the file before's joint name ("left_wrist (LeftHand)") (an audit,
2026-12-07). It is found again under the pointer (``editor/interaction.js`` ``rehover``).

The real server and a real Chromium (``tests/service/editor_page.py``); real files from the
mocap archives (AnimatedDrawings ``fair1/dab.bvh``: inches, +Z up; ReActIdle).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import M, open_editor, open_file, settle, show_frame

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

FAR = 40  # px: no joint within this of the pointer, the label must be hidden


def label(page: Any) -> str | None:
    """The hover label's text, or None where it is hidden."""
    hud = page.locator("#hud")
    return None if hud.is_hidden() else hud.text_content()


def nearest(page: Any, x: float, y: float) -> tuple[str, float]:
    """The joint whose handle is nearest to (x, y) on screen, and how far (px)."""
    page.wait_for_timeout(100)  # (a frame rendered: the camera as drawn)
    at = {j: page.evaluate(f"{M}.projectJoint('{j}')") for j in page.evaluate(f"{M}.joints()")}
    return min(((j, math.hypot(p["x"] - x, p["y"] - y)) for j, p in at.items()), key=lambda t: t[1])


def consistent(page: Any, x: float, y: float) -> str | None:
    """The label names the joint under (x, y), or is hidden where none is near."""
    joint, d = nearest(page, x, y)
    text = label(page)
    if d > FAR:
        assert text is None, (text, joint, d)
    elif text is not None:
        assert text.split(" ")[0] == joint, (text, joint, d)
    return text


@pytest.mark.browser
def test_the_hover_label_follows_the_pose_under_a_still_pointer(
    server: str, browser: Any, more_mocap: Path
) -> None:
    dab = next(more_mocap.rglob("fair1/dab.bvh")).read_text()
    other = next(more_mocap.rglob("genuine/003_genuine.bvh")).read_text()
    page = open_editor(browser, server)
    try:
        page.select_option("#bvh-units", "in")
        open_file(page, dab, "dab.bvh")
        wrist = page.evaluate(f"{M}.projectJoint('left_wrist')")
        x, y = wrist["x"], wrist["y"]
        page.mouse.move(x, y)
        page.wait_for_function("() => !document.getElementById('hud').hidden")
        assert label(page) == "left_wrist (LeftHand)"

        # another frame typed (the pointer still): the wrist has gone from under it
        show_frame(page, 200)
        assert nearest(page, x, y)[1] > FAR  # (the case this test is about)
        assert consistent(page, x, y) is None
        show_frame(page, 0)  # back under the pointer: said again, the pointer not moved
        assert label(page) == "left_wrist (LeftHand)"

        # a drag, then undone: the wrist goes back from under the pointer
        page.mouse.down()
        for i in range(1, 9):
            page.mouse.move(x + 10 * i, y - 8 * i)
            page.wait_for_timeout(16)
        page.mouse.up()
        settle(page)
        assert label(page) == "target: left_wrist"  # (exact reach: under the pointer)
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => {M}.history().index === 0")
        assert nearest(page, x + 80, y - 64)[1] > FAR
        assert consistent(page, x + 80, y - 64) is None

        # another file opened under the pointer: no label of the file before
        page.once("dialog", lambda d: d.accept())
        open_file(page, other, "003.bvh")
        text = consistent(page, x + 80, y - 64)
        assert text is None or "LeftHand" not in text
    finally:
        page.context.close()
