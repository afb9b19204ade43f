"""Ctrl+Z in the frame box. An animator types a frame, presses Enter, and undoes the last
edit with Ctrl+Z, the focus still in the box: the browser's own undo put back the text
typed before (a frame not shown: the box said 30, the view showed 100), the edit stayed,
and leaving the box jumped to that frame (an audit, 2026-12-07). It is the page's undo
(Ctrl+Shift+Z, Ctrl+Y: redo); while a frame is being typed, it undoes the typing: the box
shows the frame shown again, and nothing jumps.

The real server and a real Chromium (``tests/service/editor_page.py``); a real
AnimatedDrawings file (``fair1/dab.bvh``: inches, +Z up) from the mocap archives.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import M, drag_joint, open_editor, open_file, settle

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

BOX = "#bvh-frame-number"


def box(page: Any) -> str:
    return str(page.locator(BOX).input_value())


@pytest.mark.browser
def test_ctrl_z_in_the_frame_box_undoes_the_edit(
    server: str, browser: Any, more_mocap: Path
) -> None:
    text = next(more_mocap.rglob("fair1/dab.bvh")).read_text()
    assert "Frame Time:\t0.0333333\n" in text
    text = text.replace("Frame Time:\t0.0333333\n", "Frame Time:\t0.041667\n")  # (24 fps)
    page = open_editor(browser, server)
    try:
        page.select_option("#bvh-units", "in")
        open_file(page, text, "dab.bvh")
        # the rate to 2 decimals: it said "23.9998 fps" of 0.041667 s
        assert " @ 24 fps; " in page.locator("#bvh-meta").inner_text()
        # plain whole numbers only: the box took 1e1 for frame 10 (JavaScript's Number; the
        # number input keeps 1e1 and 1.0, and lets no x in: 0x10 typed is 010)
        for typed in ("1e1", "1.0"):
            page.locator(BOX).click()
            page.keyboard.press("Control+a")
            page.keyboard.type(typed)
            page.keyboard.press("Enter")
            page.wait_for_timeout(100)
            shown = (page.evaluate(f"{M}.bvh()")["frame"], box(page))
            assert shown == (0, "0"), (typed, shown)
        page.locator("#error-close").click()
        page.locator(BOX).fill("30")
        page.keyboard.press("Enter")
        page.wait_for_function(f"() => {M}.bvh().frame === 30")
        drag_joint(page, "left_wrist", 30, -40)
        edited = page.evaluate(f"{M}.bvhText()")
        assert edited != text

        page.locator(BOX).click()
        page.keyboard.press("Control+a")
        page.keyboard.type("100")
        page.keyboard.press("Enter")
        page.wait_for_function(f"() => {M}.bvh().frame === 100")
        page.keyboard.press("Control+z")  # (the focus in the box)
        page.wait_for_function(f"() => {M}.history().index === 0")
        assert page.evaluate(f"{M}.bvhText()") == text
        assert (page.evaluate(f"{M}.bvh()")["frame"], box(page)) == (30, "30")  # (the edit's)
        page.keyboard.press("Control+Shift+z")
        page.wait_for_function(f"() => {M}.history().index === 1")
        assert page.evaluate(f"{M}.bvhText()") == edited
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => {M}.history().index === 0")
        page.keyboard.press("Control+y")
        page.wait_for_function(f"() => {M}.history().index === 1")

        # a frame being typed: Ctrl+Z undoes the typing, nothing else
        page.keyboard.press("Control+a")
        page.keyboard.type("7")
        page.keyboard.press("Control+z")
        assert box(page) == "30" and page.evaluate(f"{M}.history().index") == 1
        page.keyboard.press("Tab")  # (left: no jump to a frame typed before)
        page.wait_for_timeout(200)
        assert page.evaluate(f"{M}.bvh()")["frame"] == 30 and box(page) == "30"
        assert page.evaluate(f"{M}.bvhText()") == edited
    finally:
        page.context.close()


def press_and_drag(page: Any, x: float, y: float, dx: float, dy: float) -> None:
    page.mouse.move(x, y)
    page.mouse.down()
    for i in range(1, 9):
        page.mouse.move(x + dx * i / 8, y + dy * i / 8)
        page.wait_for_timeout(16)
    page.mouse.up()
    settle(page)


@pytest.mark.browser
def test_a_press_that_takes_a_frame_typed_grabs_only_what_is_under_it(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """A frame typed in the box (no Enter), then a joint of the frame shown pressed and
    dragged: the press takes the frame typed (the box left), and grabs what is under the
    pointer on that frame. The wrist picked on the frame before was grabbed on the new one,
    140 px away, and dragged: an edit of frame 200 the user never saw, the wrist not under
    the pointer (exact reach)."""
    text = next(more_mocap.rglob("fair1/dab.bvh")).read_text()
    page = open_editor(browser, server)
    try:
        page.select_option("#bvh-units", "in")
        open_file(page, text, "dab.bvh")
        at = page.evaluate(f"{M}.projectJoint('left_wrist')")
        page.locator(BOX).click()
        page.keyboard.press("Control+a")
        page.keyboard.type("200")  # (no Enter)
        press_and_drag(page, at["x"], at["y"], 40, -40)
        assert page.evaluate(f"{M}.bvh()")["frame"] == 200
        moved = page.evaluate(f"{M}.projectJoint('left_wrist')")
        assert abs(moved["x"] - at["x"]) + abs(moved["y"] - at["y"]) > 60  # (not under it)
        assert page.evaluate(f"{M}.targets()") == {}
        assert page.evaluate(f"{M}.history().index") == 0
        assert page.evaluate(f"{M}.bvhText()") == text

        # a frame whose wrist is still under the pointer: grabbed there, and dragged under it
        page.locator(BOX).fill("0")
        page.keyboard.press("Enter")
        page.wait_for_function(f"() => {M}.bvh().frame === 0")
        at = page.evaluate(f"{M}.projectJoint('left_wrist')")
        page.locator(BOX).click()
        page.keyboard.press("Control+a")
        page.keyboard.type("1")
        press_and_drag(page, at["x"], at["y"], 40, -40)
        assert page.evaluate(f"{M}.bvh()")["frame"] == 1
        assert set(page.evaluate(f"{M}.targets()")) == {"left_wrist"}
        end = page.evaluate(f"{M}.projectJoint('left_wrist')")
        grab = page.evaluate(f"{M}.history()")["index"]
        assert grab == 1 and page.evaluate(f"{M}.error()") is None
        # under the pointer but for the grab's offset (the wrist at frame 1 under the press)
        assert abs(end["x"] - at["x"] - 40) < 20 and abs(end["y"] - at["y"] + 40) < 20
    finally:
        page.context.close()
