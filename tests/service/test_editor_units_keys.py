"""The file's menus arrowed through from the keyboard. A closed menu changes, and fires its
change, at each arrow: each unit passed read the file again (a ``/v1/bvh/inspect`` each),
and reaching "other…" popped its prompt (an audit, 2026-12-07). Now an arrowed choice is
taken on Enter, or when the menu is left (then "other…" asks nothing and the menu goes
back), and only where it differs from the value before the arrows.

The real server and a real Chromium (``tests/service/editor_page.py``); a real
AnimatedDrawings file (``fair1/dab.bvh``: inches, +Z up) from the mocap archives.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import M, open_editor, open_file, recorded

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

UNITS = "#bvh-units"


def units(page: Any) -> str:
    return str(page.locator(UNITS).input_value())


@pytest.mark.browser
def test_arrowing_through_the_units_menu_reads_nothing_until_chosen(
    server: str, browser: Any, more_mocap: Path
) -> None:
    text = next(more_mocap.rglob("fair1/dab.bvh")).read_text()
    page = open_editor(browser, server)
    dialogs: list[str] = []
    answer = {"text": ""}

    def on_dialog(d: Any) -> None:
        dialogs.append(d.message)
        d.accept(answer["text"])

    page.on("dialog", on_dialog)
    reads = recorded(page, lambda url: url.endswith("/v1/bvh/inspect"))
    try:
        page.select_option(UNITS, "in")
        open_file(page, text, "dab.bvh")
        assert len(reads) == 1

        # in -> ft -> CMU -> other… and back, then the menu left: nothing read, no prompt
        page.focus(UNITS)
        for key in ["ArrowDown"] * 3 + ["ArrowUp"] * 3:
            page.keyboard.press(key)
            page.wait_for_timeout(50)
        assert units(page) == "in"
        page.keyboard.press("Tab")
        page.wait_for_timeout(300)
        assert (len(reads), dialogs) == (1, [])

        # from CMU (the mouse's choice: read at once), arrowed to other…: no prompt; left
        # there, the menu goes back, nothing asked
        page.select_option(UNITS, "0.0564444")
        page.wait_for_function(f"() => {M}.bvh().units === 0.0564444")
        assert len(reads) == 2
        page.focus(UNITS)
        page.keyboard.press("ArrowDown")
        page.wait_for_timeout(300)
        assert (len(reads), dialogs, units(page)) == (2, [], "other")
        page.keyboard.press("Tab")
        page.wait_for_timeout(300)
        assert (len(reads), dialogs, units(page)) == (2, [], "0.0564444")

        # arrowed to other…, Enter: asked once, read once with it
        page.focus(UNITS)
        page.keyboard.press("ArrowDown")
        answer["text"] = "0.0254"
        page.keyboard.press("Enter")
        page.wait_for_function(f"() => {M}.bvh().units === 0.0254")
        assert len(dialogs) == 1 and len(reads) == 3
        assert reads[-1]["units"] == 0.0254

        # arrowed (letters, Home too) to cm, the menu left: read once, in cm
        page.focus(UNITS)  # (at 0.0254 m, listed before other…)
        page.keyboard.press("ArrowUp")  # CMU
        page.keyboard.press("f")  # ft
        page.keyboard.press("Home")  # auto
        page.keyboard.press("ArrowDown")  # m
        page.keyboard.press("ArrowDown")  # cm
        assert units(page) == "cm" and len(reads) == 3
        page.keyboard.press("Tab")
        page.wait_for_function(f"() => {M}.bvh().units === 'cm'")
        assert len(reads) == 4 and reads[-1]["units"] == "cm" and len(dialogs) == 1

        # the mouse's (a picker's) choice is taken at once, as before
        page.select_option(UNITS, "in")
        page.wait_for_function(f"() => {M}.bvh().units === 'in'")
        assert len(reads) == 5 and len(dialogs) == 1
    finally:
        page.context.close()


@pytest.mark.browser
def test_arrowing_through_the_sample_menu_loads_nothing_until_chosen(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """The Sample pose menu arrowed through with a file open: its first arrow closed the file
    (unasked: it had no edits; no undo brings it back), each further one loaded a sample.
    Now, as the file's menus, a choice is taken on Enter; left, the menu goes back."""
    text = next(more_mocap.rglob("fair1/dab.bvh")).read_text()
    page = open_editor(browser, server)
    try:
        page.select_option(UNITS, "in")
        open_file(page, text, "dab.bvh")
        page.focus("#sample")
        page.keyboard.press("ArrowDown")
        page.keyboard.press("ArrowDown")
        page.keyboard.press("ArrowUp")
        page.keyboard.press("ArrowUp")
        page.wait_for_timeout(300)
        assert page.evaluate(f"{M}.bvh()") is not None
        page.keyboard.press("Tab")  # left: nothing taken, the menu back (no sample shown)
        page.wait_for_timeout(300)
        assert page.evaluate(f"{M}.bvh()") is not None
        assert page.locator("#sample").input_value() == ""
        page.focus("#sample")
        page.keyboard.press("ArrowDown")
        page.keyboard.press("ArrowDown")
        page.wait_for_timeout(300)
        assert page.evaluate(f"{M}.bvh()") is not None
        page.keyboard.press("Enter")  # the sample arrowed to, taken
        page.wait_for_function(f"() => {M}.bvh() === null")
        assert page.locator("#sample").input_value() == "1"
    finally:
        page.context.close()
