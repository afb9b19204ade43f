"""A frame's banners, as the frame shown is. A "No such frame" banner (a frame typed that the
file does not have) stayed up after the slider showed a frame that exists (an audit,
2026-12-07): it goes when a frame is shown.

The real server and a real Chromium (``tests/service/editor_page.py``); a real
AnimatedDrawings file (``fair1/dab.bvh``: inches, +Z up) from the mocap archives.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import M, drag_joint, open_editor, open_file

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

BOX = "#bvh-frame-number"


def title(page: Any) -> str | None:
    err = page.evaluate(f"{M}.error()")
    return err and err["title"]


def show(page: Any, frame: int) -> None:
    page.locator(BOX).fill(str(frame))
    page.keyboard.press("Enter")
    page.wait_for_function(f"() => {M}.bvh().frame === {frame}")


@pytest.mark.browser
def test_no_such_frame_goes_when_a_frame_is_shown(
    server: str, browser: Any, more_mocap: Path
) -> None:
    text = next(more_mocap.rglob("fair1/dab.bvh")).read_text()
    page = open_editor(browser, server)
    try:
        page.select_option("#bvh-units", "in")
        open_file(page, text, "dab.bvh")
        page.locator(BOX).fill("5000")
        page.keyboard.press("Enter")
        assert title(page) == "No such frame"
        page.focus("#bvh-frame")  # the slider, by its keys
        page.keyboard.press("ArrowRight")
        page.wait_for_function(f"() => {M}.bvh().frame === 1")
        assert title(page) is None
        # the box's own arrows show a frame too
        page.locator(BOX).fill("-3")
        page.keyboard.press("Enter")
        assert title(page) == "No such frame"
        page.keyboard.press("ArrowUp")
        page.wait_for_function(f"() => {M}.bvh().frame === 2")
        assert title(page) is None
        # an undo showing its edit's frame
        drag_joint(page, "left_wrist", 30, -40)
        show(page, 3)
        page.locator(BOX).fill("5000")
        page.keyboard.press("Enter")
        assert title(page) == "No such frame"
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => {M}.history().index === 0")
        assert page.evaluate(f"{M}.bvh()")["frame"] == 2 and title(page) is None
    finally:
        page.context.close()
