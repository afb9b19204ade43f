"""The editor draws a file solve's answer without walking its text
(``service/static/editor/excerpt.js``, ``file.js`` frameRow): an excerpt's answer is spliced
into the whole text, and the splice, which wrote the frame's new line, gives the frame's
values with it; ``bvh.js`` ``frameValues`` (the walk over every line of the text to the
frame's) ran once per answer, with a lookup hashing the whole text and a comparison copying
it (0.8-49 ms an answer on 1-7.5 MB files, 0.08 ms now: the figures below). Where no
splice knows the row (an undo's text; a file sent whole: its answer is the server's text)
the page walks as before.

The walks are counted by V8 itself (CDP precise coverage, call counts): nothing in the page
is instrumented. The drawn frame is checked against the service's own reading of the
text shown (``/v1/bvh/inspect``), so a row taken from the splice that were not the text's
would fail.

``MARIONETTE_ROW_FIGURES=1 python -m pytest tests/service/test_editor_frame_rows.py -s -k
figures`` prints the time an answer's frame takes to be read, walked and from the splice
(docs/editor.md, "A file's solve sends one frame").
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import pytest

from tests.character_files import big_file
from tests.service.editor_page import (
    M,
    drag_joint,
    drawn_as_inspected,
    open_editor,
    open_file,
    settle,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)


def walk_counter(page: Any) -> Any:
    """A function giving the calls of bvh.js ``frameValues`` (the walk over a text) since it
    was last called (V8's precise coverage, with call counts)."""
    cdp = page.context.new_cdp_session(page)
    cdp.send("Profiler.enable")
    cdp.send("Profiler.startPreciseCoverage", {"callCount": True, "detailed": False})

    def walks() -> int:
        taken = cdp.send("Profiler.takePreciseCoverage")["result"]  # (the counts start again)
        return sum(
            f["ranges"][0]["count"]
            for script in taken
            if script["url"].endswith("/static/bvh.js")
            for f in script["functions"]
            if f["functionName"] == "frameValues"
        )

    walks()
    return walks


def answered(page: Any) -> int:
    return int(page.evaluate(f"{M}.solveCount().answered"))


def drawn_as_served(page: Any, server: str) -> None:
    """The frame drawn is the service's reading of the text shown, at the frame shown."""
    bvh = page.evaluate(f"{M}.bvh()")
    body = {"bvh": page.evaluate(f"{M}.bvhText()"), "frame": bvh["frame"]}
    drawn_as_inspected(page, server, {**body, "units": bvh["units"], "up": bvh["up"]})


@pytest.mark.browser
def test_editor_draws_an_answer_without_walking_its_text(
    server: str, browser: Any, bvh_files: dict[str, Path]
) -> None:
    """A 1 MB file dragged at two frames: every answer spliced from an excerpt, none walked
    (today's page walked each), the frame drawn as the service reads the text; an undo
    (a text no splice made) walks, as before. The same file with a blank line after its
    frames goes whole: its answers walked, drawn as the service reads them."""
    text = big_file(bvh_files["bandai"], 1_000_000)
    page = open_editor(browser, server)
    try:
        open_file(page, text, "rows.bvh")
        walks = walk_counter(page)
        for frame, joint in [(0, "left_wrist"), (700, "right_ankle")]:
            if page.evaluate(f"{M}.bvh().frame") != frame:
                page.locator("#bvh-frame").fill(str(frame))
                page.wait_for_function(f"() => {M}.bvh().frame === {frame}")
            walks()  # (the scrub's own reading of the frame: not an answer)
            n = answered(page)
            drag_joint(page, joint, 30, -40, steps=6)
            assert answered(page) > n
            assert "excerpt_chars" in page.evaluate(f"{M}.lastSolve()")["request"]
            assert walks() == 0, "an answer's frame was read by walking its text"
            assert page.evaluate(f"{M}.bvhText()") != text
            drawn_as_served(page, server)
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => {M}.history().index === 1")
        assert walks() >= 1  # (the text an undo rebuilt: no splice knows its row)
        drawn_as_served(page, server)

        page.once("dialog", lambda d: d.accept())  # (the edits dropped: asked first)
        open_file(page, text + "\n", "whole.bvh")  # (a blank line after: sent whole)
        walks()
        n = answered(page)
        drag_joint(page, "left_wrist", 30, -40, steps=6)
        assert "excerpt_chars" not in page.evaluate(f"{M}.lastSolve()")["request"]
        assert answered(page) > n
        assert walks() > 0  # (an answer the same text as the one before is not read again)
        drawn_as_served(page, server)
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_scrubs_a_file_without_walking_its_text(
    server: str, browser: Any, bvh_files: dict[str, Path]
) -> None:
    """Frames scrubbed on a 1 MB file are read from their lines by the text's layout
    (``excerpt.js`` committedRow: worked out once per text), not by walking the text to
    each (``frameValues``: once a frame before); each drawn as the service reads it."""
    text = big_file(bvh_files["bandai"], 1_000_000)
    page = open_editor(browser, server)
    try:
        open_file(page, text, "scrub.bvh")
        walks = walk_counter(page)
        for frame in (5, 400, 700, 0):
            page.locator("#bvh-frame").fill(str(frame))
            page.wait_for_function(f"() => {M}.bvh().frame === {frame}")
            assert walks() == 0, f"frame {frame} was read by walking the text"
            drawn_as_served(page, server)
    finally:
        page.context.close()


# The time an answer's frame takes to be drawn in the page, as sendSolve and the frame loop
# do it: the excerpt's answer spliced into the whole text, made the text shown, its frame's
# handles (file.js filePose, with the splice's row: ``spliced``; without it, the page's
# fallback: ``walked``) and the file's own bones drawn (scene.js drawPose). Each answer a new
# text as long as the one before (its first value another 4 digits), as a drag's are; ms an
# answer, each figure the mean of a batch of ``reps`` answers (the page's clock counts in
# 0.1 ms), ``batches`` of each. (A page before the splice gave the row: both are its one
# path.)
FIGURES = """async ([frame, reps, batches]) => {
  const { doc } = await import('/static/editor/state.js');
  const { excerptOf } = await import('/static/editor/excerpt.js');
  const { filePose } = await import('/static/editor/file.js');
  const { drawPose } = await import('/static/editor/scene.js');
  const e = excerptOf({ bvh: doc.text, frame }, doc.info);
  const head = e.body.bvh.slice(0, e.body.bvh.lastIndexOf('\\n', e.body.bvh.length - 2) + 1);
  const words = e.body.bvh.slice(head.length, -1).split(' ');
  const line = (k) => [String(1000 + (k % 9000)), ...words.slice(1)].join(' ');
  const answer = (k) => ({ bvh: `${head}${line(k)}\\n` });
  const times = { walked: [], spliced: [] };
  let k = 0;
  const was = doc.frame;
  doc.frame = frame;
  for (let b = 0; b < batches; b += 1) {
    for (const how of ['walked', 'spliced']) {
      const t0 = performance.now();
      for (let i = 0; i < reps; i += 1) {
        const s = e.splice(answer((k += 1)));
        doc.shown = (s.data || s).bvh;
        filePose(doc.shown, frame, how === 'spliced' ? s.row : null);
        drawPose();
      }
      times[how].push((performance.now() - t0) / reps);
    }
  }
  doc.shown = doc.text;
  doc.frame = was;
  drawPose();
  return times;
}"""


@pytest.mark.browser
@pytest.mark.skipif(
    not os.environ.get("MARIONETTE_ROW_FIGURES"), reason="figures: MARIONETTE_ROW_FIGURES=1"
)
def test_answer_row_figures(server: str, browser: Any, bvh_files: dict[str, Path]) -> None:
    """The figures (median and range, ms per answer) for 1, 2.5 and 7.5 MB files; then a
    real drag's (the 7.5 MB file, its middle frame), from V8's CPU profile."""
    page = open_editor(browser, server)
    try:
        for size in (1_000_000, 2_500_000, 7_500_000):
            text = big_file(bvh_files["bandai"], size)
            open_file(page, text, f"figures{size}.bvh")
            frames = page.evaluate(f"{M}.bvh().frames")
            print(f"\na {len(text) / 1e6:.2f} MB file ({frames} frames), ms an answer:")
            for frame in (0, frames // 2, frames - 1):
                times = page.evaluate(FIGURES, [frame, 20, 8])
                for how, t in times.items():
                    t = sorted(t[1:])  # (the first batch: the JIT warming up)
                    print(f"  frame {frame:>5} {how:>8}: median {t[len(t) // 2]:.3f}, "
                          f"{t[0]:.3f}-{t[-1]:.3f}")  # fmt: skip
        page.locator("#bvh-frame").fill(str(frames // 2))
        page.wait_for_function(f"() => {M}.bvh().frame === {frames // 2}")
        for _ in range(2):
            answers, spent = profiled_drag(page)
            print(f"a drag of {answers} answers at frame {frames // 2}, ms an answer (CPU): "
                  + ", ".join(f"{k} {v / answers:.2f}" for k, v in spent.items()))  # fmt: skip
    finally:
        page.context.close()


#: the functions a real drag's profile is summed over: an answer's handling (solve.js, with
#: its request), its frame's row (file.js), the drawing (scene.js)
PROFILED = ("sendSolve", "frameRow", "drawPose")


def profiled_drag(page: Any) -> tuple[int, dict[str, float]]:
    """A drag of the left wrist (24 moves, the button held while its answers come), V8's CPU
    profile taken meanwhile: the answers, and the ms of CPU spent in (and under) each of
    ``PROFILED``."""
    cdp = page.context.new_cdp_session(page)
    cdp.send("Profiler.enable")
    cdp.send("Profiler.setSamplingInterval", {"interval": 50})  # (µs)
    n = answered(page)
    cdp.send("Profiler.start")
    xy = page.evaluate(f"{M}.projectJoint('left_wrist')")
    page.mouse.move(xy["x"], xy["y"])
    page.mouse.down()
    for i in range(1, 25):
        page.mouse.move(xy["x"] + i, xy["y"] - i)
        page.wait_for_timeout(30)
    settle(page)
    profile = cdp.send("Profiler.stop")["profile"]
    page.mouse.up()
    settle(page)
    nodes = {node["id"]: node for node in profile["nodes"]}
    parent = {c: node["id"] for node in profile["nodes"] for c in node.get("children", [])}
    spent = dict.fromkeys(PROFILED, 0.0)
    for sample, dt in zip(profile["samples"], profile["timeDeltas"], strict=True):
        names, at = set(), sample
        while at is not None:
            names.add(nodes[at]["callFrame"]["functionName"])
            at = parent.get(at)
        for name in names & set(PROFILED):
            spent[name] += dt / 1000
    return answered(page) - n, spent
