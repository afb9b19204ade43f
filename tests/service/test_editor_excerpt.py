"""The editor's solves of a file sent as an excerpt (``service/static/editor/excerpt.js``):
the header with ``Frames: 1`` and the frame's line alone, its answer's line spliced back.
The spliced text is byte for byte the whole file's answer (real files, the real server,
the page's own excerpt code), the rest of the answer the same; a file whose excerpt could
differ goes whole; in the page, a drag on a 7.5 MB file sends small requests and leaves the
text the whole file's answer would. Shared parts: ``tests/service/editor_page.py``.
"""

from __future__ import annotations

import json
import urllib.request
from pathlib import Path
from typing import Any

import pytest

from tests.character_files import FILES, big_file
from tests.service.editor_page import (
    M,
    drag_joint,
    open_editor,
    open_file,
    post_json,
    recorded,
    settle,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

EXCERPT = """async ([body, info, data]) => {
  const { excerptOf } = await import('/static/editor/excerpt.js');
  const e = excerptOf(body, info);
  if (!e) return null;
  const spliced = data ? e.splice(data) : null;
  const row = spliced && spliced.row && [...spliced.row];
  return { body: e.body, spliced: spliced && spliced.data, row };
}"""


def excerpt(page: Any, body: dict[str, Any], info: dict[str, Any], data: Any = None) -> Any:
    """The page's excerpt of ``body`` (None: the whole file goes), and ``data`` spliced."""
    return page.evaluate(EXCERPT, [body, info, data])


def frame_line(text: str, frame: int) -> tuple[int, int]:
    """Where frame ``frame``'s line stands in ``text`` (one frame a line)."""
    at = text.index("\n", text.index("\n", text.index("\n", text.index("\nMOTION") + 1) + 1) + 1)
    start = at + 1
    for _ in range(frame):
        start = text.index("\n", start) + 1
    end = text.find("\n", start)
    return start, len(text) if end < 0 else end


def targets_of(points: dict[str, list[float]], joints: list[str], far: float) -> list[Any]:
    """Targets moved from the frame's own points by ``far`` (file units) up and forward."""
    return [
        {"joint": j, "position": [p[0] + far * k / 3, p[1] + far, p[2] - far / 2], "weight": 1}
        for k, j in enumerate(joints, 1)
        for p in [points[j]]
    ]


#: A file longer than this is cut to its first frames (``big_file``): each case posts the
#: whole file 48 times, and ReActIdle's 3.6 MB take (3,500 frames) took 31 s where the two
#: files of ~240 kB took 7 s each.
CUT_BYTES = 300_000

CASES = [  # (joints moved, pins, options)
    (["left_wrist"], [], {"reach": "exact"}),
    (["right_ankle", "head"], ["left_ankle"], {"reach": "soft", "method": "fabrik"}),
    (["pelvis", "left_wrist", "right_wrist"], [], {"preserve_bone_lengths": True}),
]


@pytest.mark.browser
@pytest.mark.parametrize("name", ["bandai", "reactidle-6ch", "fair1-child-inches-zup"])
def test_excerpt_answer_is_the_whole_files(
    server: str, browser: Any, bvh_files: dict[str, Path], name: str
) -> None:
    """For real files (cm with 6-channel joints; inches, +Z up, a child), several frames
    and target sets: the whole file and the page's excerpt POSTed to /v1/bvh/solve; the
    excerpt's answer spliced (by the page, and by this test apart) is the whole file's
    ``bvh`` byte for byte, and every other field of the answer is the same but ``frame``
    (0, the page puts back the real one). Also as CRLF, with a byte order mark, and without
    a final newline (the last frame's line ends the file)."""
    text = bvh_files[name].read_text()
    if len(text) > CUT_BYTES:  # (its first frames, their lines as they are)
        text = big_file(bvh_files[name], CUT_BYTES)
    units = FILES[name][2]
    page = open_editor(browser, server)
    try:
        variants = {
            "as is": text,
            "CRLF": text.replace("\n", "\r\n"),
            "BOM": "\ufeff" + text,
            "no final newline": text.rstrip("\n"),
        }
        edits = 0
        for how, bvh in variants.items():
            ask = {"bvh": bvh, "frame": 0, **({"units": units} if units is not None else {})}
            info = post_json(server + "/v1/bvh/inspect", ask)
            n = info["frames"]
            for frame in sorted({0, FILES[name][3] % n, n // 2, n - 1}):
                points = post_json(server + "/v1/bvh/inspect", {**ask, "frame": frame})["points"]
                far = 0.12 / info["metres_per_unit"]
                for joints, pins, options in CASES:
                    targets = targets_of(points, joints, far)
                    body = {
                        "bvh": bvh, "frame": frame, "units": info["units"], "up": info["up"],
                        "targets": targets, "pins": pins, "options": options,
                    }  # fmt: skip
                    whole = post_json(server + "/v1/bvh/solve", body)
                    got = excerpt(page, body, info)
                    assert got is not None, (name, how, frame)
                    sent = got["body"]
                    assert sent["frame"] == 0 and len(sent["bvh"]) < 50_000
                    part = post_json(server + "/v1/bvh/solve", sent)
                    # the page's splice
                    got = excerpt(page, body, info, part)
                    spliced = got["spliced"]
                    assert spliced["bvh"] == whole["bvh"], (name, how, frame, joints)
                    assert spliced["frame"] == frame
                    # this test's own: the excerpt answer's last line in place of the frame's
                    line = part["bvh"][:-1].rsplit("\n", 1)[1]
                    # (and the frame's values, as the page draws them: that line's)
                    assert got["row"] == [float(v) for v in line.split()]
                    start, end = frame_line(bvh, frame)
                    assert bvh[:start] + line + bvh[end:] == whole["bvh"]
                    assert {**part, "bvh": None, "frame": frame} == {**whole, "bvh": None}
                    edits += bool(whole["changed_joints"])
        assert edits > 0  # (answers that edit the file, not only ones that keep it)
    finally:
        page.context.close()


def wrapped_file(text: str) -> str:
    """``text`` with each frame's line cut in two (its frames not one a line)."""
    head, _, frames = text.partition("Frame Time:")
    time_line, _, rows = frames.partition("\n")
    wrapped = []
    for row in rows.rstrip("\n").split("\n"):
        words = row.split()
        wrapped += [" ".join(words[: len(words) // 2]), " ".join(words[len(words) // 2 :])]
    return f"{head}Frame Time:{time_line}\n" + "\n".join(wrapped) + "\n"


def small_file() -> str:
    from tests.conftest import REPO_ROOT

    text: str = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    return text


@pytest.mark.browser
def test_excerpt_falls_back_to_the_whole_file(server: str, browser: Any) -> None:
    """Where an excerpt could be read otherwise than the whole file, the page sends the
    whole file: frames wrapped over lines, blank lines among or after them, CR alone, a file
    cut short, a frame holding a value the server refuses (its 422 names the line and frame
    of the whole file); the file as it is goes as an excerpt."""
    text = small_file()
    page = open_editor(browser, server)
    try:
        info = post_json(server + "/v1/bvh/inspect", {"bvh": text, "frame": 0})
        body = {"bvh": text, "frame": 1, "units": info["units"], "up": info["up"], "targets": []}
        assert info["frames"] >= 3
        assert excerpt(page, body, info) is not None
        head, _, frames = text.partition("Frame Time:")
        time_line, _, rows = frames.partition("\n")
        lines = rows.rstrip("\n").split("\n")
        start = f"{head}Frame Time:{time_line}\n"
        cut = start + "\n".join(lines[:-1]) + "\n" + " ".join(lines[-1].split()[:5]) + "\n"
        bad = lines.copy()
        bad[1] = " ".join(["1e9", *bad[1].split()[1:]])
        falls_back = {
            "wrapped": wrapped_file(text),
            "blank line among": start + "\n".join([lines[0], "", *lines[1:]]) + "\n",
            "blank line after": start + "\n".join(lines) + "\n\n",
            "CR alone": text.replace("\n", "\r"),
            "mixed CR": text.replace("\n", "\r", 3),
            "cut short": cut,
            "value refused": start + "\n".join(bad) + "\n",
        }
        for how, bvh in falls_back.items():
            got_info = {**info, "cut_short": {"frame": 2}} if how == "cut short" else info
            assert excerpt(page, {**body, "bvh": bvh}, got_info) is None, how
            # (and the cut short file is told by its text alone too)
            assert excerpt(page, {**body, "bvh": bvh}, info) is None, how
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_sends_excerpts_of_a_big_file(
    server: str, browser: Any, bvh_files: dict[str, Path]
) -> None:
    """A 7.5 MB file opened in the editor and dragged at two frames: every solve's request
    is under 50 kB (the whole file's was 7.5 MB), the text after each gesture is what the
    whole file's request (the last excerpt's targets, the text before, the real frame)
    answers, byte for byte, and the last solve says the real frame. A wrapped file's solves
    go whole."""
    text = big_file(bvh_files["bandai"], 7_500_000)
    page = open_editor(browser, server)
    sizes: list[int] = []
    answers: list[int] = []  # (bytes of each solve's answer, as sent: Content-Length)
    whole_sizes: list[tuple[int, int]] = []  # (the whole file's request and answer, bytes)
    bodies: list[dict[str, Any]] = []

    def seen(r: Any) -> None:
        if r.url.endswith("/v1/bvh/solve"):
            sizes.append(len(r.post_data_buffer or b""))
            bodies.append(json.loads(r.post_data or "{}"))

    page.on("request", seen)
    page.on(
        "response",
        lambda r: (
            answers.append(int(r.headers.get("content-length", "0")))
            if r.url.endswith("/v1/bvh/solve")
            else None
        ),
    )
    try:
        open_file(page, text, "big.bvh")
        for frame, joint in [(0, "left_wrist"), (3000, "right_wrist"), (3000, "left_ankle")]:
            if page.evaluate(f"{M}.bvh().frame") != frame:
                page.locator("#bvh-frame").fill(str(frame))
                page.wait_for_function(f"() => {M}.bvh().frame === {frame}")
            before = page.evaluate(f"{M}.bvhText()")
            n = len(bodies)
            drag_joint(page, joint, 30, -40, steps=6)
            settle(page)
            assert len(bodies) > n
            last = bodies[-1]
            assert last["frame"] == 0 and last["bvh"].count("\n") < 400
            asked = json.dumps({**last, "bvh": before, "frame": frame}).encode()
            req = urllib.request.Request(
                server + "/v1/bvh/solve", data=asked, headers={"Content-Type": "application/json"}
            )
            with urllib.request.urlopen(req, timeout=60) as r:
                raw = r.read()
            whole = json.loads(raw)
            whole_sizes.append((len(asked), len(raw)))
            after = page.evaluate(f"{M}.bvhText()")
            assert after == whole["bvh"]  # byte for byte
            assert after != before
            solve = page.evaluate(f"{M}.lastSolve()")
            assert solve["request"]["frame"] == frame
            assert solve["response"]["frame"] == frame
            assert solve["request"]["bvh_chars"] == len(before)
            assert solve["request"]["excerpt_chars"] == len(last["bvh"])
            assert solve["response"]["changed_joints"] == whole["changed_joints"]
        assert max(sizes) < 50_000, sizes
        assert answers and max(answers) < 50_000, answers
        print(f"\nbytes per solve, a {len(text) / 1e6:.2f} MB file, {len(sizes)} solves:")
        print(f"  excerpt: up {min(sizes)}-{max(sizes)}, down {min(answers)}-{max(answers)}")
        ups, downs = zip(*whole_sizes, strict=True)
        print(f"  whole file: up {min(ups)}-{max(ups)}, down {min(downs)}-{max(downs)}")
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_sends_a_wrapped_file_whole(server: str, browser: Any) -> None:
    """A file whose frames are wrapped over two lines each: its solves go whole (the
    excerpt of one line is no frame), as before."""
    text = small_file()
    bvh = wrapped_file(text)
    page = open_editor(browser, server)
    bodies = recorded(page, lambda url: url.endswith("/v1/bvh/solve"))
    try:
        open_file(page, bvh, "wrapped.bvh")
        drag_joint(page, "left_wrist", 30, -40, steps=4)
        assert bodies and all(b["bvh"] == bvh and b["frame"] == 0 for b in bodies)
        solve = page.evaluate(f"{M}.lastSolve()")
        assert "excerpt_chars" not in solve["request"]
        assert page.evaluate(f"{M}.bvhText()") == solve["response"]["bvh"] != bvh
    finally:
        page.context.close()
