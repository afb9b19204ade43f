"""The editor's memory with a big file (``service/static/editor/``): the page's JS heap after
a garbage collection holds the file's text about once, and an edit adds the few kB its undo
step holds, not a copy of the file.

Found by measuring (2026-12-06, a 7.5 MB file, six edits): the last solve kept its request,
the file before the edit (7.5 MB more for as long as it was the last), and after an undo
its answer's text too (7.5 MB more); a file opened over another's edits kept the yes to
replacing them, and with it that file's text, for as long as the new file was open.

The real server and a real Chromium (``tests/service/editor_page.py``); a real ReActIdle file
(``tests/character_files.py``) made ~7.5 MB by repeating its frames. ``JSHeapUsedSize``
(CDP) counts the strings the page made (a solve's answer, an undo's text) but not the file
as read from the disk (the decoder's string is held outside V8's heap): the bounds below are
on the growth over the page with a sample.

``MARIONETTE_HEAP_FIGURES=1 python -m pytest tests/service/test_editor_memory.py -s`` prints
the figures (docs/editor.md, "Memory").
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from tests.character_files import big_file
from tests.service.editor_page import M, drag_joint, open_editor, open_file

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

SIZE = 7_500_000
#: an edit's growth of the heap, at most (its undo step holds ~2 kB; measured 10-60 kB an
#: edit with the page's own bookkeeping; a copy of the file is 7.5 MB, its parsed frames 8 MB)
PER_EDIT = 400_000


def say_figures(figures: list[tuple[str, float]], size: int, how: str) -> None:
    """The heap figures printed, with MARIONETTE_HEAP_FIGURES=1 (docs/editor.md's table)."""
    if not os.environ.get("MARIONETTE_HEAP_FIGURES"):
        return
    print(f"\nJSHeapUsedSize after GC, a {size / 1e6:.2f} MB file{how}:")
    empty = figures[0][1]
    for name, value in figures:
        print(f"{name:>20}: {value / 1e6:6.2f} MB ({(value - empty) / size:+.2f} x the file)")


def opened(page: Any, text: str, name: str) -> tuple[Any, list[tuple[str, float]]]:
    """:func:`heap_of` ``page``, and its figures before and after ``text`` is opened."""
    heap = heap_of(page)
    empty = heap()
    open_file(page, text, name)
    return heap, [("the sample", empty), ("file opened", heap())]


def heap_of(page: Any) -> Any:
    """A function giving the page's JS heap in use after a forced garbage collection (bytes,
    CDP ``Performance.getMetrics``' ``JSHeapUsedSize``)."""
    cdp = page.context.new_cdp_session(page)
    cdp.send("Performance.enable")

    def heap() -> float:
        for _ in range(2):  # (a second pass: what the first one's finalizers let go)
            cdp.send("HeapProfiler.collectGarbage")
        metrics = cdp.send("Performance.getMetrics")["metrics"]
        return float(next(m["value"] for m in metrics if m["name"] == "JSHeapUsedSize"))

    return heap


def edit(page: Any, frame: int, joint: str, steps: int) -> None:
    """A drag of ``joint`` at ``frame`` (one solve: a 7.5 MB answer), committed as the
    history's step ``steps``."""
    if page.evaluate(f"{M}.bvh().frame") != frame:
        page.locator("#bvh-frame").fill(str(frame))
        page.wait_for_function(f"() => {M}.bvh().frame === {frame}")
    drag_joint(page, joint, 25, -30, steps=1)
    page.wait_for_function(f"() => {M}.history().length === {steps}")


@pytest.mark.browser
def test_editor_heap_with_a_big_file(server: str, browser: Any, bvh_files: dict[str, Path]) -> None:
    """A 7.5 MB file opened and edited six times at three frames: the heap holds its text
    about once (not the last solve's request too), grows by far less than a copy an edit,
    and after two undos holds no more (not the undone answer's text). Another 7.5 MB file
    opened over the edits and edited: the first file's texts are gone."""
    text = big_file(bvh_files["reactidle-6ch"], SIZE)
    page = open_editor(browser, server)
    try:
        heap, figures = opened(page, text, "big.bvh")
        empty = figures[0][1]
        edits = [
            (0, "left_wrist"),
            (0, "right_ankle"),
            (2000, "right_wrist"),
            (2000, "left_ankle"),
            (4500, "left_wrist"),
            (4500, "right_wrist"),
        ]
        for k, (frame, joint) in enumerate(edits):
            edit(page, frame, joint, k + 2)
            figures.append((f"edit {k + 1}", heap()))
        size = page.evaluate(f"{M}.historySize()")
        assert size["steps"] == 7 and size["chars"] < 6 * 4_000  # (a line before and after)
        # no copy of the file an edit (a step, the last solve's request, a parsed file ...)
        per_edit = (figures[-1][1] - figures[3][1]) / 4
        assert per_edit < PER_EDIT, figures
        # the edited text once (was twice: the last solve's request held the text before)
        assert figures[-1][1] - empty < 1.5 * len(text), figures

        page.click("#undo")
        page.click("#undo")
        page.wait_for_function(f"() => {M}.history().index === 4")
        figures.append(("2 undos", heap()))
        # (was once more: the last solve's answer, the text of a step undone)
        assert figures[-1][1] - empty < 1.5 * len(text), figures

        # -- another file over the edits: the first one's texts go ----------------------------
        other = big_file(bvh_files["reactidle-6ch"], SIZE, skip=7)
        page.once("dialog", lambda d: d.accept())  # (the edits are dropped)
        open_file(page, other, "other.bvh")
        edit(page, 0, "left_wrist", 2)
        figures.append(("other file, edited", heap()))
        # (was twice: the yes to dropping the first file's edits held its text)
        assert figures[-1][1] - empty < 1.5 * len(text), figures
        say_figures(figures, len(text), "")
    finally:
        page.context.close()


def split_frames(text: str) -> str:
    """``text`` with each frame's line cut in two after its sixth value (a file the page reads
    whole: its frames are not one a line)."""
    head, motion = text.split("Frame Time:", 1)
    time, rows = motion.split("\n", 1)
    out = []
    for row in rows.split("\n"):
        values = row.split(" ")
        out.append(" ".join(values[:6]) + "\n" + " ".join(values[6:]) if len(values) > 6 else row)
    return f"{head}Frame Time:{time}\n" + "\n".join(out)


@pytest.mark.browser
def test_editor_heap_with_a_big_file_read_whole(
    server: str, browser: Any, bvh_files: dict[str, Path]
) -> None:
    """The same 7.5 MB file with each frame over two lines (the page parses such a file
    whole to draw a frame): four edits, the heap holds its text about once (the values
    parsed were kept for the last six texts, each answer's: +7.5 MB an edit, 50 MB after
    six), and an edit adds far less than a copy."""
    text = split_frames(big_file(bvh_files["reactidle-6ch"], SIZE))
    page = open_editor(browser, server)
    try:
        heap, figures = opened(page, text, "split.bvh")
        empty = figures[0][1]
        for k, (frame, joint) in enumerate(
            [(0, "left_wrist"), (0, "right_wrist"), (100, "left_ankle"), (200, "right_wrist")]
        ):
            edit(page, frame, joint, k + 2)
            figures.append((f"edit {k + 1}", heap()))
        assert page.evaluate(f"{M}.bvhText()").count("\n") == text.count("\n")  # (still split)
        assert (figures[-1][1] - figures[3][1]) / 2 < PER_EDIT, figures
        assert figures[-1][1] - empty < 1.5 * len(text), figures
        say_figures(figures, len(text), " read whole")
    finally:
        page.context.close()
