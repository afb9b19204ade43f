"""A frame's banners, as the frame shown is. A "No such frame" banner (a frame typed that the
file does not have) stayed up after the slider showed a frame that exists (an audit,
2026-12-07): it goes when a frame is shown. A frame's line holding a value the service does
not read as a number but JavaScript's ``Number`` does (``0x10``, ``0b11``) was drawn, and
the service's 422 named the line only when it was dragged: the page reads numbers as the
service does (ASCII decimals: sign, digits, point, exponent; ``core/bvh_words.py``
``NUMBER``), and shows that frame as broken.

The real server and a real Chromium (``tests/service/editor_page.py``); a real
AnimatedDrawings file (``fair1/dab.bvh``: inches, +Z up) from the mocap archives.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import REPO_ROOT
from tests.service.editor_page import (
    M,
    drag_joint,
    drawn_as_inspected,
    give_file,
    open_editor,
    open_file,
    recorded,
    show_frame,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

BOX = "#bvh-frame-number"


def title(page: Any) -> str | None:
    err = page.evaluate(f"{M}.error()")
    return err and err["title"]


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
        show_frame(page, 3)
        page.locator(BOX).fill("5000")
        page.keyboard.press("Enter")
        assert title(page) == "No such frame"
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => {M}.history().index === 0")
        assert page.evaluate(f"{M}.bvh()")["frame"] == 2 and title(page) is None
    finally:
        page.context.close()


def js_numbers_file(path: Path) -> str:
    """The file's first 12 frames, frame 4's line with '0x10', frame 7's with '0b11' (both
    numbers to JavaScript's ``Number``, neither to the service), frame 9's with '2.5e7' (a
    number past the ±1e7 the service reads: a review found it drawn, its drag refused)."""
    head, motion = path.read_text().split("MOTION\n", 1)
    lines = motion.split("\n")
    rows = [row for row in lines[2:] if row.strip()][:12]
    for frame, word in ((4, "0x10"), (7, "0b11"), (9, "2.5e7")):
        words = rows[frame].split()
        words[10] = word
        rows[frame] = " ".join(words)
    return f"{head}MOTION\nFrames: 12\n{lines[1]}\n" + "\n".join(rows) + "\n"


def wrapped(text: str) -> str:
    """The file with each frame over two lines (its first 40 values, then the rest), frame 2's
    first values parted by '\\x1f' (white space to the service's reader, ``str.split``, not to
    JavaScript's ``\\s``): the service reads such frames as words over the block."""
    head, motion = text.split("MOTION\n", 1)
    lines = motion.split("\n")
    rows = [row.split() for row in lines[2:] if row.strip()]
    rows[2][:4] = ["\x1f".join(rows[2][:4])]
    cut = [37 if i == 2 else 40 for i in range(len(rows))]  # (frame 2: 3 words fewer)
    body = "\n".join(
        " ".join(r[: cut[i]]) + "\n" + " ".join(r[cut[i] :]) for i, r in enumerate(rows)
    )
    return f"{head}MOTION\n{lines[0]}\n{lines[1]}\n{body}\n"


@pytest.mark.browser
def test_a_value_the_service_reads_as_no_number_is_a_broken_frame(
    server: str, browser: Any, more_mocap: Path
) -> None:
    text = js_numbers_file(next(more_mocap.rglob("fair1/dab.bvh")))
    page = open_editor(browser, server)
    try:
        page.select_option("#bvh-units", "in")
        open_file(page, text, "hex.bvh")
        err = page.evaluate(f"{M}.error()")
        assert err["title"] == "Broken file" and "0x10" in err["detail"], err
        said = {4: "a value that is no number ('0x10')", 7: "a value that is no number ('0b11')",
                9: "a value past ±1e7 ('2.5e7')"}  # fmt: skip
        for frame, holds in said.items():
            show_frame(page, frame)
            assert all(math.isnan(v) for p in page.evaluate(f"{M}.bvhPositions()") for v in p)
            err = page.evaluate(f"{M}.error()")
            assert err["title"] == "Broken frame", err
            assert err["detail"].startswith(f"hex.bvh: line {168 + frame}: frame {frame} holds")
            assert holds in err["detail"], err
        show_frame(page, 5)
        drawn_as_inspected(page, server, {"bvh": text, "frame": 5, "units": "in"})
        assert title(page) is None

        # its frames wrapped over two lines: each read as words, as the service reads them
        # (by JavaScript's Number they were: 0x10 drawn as 16, its drag refused)
        text = wrapped(text)
        give_file(page, text, "wrapped.bvh")  # (read anew: its units refused, then picked)
        page.wait_for_function(f"() => {M}.error() && {M}.error().detail.startsWith('wrapped')")
        page.select_option("#bvh-units", "in")
        page.wait_for_function(f"() => {M}.bvh().name === 'wrapped.bvh'")
        for frame, holds in said.items():
            show_frame(page, frame)
            assert all(math.isnan(v) for p in page.evaluate(f"{M}.bvhPositions()") for v in p)
            err = page.evaluate(f"{M}.error()")
            assert err["title"] == "Broken frame", err
            assert err["detail"].startswith(f"wrapped.bvh: line {168 + 2 * frame}: frame {frame}")
            assert holds in err["detail"], err
        for frame in (2, 5):  # (2: its values parted by \x1f, as the service parts them)
            show_frame(page, frame)
            drawn_as_inspected(page, server, {"bvh": text, "frame": frame, "units": "in"})
            assert title(page) is None
    finally:
        page.context.close()


@pytest.mark.browser
def test_a_file_whose_frame_0_is_broken_opens_at_its_first_whole_frame(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """Frame 0's line holding '0x10': the page asked for frame 0 and the service refused the
    whole file (422), though its other frames read; a frame 0 the page read as no pose set
    the view up from NaN. Now the file opens, inspected at its first whole frame (1), the
    view set up from it, frame 0 shown as any broken frame is."""
    head, motion = next(more_mocap.rglob("fair1/dab.bvh")).read_text().split("MOTION\n", 1)
    lines = motion.split("\n")
    rows = [row for row in lines[2:] if row.strip()][:6]
    rows[0] = rows[0].replace(" ", " 0x10 ", 1).rsplit(" ", 1)[0]
    text = f"{head}MOTION\nFrames: 6\n{lines[1]}\n" + "\n".join(rows) + "\n"
    page = open_editor(browser, server)
    inspected = recorded(page, lambda url: url.endswith("/v1/bvh/inspect"))
    try:
        page.select_option("#bvh-units", "in")
        open_file(page, text, "zero.bvh")
        assert [body["frame"] for body in inspected] == [1]
        err = page.evaluate(f"{M}.error()")
        assert err["title"] == "Broken frame", err
        assert err["detail"].startswith("zero.bvh: line 168: frame 0 holds a value that is no ")
        assert page.evaluate(f"{M}.bvh().frame") == 0
        assert all(math.isnan(v) for p in page.evaluate(f"{M}.bvhPositions()") for v in p)
        at = page.evaluate(f"{M}.projectPoint([0, 0.8, 0])")  # (the view: no NaN)
        assert math.isfinite(at["x"]) and math.isfinite(at["y"]), at
        show_frame(page, 1)
        drawn_as_inspected(page, server, {"bvh": text, "frame": 1, "units": "in"})
        assert title(page) is None
        pelvis = page.evaluate(f"{M}.projectJoint('pelvis')")
        assert 0 < pelvis["x"] < 1280 and 0 < pelvis["y"] < 800, pelvis  # (framed in view)
    finally:
        page.context.close()


def test_the_page_reads_words_as_the_service_does() -> None:
    """bvh.js ``bvhValue`` (Number first, the regex only where Number may read more) against
    the service's own reader (``core.bvh_words.as_number`` and the ±1e7 bound) on tricky
    words, and ``words`` against ``str.split`` (Python's white space, not JavaScript's)."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is needed to run the page's module")
    from core.bvh_words import as_number

    tricky = ["0x10", "0X1f", "0b11", "0o7", "1e5", "1E+5", "-0", "+.5", "5.", ".", "1e", "e1"]
    tricky += ["Infinity", "-Infinity", "nan", "1_0", "\ufeff1", "1\ufeff", "2.5e7", "-1e7", "0.b"]
    text = "1\x1f2\x853\xa04\ufeff5\u30006\t7\x0b8\x1c9"
    run = (
        "const m = await import(process.argv[1]); const [ws, t] = JSON.parse(process.argv[2]);"
        "console.log(JSON.stringify([ws.map((w) => { const v = m.bvhValue(w);"
        " return Number.isNaN(v) ? null : v; }), m.words(t)]));"
    )
    bvh_js = REPO_ROOT / "service" / "static" / "bvh.js"
    arg = json.dumps([tricky, text])
    done = subprocess.run(
        [node, "--input-type=module", "-e", run, bvh_js.as_uri(), arg],
        capture_output=True,
        text=True,
        check=True,
    )
    values, split = json.loads(done.stdout)
    want = [v if v is not None and abs(v) <= 1e7 else None for v in map(as_number, tricky)]
    assert values == want
    assert split == text.split()
