"""The BVH menus (Units, Up axis, Root channels) set before a file is opened: an animator who
knows the file (a child skeleton in inches, +Z up) picks them, then opens it. The page put
them back to auto as the file opened, and the service refused it for its units, the banner
saying "pick them in the Units menu", just picked there (an audit, 2026-12-07). A file
closed (a Sample) puts the menus back to the defaults, and another file opened over an open
one starts at them, as before.

The real server and a real Chromium (``tests/service/editor_page.py``); a real
AnimatedDrawings file (``fair1/dab.bvh``: inches, +Z up) from the mocap archives.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import M, drag_joint, open_editor, open_file, recorded

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

MENUS = ("#bvh-units", "#bvh-up", "#bvh-root")


def menus(page: Any) -> list[str]:
    return [page.locator(m).input_value() for m in MENUS]


@pytest.mark.browser
def test_menus_chosen_before_a_file_are_the_ones_it_is_read_with(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """Units `in` and Up `+Z` picked with no file: nothing sent; the file opens with them at
    once (one inspection, no refusal) and is edited. A Sample closes it: the menus back at
    auto. The file opened then is read with auto (refused for its units, as before)."""
    text = next(more_mocap.rglob("fair1/dab.bvh")).read_text()
    page = open_editor(browser, server)
    inspected = recorded(page, lambda url: url.endswith("/v1/bvh/inspect"))
    try:
        page.select_option("#bvh-units", "in")
        page.select_option("#bvh-up", "+Z")
        page.wait_for_timeout(200)
        assert inspected == [] and page.evaluate(f"{M}.error()") is None
        open_file(page, text, "dab.bvh")
        assert page.evaluate(f"{M}.error()") is None
        assert [(b["units"], b["up"]) for b in inspected] == [("in", "+Z")]
        info = page.evaluate(f"{M}.bvh()")
        assert (info["units"], info["up"]) == ("in", "+Z")
        assert menus(page) == ["in", "+Z", "replace"]
        drag_joint(page, "left_wrist", 30, -40)
        assert page.evaluate(f"{M}.bvh()")["edited"] and page.evaluate(f"{M}.error()") is None

        # a Sample closes the file: the menus said how it was read, and go back to auto
        page.once("dialog", lambda d: d.accept())  # (its edits are dropped)
        page.select_option("#sample", "1")
        page.wait_for_function(f"() => {M}.bvh() === null")
        assert menus(page) == ["auto", "auto", "replace"]
        # the next file is read as the menus say: auto (refused for its units)
        page.set_input_files(
            "#bvh-file",
            files=[{"name": "dab.bvh", "mimeType": "text/plain", "buffer": text.encode()}],
        )
        page.wait_for_function(f"() => {M}.error() && {M}.error().status === 422")
        assert (
            "units" not in inspected[-1]
            and "in the Units menu" in page.evaluate(f"{M}.error()")["detail"]
        )
        # picked now, it is read again with them
        page.select_option("#bvh-units", "in")
        page.wait_for_function(f"() => {M}.bvh() !== null")
        assert inspected[-1]["units"] == "in"
    finally:
        page.context.close()


@pytest.mark.browser
def test_another_file_over_an_open_one_starts_at_the_defaults(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """With a file open (read as inches), another file opened starts at auto: the menus said
    how the open file was read, no choice for the next (a centimetre file read as inches
    was a giant)."""
    text = next(more_mocap.rglob("fair1/dab.bvh")).read_text()
    other = next(more_mocap.rglob("genuine/003_genuine.bvh")).read_text()
    page = open_editor(browser, server)
    inspected = recorded(page, lambda url: url.endswith("/v1/bvh/inspect"))
    try:
        page.select_option("#bvh-units", "in")
        page.select_option("#bvh-up", "+Z")
        open_file(page, text, "dab.bvh")
        open_file(page, other, "003.bvh")
        assert "units" not in inspected[-1] and "up" not in inspected[-1]
        info = page.evaluate(f"{M}.bvh()")
        assert (info["units"], info["up"]) == ("m", "+Y")
        assert menus(page)[:2] == ["auto", "auto"]
    finally:
        page.context.close()
