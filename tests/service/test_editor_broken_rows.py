"""A BVH file one frame a line whose line of a frame mid-file is broken (a value lost, a
value that is no number): the service reads only the frames it is asked for, says so at
opening (``rows_warning``) and refuses that frame with a 422 naming its line. The page said
nothing at opening, and scrubbed to that frame it read the frame from the whole file's
values, every value after the broken line shifted: it drew another pose (the frame with a
value lost) or half a body (the one with 'abc'), without a word (an audit, 2026-12-07). Now
the opening banner gives the service's warning, and that frame has no pose (nothing drawn,
nothing grabbed) under a "Broken frame" banner naming its line; the other frames are drawn
as the service reads them, and edited and exported with the broken lines as they were.

The real server and a real Chromium (``tests/service/editor_page.py``); a real
AnimatedDrawings file (``fair1/dab.bvh``: inches, +Z up) from the mocap archives.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import (
    M,
    drag_joint,
    drawn_as_inspected,
    open_editor,
    open_file,
    show_frame,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)


def broken_file(path: Path) -> str:
    """The file's first 20 frames, frame 5's line a value short, frame 8's with 'abc'."""
    head, motion = path.read_text().split("MOTION\n", 1)
    lines = motion.split("\n")
    rows = [row for row in lines[2:] if row.strip()][:20]
    rows[5] = " ".join(rows[5].split()[:-1])
    words = rows[8].split()
    words[10] = "abc"
    rows[8] = " ".join(words)
    return f"{head}MOTION\nFrames: 20\n{lines[1]}\n" + "\n".join(rows) + "\n"


@pytest.mark.browser
def test_a_broken_frame_line_is_said_and_not_drawn_as_another_pose(
    server: str, browser: Any, more_mocap: Path
) -> None:
    text = broken_file(next(more_mocap.rglob("fair1/dab.bvh")))
    line_of = {f: 168 + f for f in (5, 8)}  # (frame 0 is the file's line 168)
    page = open_editor(browser, server)
    try:
        page.select_option("#bvh-units", "in")
        open_file(page, text, "bad.bvh")
        err = page.evaluate(f"{M}.error()")
        assert err["title"] == "Broken file", err
        assert f"line {line_of[5]}: frame 5 holds 83 values, not 84" in err["detail"]

        def inspected(frame: int) -> None:
            body = {"bvh": text, "frame": frame, "units": "in"}
            drawn_as_inspected(page, server, body)

        show_frame(page, 4)
        inspected(4)
        for frame, holds in ((5, "83 values, not 84"), (8, "a value that is no number ('abc')")):
            show_frame(page, frame)
            # no pose: not the whole file's values read shifted (another pose, half a body)
            assert all(math.isnan(v) for p in page.evaluate(f"{M}.bvhPositions()") for v in p)
            err = page.evaluate(f"{M}.error()")
            assert err["title"] == "Broken frame"
            assert err["detail"].startswith(f"bad.bvh: line {line_of[frame]}: frame {frame} holds")
            assert holds in err["detail"]
            # nothing there to grab: a press where the pelvis was orbits
            show_frame(page, frame - 1)
            xy = page.evaluate(f"{M}.projectJoint('pelvis')")
            show_frame(page, frame)
            page.mouse.move(xy["x"], xy["y"])
            page.mouse.down()
            page.mouse.move(xy["x"] + 30, xy["y"] - 30, steps=4)
            page.mouse.up()
            assert page.evaluate(f"{M}.targets()") == {}
        show_frame(page, 6)
        inspected(6)
        assert page.evaluate(f"{M}.error()") is None  # (the frame's banner gone with it)

        drag_joint(page, "left_wrist", 30, -40)
        assert page.evaluate(f"{M}.error()") is None
        with page.expect_download() as download:
            page.click("#export")
        out = Path(download.value.path()).read_text()
        was, got = text.split("\n"), out.split("\n")
        changed = [i for i, (a, b) in enumerate(zip(was, got, strict=True)) if a != b]
        assert changed == [167 + 6]  # frame 6's line alone; the broken ones as they were

        # an undo from a broken frame shows the edit's frame: the banner goes with the frame
        show_frame(page, 8)
        assert page.evaluate(f"{M}.error()")["title"] == "Broken frame"
        page.click("#undo")
        page.wait_for_function(f"() => {M}.history().index === 0")
        assert page.evaluate(f"{M}.bvh()")["frame"] == 6
        assert page.evaluate(f"{M}.error()") is None
    finally:
        page.context.close()


@pytest.mark.browser
def test_frames_read_as_words_are_drawn_as_the_service_reads_them(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """A blank line among the frames: the service reads the frames as words over the block,
    whatever a line holds, so a line a value short beside one a value long is no broken
    frame: each is drawn as the service reads it, no banner."""
    head, motion = next(more_mocap.rglob("fair1/dab.bvh")).read_text().split("MOTION\n", 1)
    lines = motion.split("\n")
    rows = [row for row in lines[2:] if row.strip()][:6]
    rows[2], rows[3] = " ".join(rows[2].split()[:-1]), rows[3] + " " + rows[2].split()[-1]
    blocks = "\n".join(rows[:2]) + "\n\n" + "\n".join(rows[2:])
    text = f"{head}MOTION\nFrames: 6\n{lines[1]}\n{blocks}\n"
    page = open_editor(browser, server)
    try:
        page.select_option("#bvh-units", "in")
        open_file(page, text, "words.bvh")
        for frame in (1, 2, 3, 4):
            show_frame(page, frame)
            drawn_as_inspected(page, server, {"bvh": text, "frame": frame, "units": "in"})
            assert page.evaluate(f"{M}.error()") is None
    finally:
        page.context.close()
