"""A gesture's commit reads neither the old text nor the new one whole
(``service/static/editor/excerpt.js`` ``seedLayout``, ``layoutAfter``; ``history.js``
``pushStep``; ``textdiff.js`` ``lineChange``). The answer committed is an excerpt's spliced
into the committed text, and the splice knows what changed (one frame's line): the next
gesture's excerpts take their layout from the old text's, its lines after the frame's moved
by the line's change of length, and the undo step holds that line, where each commit read
the new text whole to work out its layout (``layoutOf``, at the next gesture's first solve:
~10-16 ms on a 7.5 MB file) and compared the two texts from each end (``diff``, 3-4 ms).

The reads are counted by V8 itself (CDP precise coverage, call counts): nothing in the page
is instrumented. The excerpts sent after each commit are checked against this test's own
reading of the text committed, and undo / redo against the texts each commit made, byte
for byte. Node checks ``layoutAfter`` against ``layoutOf`` (the read it replaces) and
``lineChange`` against ``diff`` on a real file's lines changed every way the check on the
line must catch.

``MARIONETTE_COMMIT_FIGURES=1 python -m pytest tests/service/test_editor_commit_reads.py -s
-k figures`` prints a real drag's CPU profile on a 7.5 MB file: per gesture, the commit and
the next gesture's first excerpt; per answer, ``post`` (solve.js) split (docs/editor.md).
"""

from __future__ import annotations

import collections
import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

from tests.character_files import big_file
from tests.conftest import REPO_ROOT
from tests.service.editor_page import M, drag_joint, open_editor, open_file, recorded, settle

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

EXCERPT_JS = REPO_ROOT / "service" / "static" / "editor" / "excerpt.js"
TEXTDIFF_JS = REPO_ROOT / "service" / "static" / "editor" / "textdiff.js"


def read_counter(page: Any) -> Any:
    """A function giving the calls, since it was last called, of the functions that read a
    whole text at a commit: excerpt.js ``layoutOf`` and textdiff.js ``diff`` (V8's precise
    coverage, with call counts)."""
    cdp = page.context.new_cdp_session(page)
    cdp.send("Profiler.enable")
    cdp.send("Profiler.startPreciseCoverage", {"callCount": True, "detailed": False})
    wanted = {"/static/editor/excerpt.js": "layoutOf", "/static/editor/textdiff.js": "diff"}

    def reads() -> dict[str, int]:
        taken = cdp.send("Profiler.takePreciseCoverage")["result"]  # (the counts start again)
        out = dict.fromkeys(wanted.values(), 0)
        for script in taken:
            name = next((n for url, n in wanted.items() if script["url"].endswith(url)), None)
            for f in script["functions"] if name else ():
                if f["functionName"] == name:
                    out[name] += f["ranges"][0]["count"]
        return out

    reads()
    return reads


def frame_lines(text: str) -> list[str]:
    """The frame lines of a file holding one frame a line (after MOTION, Frames, Frame Time)."""
    motion = text.split("\n").index("MOTION")
    return text.split("\n")[motion + 3 :]


def scrub(page: Any, frame: int) -> None:
    page.locator("#bvh-frame").fill(str(frame))
    page.wait_for_function(f"() => {M}.bvh().frame === {frame}")


