"""The Units menu's "other…" cancelled goes back to the choice before it. With no file open
it went back to ``auto`` (a review, 2026-12-07): units picked for the next file were lost
by a look at "other…". With a file open it goes back to the file's units, as before.

The real server and a real Chromium (``tests/service/editor_page.py``); a real
AnimatedDrawings file (``fair1/dab.bvh``: inches, +Z up) from the mocap archives.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import M, open_editor, open_file

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

UNITS = "#bvh-units"


@pytest.mark.browser
def test_other_units_cancelled_keeps_the_choice_before(
    server: str, browser: Any, more_mocap: Path
) -> None:
    text = next(more_mocap.rglob("fair1/dab.bvh")).read_text()
    page = open_editor(browser, server)
    dialogs: list[str] = []

    def on_dialog(d: Any) -> None:
        dialogs.append(d.message)
        d.dismiss()

    page.on("dialog", on_dialog)
    try:
        page.select_option(UNITS, "in")  # no file open: the next file's units
        page.select_option(UNITS, "other")
        page.wait_for_function(f"() => document.querySelector('{UNITS}').value !== 'other'")
        assert len(dialogs) == 1
        assert page.locator(UNITS).input_value() == "in"
        open_file(page, text, "dab.bvh")  # read in inches, as picked
        assert page.evaluate(f"{M}.bvh().units") == "in"
        page.select_option(UNITS, "other")  # a file open: back to its units
        page.wait_for_function(f"() => document.querySelector('{UNITS}').value !== 'other'")
        assert len(dialogs) == 2 and page.locator(UNITS).input_value() == "in"
    finally:
        page.context.close()
