"""The editor's undo history holds what the edits changed, not a copy of the file per step
(``service/static/editor/history.js``, ``textdiff.js``): a copy per step of a 7.5 MB file
reached ~200 MB of the page in eight edits, and could reach 1.5 GB in its 200 steps (an
audit, 2026-12-06). Undo rebuilds each step's text from the one shown, byte for byte. And
the "Last solve" panel is the file's or the sample's shown: opening a file showed the
sample's last solve until the file's first edit.

The real server and a real Chromium (``tests/service/editor_page.py``); a real ReActIdle file
(``tests/character_files.py``) made big by repeating its frames. The text diff itself also
runs in Node, on the real file changed as edits and other tools change a file.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
from itertools import pairwise
from pathlib import Path
from typing import Any

import pytest

from tests.character_files import big_file
from tests.conftest import REPO_ROOT
from tests.service.editor_page import M, drag_joint, open_editor, open_file

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

TEXTDIFF_JS = REPO_ROOT / "service" / "static" / "editor" / "textdiff.js"
#: reads JSON [[a, b], ...] on stdin, writes [[a→b == b, b→a == a, its hunks' characters], ...]
RUN = """
const { apply, diff } = await import(process.argv[1]);
let input = '';
for await (const chunk of process.stdin) input += chunk;
console.log(JSON.stringify(JSON.parse(input).map(([a, b]) => {
  const change = diff(a, b);
  if (change === null) return [a === b, a === b, 0];
  const held = change.hunks.reduce((n, h) => n + h.from.length + h.to.length, 0);
  return [apply(a, change, true) === b, apply(b, change, false) === a, held];
})));
"""
#: the SHA-256 of the open file's text, in the page (not 5 MB brought over each time)
DIGEST = f"""async () => {{
  const bytes = new TextEncoder().encode({M}.bvhText());
  const sum = new Uint8Array(await crypto.subtle.digest('SHA-256', bytes));
  return [...sum].map((b) => b.toString(16).padStart(2, '0')).join('');
}}"""
STATS = ("latency", "rtt", "solve-method", "solvers", "bone-error")  # the "Last solve" panel


def changed(a: str, b: str) -> int:
    """The characters of the lines that differ between ``a`` and ``b`` (as many lines),
    both sides: what an undo step of ``a`` becoming ``b`` holds."""
    pairs = list(zip(a.split("\n"), b.split("\n"), strict=True))
    return sum(len(x) + len(y) for x, y in pairs if x != y)


def test_the_text_diff_gives_back_each_text_byte_for_byte(bvh_files: dict[str, Path]) -> None:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is needed to run the editor's module")
    text = bvh_files["reactidle-6ch"].read_text()
    lines = text.split("\n")
    motion = lines.index("MOTION") + 3

    def edit(*at: int) -> str:
        out = list(lines)
        for i in at:
            out[motion + i] = out[motion + i].replace("0", "7", 3) + " 1.5"
        return "\n".join(out)

    one, two = edit(500), edit(0, 10, 11, 3000)
    cases = {
        "one frame's line": (text, one, changed(text, one)),
        # (lines 10 and 11: one hunk, an LF between them on each side)
        "lines apart and side by side (a Reset)": (text, two, changed(text, two) + 2),
        "the last line": (text, edit(len(lines) - motion - 2), None),
        "a line more": (text, text.replace("\n", "\n1 2 3\n", 1), None),
        "a line less, LF ends gone": (text, text[: text.rindex("\n", 0, -1)], None),
        "CRLF": (text.replace("\n", "\r\n"), one.replace("\n", "\r\n"), None),
        "no change": (text, text, 0),
        "from nothing": ("", text, None),
        "Latin-1, a byte order mark": ("\ufeffabdom\xe9n\n1 2\n", "\ufeffabdom\xe9n\n1 3\n", 6),
    }
    done = subprocess.run(
        [node, "--input-type=module", "-e", RUN, TEXTDIFF_JS.as_uri()],
        input=json.dumps([[a, b] for a, b, _ in cases.values()]),
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    for (name, (_, _, held)), result in zip(cases.items(), json.loads(done.stdout), strict=True):
        assert result[:2] == [True, True], name  # a to b, b to a: byte for byte
        if held is not None:
            assert result[2] == held, name  # the lines that differ, no more


@pytest.mark.browser
def test_editor_history_holds_what_the_edits_change(
    server: str, browser: Any, bvh_files: dict[str, Path]
) -> None:
    """A ~5 MB file (4,600 frames) opened over a sample with a solve: the panel says no
    solve yet. Four edits at three frames, a Reset: the history holds the lines they changed
    (and the text shown, once), not 5 MB a step, and the page's JS heap does not grow with
    the edits. Undone to the start: the file byte for byte, shown and exported; redone to
    the end: each edit's text. A sample chosen: no solve yet again."""
    text = big_file(bvh_files["reactidle-6ch"], 5_000_000)
    frames = text.count("\n") - text[: text.index("MOTION")].count("\n") - 3
    page = open_editor(browser, server)
    try:
        panel = lambda: {key: page.locator(f"#{key}").inner_text() for key in STATS}  # noqa: E731
        cdp = page.context.new_cdp_session(page)

        def heap() -> float:
            """The page's JS heap in use after a garbage collection (bytes)."""
            cdp.send("HeapProfiler.collectGarbage")
            used: float = cdp.send("Runtime.getHeapUsage")["usedSize"]
            return used

        blank = dict.fromkeys(STATS, "–")
        assert panel() == blank

        # -- a sample's solve shown; a file opened over it: none yet ----------------------
        drag_joint(page, "left_wrist", 30, -40)
        assert page.evaluate(f"{M}.lastSolve()") is not None
        assert panel()["latency"].endswith(")") and panel()["solvers"] != "–"
        page.once("dialog", lambda d: d.accept())  # (the sample has a target)
        open_file(page, text, "big.bvh")
        assert page.evaluate(f"{M}.bvh().frames") == frames > 4500
        assert page.evaluate(f"{M}.lastSolve()") is None
        assert panel() == blank
        size = page.evaluate(f"{M}.historySize()")
        assert size == {"steps": 1, "chars": 0, "text": len(text)}

        # -- edits: each step holds the line its edit changed -----------------------------
        texts = [text]
        edits = [
            (0, "left_wrist"),
            (2000, "right_ankle"),
            (4500, "right_wrist"),
            (4500, "left_ankle"),
        ]
        for frame, joint in edits:
            if page.evaluate(f"{M}.bvh().frame") != frame:
                page.locator("#bvh-frame").fill(str(frame))
                page.wait_for_function(f"() => {M}.bvh().frame === {frame}")
            drag_joint(page, joint, 25, -30, steps=1)  # (one solve: 5 MB)
            page.wait_for_function(f"() => {M}.history().length === {len(texts) + 1}")
            texts.append(page.evaluate(f"{M}.bvhText()"))
            assert changed(texts[-2], texts[-1]) > 0  # (one frame's line)
            assert page.evaluate(f"{M}.lastSolve().request.frame") == frame
            if len(texts) == 3:  # (the text shown; the last solve's request, the text before)
                after_two = heap()
        # two edits more: the heap as it was (a step held a copy: 5 MB an edit, measured)
        assert heap() - after_two < len(text) / 2
        assert panel()["solvers"] != "–"
        held = sum(changed(a, b) for a, b in pairwise(texts))
        size = page.evaluate(f"{M}.historySize()")
        assert size == {"steps": 5, "chars": held, "text": len(texts[-1])}
        assert held < 10_000  # four lines of ~1 kB, before and after (was 5 MB a step)

        # -- Reset: a step of its own, holding the three lines it gives back ---------------
        page.click("#reset")
        page.wait_for_function(f"() => {M}.history().length === 6 && !{M}.bvh().edited")
        assert page.evaluate(DIGEST) == hashlib.sha256(text.encode()).hexdigest()
        size = page.evaluate(f"{M}.historySize()")
        assert size == {"steps": 6, "chars": held + changed(texts[-1], text), "text": len(text)}

        # -- undo to the start: each step's text rebuilt, the file byte for byte ----------
        sums = [hashlib.sha256(t.encode()).hexdigest() for t in texts]
        for want in reversed(sums):
            page.click("#undo")
            assert page.evaluate(DIGEST) == want
        assert page.evaluate(f"{M}.history().index") == 0
        assert page.locator("#undo").is_disabled()
        assert not page.evaluate(f"{M}.bvh().edited")
        page.locator("#bvh-frame").fill("4500")  # (a scrub: no step, the text as it is)
        page.wait_for_function(f"() => {M}.bvh().frame === 4500")
        with page.expect_download() as dl:
            page.click("#export")
        assert Path(dl.value.path()).read_bytes() == text.encode()

        # -- redo to the end: each edit's text, then the Reset's --------------------------
        for want in [*sums[1:], sums[0]]:
            page.click("#redo")
            assert page.evaluate(DIGEST) == want
        assert page.locator("#redo").is_disabled()
        assert page.evaluate(f"{M}.historySize().chars") == size["chars"]

        # -- a sample chosen: none yet again ----------------------------------------------
        page.click("#undo")  # (the Reset undone: the file has edits, asked about)
        page.once("dialog", lambda d: d.accept())
        page.select_option("#sample", index=1)
        page.wait_for_function(f"() => {M}.bvh() === null")
        assert page.evaluate(f"{M}.lastSolve()") is None
        assert panel() == blank
        assert page.evaluate(f"{M}.historySize()") == {"steps": 1, "chars": 0, "text": 0}
    finally:
        page.context.close()