@pytest.mark.browser
def test_a_commit_reads_no_text_whole(
    server: str, browser: Any, bvh_files: dict[str, Path]
) -> None:
    """A 1 MB file edited at frames 100, 600, 100, 50 (a drag each): after the first, no
    gesture works out its layout by reading the text, and no commit diffs the texts (the
    page before: one of each a gesture); each gesture's excerpt is the line this test reads
    at its frame of the text committed; undo and redo give back each commit's text, byte for
    byte, the export too."""
    text = big_file(bvh_files["bandai"], 1_000_000)
    page = open_editor(browser, server)
    try:
        solves = recorded(page, lambda url: url.endswith("/v1/bvh/solve"))
        open_file(page, text, "commits.bvh")
        reads = read_counter(page)
        texts = [page.evaluate(f"{M}.bvhText()")]
        lengths = set()
        for k, (frame, joint) in enumerate(
            [(100, "left_wrist"), (600, "right_wrist"), (100, "left_ankle"), (50, "head")]
        ):
            scrub(page, frame)
            reads()  # (a scrub reads its frame by walking the text: not a commit's read)
            del solves[:]
            drag_joint(page, joint, 24, -30, steps=5)
            assert page.evaluate(f"{M}.history().index") == k + 1
            got = reads()
            if k > 0:  # (the file's first excerpt works its layout out: no splice made it)
                assert got == {"layoutOf": 0, "diff": 0}, f"gesture {k}: {got}"
            committed = page.evaluate(f"{M}.bvhText()")
            lines = frame_lines(texts[-1])
            for body in solves:  # every solve of the gesture: the committed text's frame line
                assert body["frame"] == 0 and "MOTION" in body["bvh"]
                assert body["bvh"].split("\n")[-2] == lines[frame], f"gesture {k}"
            before, after = lines[frame], frame_lines(committed)[frame]
            assert frame_lines(committed)[:frame] == lines[:frame]
            assert frame_lines(committed)[frame + 1 :] == lines[frame + 1 :]
            lengths.add(len(after) - len(before))
            texts.append(committed)
        assert lengths != {0}  # (the lines after an edit moved: a layout shifted was used)

        for k in range(len(texts) - 2, -1, -1):  # undone to the file as opened
            page.keyboard.press("Control+z")
            page.wait_for_function(f"() => {M}.history().index === {k}")
            assert page.evaluate(f"{M}.bvhText()") == texts[k], f"undo to {k}"
        for k in range(1, len(texts)):
            page.keyboard.press("Control+Shift+z")
            page.wait_for_function(f"() => {M}.history().index === {k}")
            assert page.evaluate(f"{M}.bvhText()") == texts[k], f"redo to {k}"
        with page.expect_download() as info:
            page.locator("#export").click()
        assert Path(info.value.path()).read_text() == texts[-1]
        # an edit after an undo: its commit is known too (the text the undo rebuilt)
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => {M}.history().index === {len(texts) - 2}")
        scrub(page, 600)
        drag_joint(page, "left_wrist", 20, 20, steps=4)
        assert reads()["diff"] == 0
        assert page.evaluate(f"{M}.history().index") == len(texts) - 1
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => {M}.history().index === {len(texts) - 2}")
        assert page.evaluate(f"{M}.bvhText()") == texts[-2]
    finally:
        page.context.close()


#: reads JSON {"text", "channels", "cases": [[frame, new line], ...]} on stdin; writes, for
#: each case: [the new text's layout worked out by reading it (``layoutOf``), the same from
#: the splice (``layoutAfter``), the new text the splice made, the change ``diff`` finds ==
#: ``lineChange``'s (each applied both ways: byte for byte)]
RUN = """
const { excerptOf, layoutAfter, readLayout } = await import(process.argv[1]);
const { apply, diff, lineChange } = await import(process.argv[2]);
let input = '';
for await (const chunk of process.stdin) input += chunk;
const { text, channels, frames, cases } = JSON.parse(input);
const info = { frames, joints: [{ channels: Array(channels).fill('Xrotation') }] };
console.log(JSON.stringify(cases.map(([frame, line]) => {
  const e = excerptOf({ bvh: text, frame }, info);
  if (!e) return null;
  const head = e.body.bvh.slice(0, e.body.bvh.lastIndexOf('\\n', e.body.bvh.length - 2) + 1);
  const s = e.splice({ bvh: `${head}${line}\\n` });
  const ed = s.edit;
  const change = lineChange(ed.start, ed.fromLength - ed.end, ed.before, ed.after);
  const both = (c) => c === null
    || (apply(text, c, true) === ed.to && apply(ed.to, c, false) === text);
  return [
    readLayout(ed.to, frames, channels), layoutAfter(ed), ed.to,
    JSON.stringify(change) === JSON.stringify(diff(text, ed.to)) && both(change),
  ];
})));
"""


def layout_cases(text: str) -> tuple[int, list[tuple[int, str]]]:
    """Lines written into frames of ``text`` (its channels, and [frame, line] each): longer,
    shorter, as long, the same, at the first and last frame; and each that ``layoutAfter``
    must refuse (``layoutOf`` finds no layout, or another, once it is written)."""
    lines = frame_lines(text)
    words = lines[0].split()
    last = len([line for line in lines if line.strip()]) - 1
    longer = " ".join(w + "1" for w in words)
    return len(words), [
        (0, longer),
        (3, " ".join(words[:-1]) + " 7"),
        (last, " ".join(words[:-1])),  # (the last line short of values: cut short)
        (last, longer),
        (5, lines[5]),  # (the same line: no change)
        (5, lines[5].replace(" ", "  ", 2)),
        (7, longer + "\r"),  # (a CR before the LF: CRLF on that line)
        (7, "1\r2 " + longer),  # (a CR alone)
        (8, longer.replace("1", "\u00e9", 1)),  # (not ASCII)
        (9, "   "),  # (a blank line among the frames)
        (0, "\t"),
        (10, "\f" + longer),  # (a form feed: not printable ASCII)
    ]


@pytest.mark.parametrize("ends", ["LF", "CRLF", "no LF at the end"])
def test_a_layout_from_the_splice_is_the_one_read(bvh_files: dict[str, Path], ends: str) -> None:
    """``layoutAfter`` (the layout of a spliced text, from its text before's) is exactly
    ``layoutOf`` (the new text read), or null where the line written could change what that
    finds; ``lineChange`` is the change ``diff`` finds, giving back each text. A real
    file's lines, LF, CRLF and without its last LF."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is needed to run the editor's module")
    text = big_file(bvh_files["bandai"], 60_000)
    if ends == "CRLF":
        text = text.replace("\n", "\r\n")
    elif ends == "no LF at the end":
        text = text[:-1]
    channels, cases = layout_cases(text.replace("\r\n", "\n"))
    if ends == "CRLF":  # (the CR stays the line's: the splice writes it back)
        cases = [(f, line if line.endswith("\r") else line + "\r") for f, line in cases]
    frames = len(frame_lines(text.replace("\r\n", "\n"))) - (ends != "no LF at the end")
    done = subprocess.run(
        [node, "--input-type=module", "-e", RUN, EXCERPT_JS.as_uri(), TEXTDIFF_JS.as_uri()],
        input=json.dumps({"text": text, "channels": channels, "frames": frames, "cases": cases}),
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    seeded = 0
    for (frame, line), result in zip(cases, json.loads(done.stdout), strict=True):
        assert result is not None, (frame, line)  # (the text as it is: an excerpt)
        read, after, new, change = result
        start = text.index("\n", text.index("Frame Time:")) + 1
        rows = text[start:].split("\n")
        rows[frame] = line
        assert new == text[:start] + "\n".join(rows), (frame, line)  # (the splice's text)
        assert change, (frame, line)
        if after is not None:
            assert after == read, (frame, line)
            seeded += 1
    assert seeded >= 5  # (the usual lines: longer, shorter, as long, the same, the first)


# -- the figures (opt-in) -------------------------------------------------------------------

#: per gesture: the commit (``pushHistory``: its compare and diff), the next gesture's first
#: excerpt (``excerptOf``: its layout, its line), and the two reads; per answer of a long
#: drag: ``post`` (solve.js: the excerpt, the request, its answer spliced) and under it
GESTURE = ("pushHistory", "excerptOf", "layoutOf", "diff")
ANSWER = ("sendSolve", "post", "api", "fetch", "excerptOf", "splice", "lineValues")


@pytest.mark.browser
@pytest.mark.skipif(
    not os.environ.get("MARIONETTE_COMMIT_FIGURES"),
    reason="figures: MARIONETTE_COMMIT_FIGURES=1",
)
def test_commit_figures(server: str, browser: Any, bvh_files: dict[str, Path]) -> None:
    """A 7.5 MB file, its middle frame, V8's CPU profile: 3 runs of 6 gestures (a drag of 6
    moves each, let go once answered), ms of CPU a gesture in (and under) each of
    ``GESTURE``; 3 drags of 40 moves, ms an answer in (and under) each of ``ANSWER``."""
    text = big_file(bvh_files["bandai"], 7_500_000)
    page = open_editor(browser, server)
    try:
        open_file(page, text, "figures.bvh")
        frames = page.evaluate(f"{M}.bvh().frames")
        scrub(page, frames // 2)
        drag_joint(page, "left_wrist", 10, -10, steps=3)  # (the JIT warmed, the layout read)
        for run in range(3):
            answers, spent = profiled(page, [6] * 6)
            print(f"\nrun {run}, 6 gestures ({answers} answers), ms a gesture: "
                  + ", ".join(f"{k} {spent[k] / 6:.2f}" for k in GESTURE))  # fmt: skip
        for run in range(3):
            each = page.evaluate(LATER_EXCERPTS, 500)
            print(f"run {run}, a gesture's later excerpts (the text and frame of its first): "
                  f"{each * 1000:.1f} us each")  # fmt: skip
        for run in range(3):
            answers, spent = profiled(page, [40])
            print(f"run {run}, a drag of {answers} answers, ms an answer: "
                  + ", ".join(f"{k} {spent[k] / answers:.3f}" for k in ANSWER))  # fmt: skip
    finally:
        page.context.close()


#: the ms each of ``reps`` excerpts of the committed text at its frame takes, as a gesture's
#: solves after its first make them (the same text, the same frame)
LATER_EXCERPTS = """async (reps) => {
  const { doc } = await import('/static/editor/state.js');
  const { excerptOf } = await import('/static/editor/excerpt.js');
  excerptOf({ bvh: doc.text, frame: doc.frame }, doc.info);
  const t0 = performance.now();
  for (let i = 0; i < reps; i += 1) excerptOf({ bvh: doc.text, frame: doc.frame }, doc.info);
  return (performance.now() - t0) / reps;
}"""


def profiled(page: Any, moves: list[int]) -> tuple[int, dict[str, float]]:
    """Drags of the left wrist (``moves[k]`` moves the k-th, each let go once answered)
    under V8's CPU profiler: the answers, and the ms of CPU spent in (and under) each
    function of the figures."""
    cdp = page.context.new_cdp_session(page)
    cdp.send("Profiler.enable")
    cdp.send("Profiler.setSamplingInterval", {"interval": 50})  # (µs)
    n = int(page.evaluate(f"{M}.solveCount().answered"))
    cdp.send("Profiler.start")
    for k, count in enumerate(moves):
        xy = page.evaluate(f"{M}.projectJoint('left_wrist')")
        page.mouse.move(xy["x"], xy["y"])
        page.mouse.down()
        for i in range(1, count + 1):
            page.mouse.move(xy["x"] + i * (1 if k % 2 else -1) / 2, xy["y"] - i / 2)
            page.wait_for_timeout(30)
        settle(page)
        page.mouse.up()
        settle(page)
    profile = cdp.send("Profiler.stop")["profile"]
    cdp.detach()
    nodes = {node["id"]: node for node in profile["nodes"]}
    parent = {c: node["id"] for node in profile["nodes"] for c in node.get("children", [])}
    names = set(GESTURE + ANSWER)
    spent: dict[str, float] = collections.defaultdict(float)
    for sample, dt in zip(profile["samples"], profile["timeDeltas"], strict=True):
        seen, at = set(), sample
        while at is not None:
            seen.add(nodes[at]["callFrame"]["functionName"])
            at = parent.get(at)
        for name in seen & names:
            spent[name] += dt / 1000
    return int(page.evaluate(f"{M}.solveCount().answered")) - n, spent
