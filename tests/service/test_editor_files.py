"""The browser editor and users' BVH files (real Chromium, the real server): a real CMU file
opened (picker and drop), posed, scrubbed and exported; files written back in their own
bytes; an answer read by its frame's line. Shared parts: ``tests/service/editor_page.py``.
``$MARIONETTE_SCREENSHOT_BVH`` names where the file's screenshot goes (default: the test's
temp folder); ``docs/img/editor_bvh.png`` is made that way.
"""

from __future__ import annotations

import json
import os
from math import dist
from pathlib import Path
from typing import Any

import pytest

from core.skeleton import JOINT_NAMES
from tests.service.editor_page import (
    REPO_ROOT,
    WAIT_MS,
    M,
    drag_joint,
    drawn_as_inspected,
    give_file,
    open_editor,
    open_file,
    post_json,
    recorded,
    settle,
    watched_page,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)


@pytest.mark.browser
def test_editor_opens_poses_scrubs_and_exports_a_real_bvh_file(
    server: str, browser: Any, more_mocap: Path, tmp_path: Path
) -> None:
    """A real CMU file (AnimatedDrawings' cmu1, CMU ASF units, 38 joints with End Sites):
    opened with the file picker (units first refused, then stated), and again by dropping
    it; its own bones drawn where the service's FK puts them; a frame posed by dragging the
    left wrist (exact reach by default), undone and redone, another frame shown, the file
    exported: only the edited frame's line differs."""
    from core.bvh import parse_bvh

    path = next(more_mocap.rglob("cmu1/jumping_jacks.bvh"))
    original = path.read_text()
    units = 0.0564444  # CMU ASF units: the file's leg is ~15 of them, not plain
    context, page, console_errors, page_errors, urls, solves = watched_page(
        browser, "/v1/bvh/solve"
    )
    m = "window.marionette"

    def inspect(text: str, frame: int) -> Any:
        body = {"bvh": text, "frame": frame, "units": units}
        return post_json(server + "/v1/bvh/inspect", body)

    def assert_drawn_as_served(text: str, frame: int) -> None:
        want = inspect(text, frame)["positions"]
        got = page.evaluate(f"{m}.bvhPositions()")
        assert len(got) == len(want) == 38
        worst = max(dist(a, b) for a, b in zip(got, want, strict=True))
        assert worst < 1e-6, worst  # the page's FK is the service's

    def drop(text: str, name: str) -> int:
        """Drop ``text`` on the page as the file ``name``; the status of its inspection."""
        with page.expect_response("**/v1/bvh/inspect") as inspected:
            page.evaluate(
                """([text, name]) => {
                  const dt = new DataTransfer();
                  dt.items.add(new File([text], name, { type: 'text/plain' }));
                  document.getElementById('viewport').dispatchEvent(
                    new DragEvent('drop', { dataTransfer: dt, bubbles: true, cancelable: true }));
                }""",
                [text, name],
            )
        status: int = inspected.value.status
        return status

    def scrub(frame: int) -> None:
        page.locator("#bvh-frame").fill(str(frame))
        page.wait_for_function(f"() => {m}.bvh().frame === {frame}")

    try:
        page.goto(server + "/editor")
        page.wait_for_function(f"() => {m} && {m}.ready()")
        page.wait_for_function(
            "() => document.getElementById('status').textContent === 'connected'"
        )
        assert page.evaluate(f"{m}.options()")["reach"] == "exact"  # the default (issue 11)
        assert page.evaluate(f"{m}.bvh()") is None

        # -- the file picker; units 'auto' cannot be inferred for this file: a clear 422 --------
        page.set_input_files("#bvh-file", str(path))
        page.wait_for_function(f"() => {m}.error() !== null")
        err = page.evaluate(f"{m}.error()")
        assert err["status"] == 422, err
        assert "units" in err["detail"] and "in the Units menu" in err["detail"], err
        assert page.evaluate(f"{m}.bvh()") is None
        # stating the units re-opens the file
        page.select_option("#bvh-units", str(units))
        page.wait_for_function(f"() => {m}.bvh() !== null")
        info = page.evaluate(f"{m}.bvh()")
        assert info["name"] == "jumping_jacks.bvh"
        assert info["frames"] == 125
        assert info["scheme"] == "cmu-asf-bvh"
        assert info["units"] == units
        assert info["up"] == "+Y"
        assert info["joints"] == list(parse_bvh(original).joint_names)
        assert page.evaluate(f"{m}.error()") is None
        assert set(page.evaluate(f"{m}.pose()")) == set(JOINT_NAMES)  # the 21 handles
        assert_drawn_as_served(original, 0)
        # standing on the grid, head up, about a person's height (metres in the page)
        world = page.evaluate(f"{m}.bvhWorld()")
        heights = [p[1] for p in world]
        assert abs(min(heights)) < 1e-9
        assert 1.3 < max(heights) < 2.1, max(heights)

        # -- drag and drop opens a file too: its units found anew (the file's before are no
        # guide: inches carried over drew a centimetre file as a giant), so stated again ------
        scrub(10)
        assert drop(original, "dropped.bvh") == 422
        assert page.locator("#bvh-units").input_value() == "auto"
        page.select_option("#bvh-units", str(units))
        page.wait_for_function(f"() => {m}.bvh().name === 'dropped.bvh'")
        assert page.evaluate(f"{m}.bvh().frame") == 0

        # -- scrub to frame 40 and drag the left wrist -------------------------------------
        edited_frame = 40
        scrub(edited_frame)
        assert_drawn_as_served(original, edited_frame)
        world_before = page.evaluate(f"{m}.bvhWorld()")
        pose_before = page.evaluate(f"{m}.pose()")
        before_png = page.locator("#viewport canvas").screenshot()
        wrist = page.evaluate(f"{m}.projectJoint('left_wrist')")
        dx, dy = 50, -110
        page.mouse.move(wrist["x"], wrist["y"])
        page.mouse.down()
        for i in range(1, 13):
            t = i / 12
            page.mouse.move(wrist["x"] + t * dx, wrist["y"] + t * dy)
            page.wait_for_timeout(16)
        page.mouse.up()
        settle(page)

        assert solves, "dragging sent no /v1/bvh/solve"
        assert len(solves) <= 13  # throttled, latest wins
        first = solves[0]
        # every solve starts from the committed file: the header and the frame's line of it,
        # as frame 0 (editor/excerpt.js: the answer's line is spliced back)
        lines = original.split("\n")
        at = lines.index("MOTION") + 3  # the first frame's line
        head = [*lines[: at - 2], "Frames: 1", lines[at - 1]]
        assert first["bvh"] == "\n".join([*head, lines[at + edited_frame]]) + "\n"
        assert first["frame"] == 0
        assert first["units"] == units
        assert [t["joint"] for t in first["targets"]] == ["left_wrist"]
        assert first["options"]["reach"] == "exact"
        last = page.evaluate(f"{m}.lastSolve()")
        assert last["response"]["frame"] == edited_frame
        assert last["request"]["frame"] == edited_frame
        assert last["response"]["targets"][0]["reached"], last["response"]["targets"]
        target = page.evaluate(f"{m}.targets()")["left_wrist"]
        on_screen = page.evaluate(f"{m}.projectPoint({json.dumps(target)})")
        assert abs(on_screen["x"] - (wrist["x"] + dx)) < 2
        assert abs(on_screen["y"] - (wrist["y"] + dy)) < 2
        pose_after = page.evaluate(f"{m}.pose()")
        assert dist(pose_after["left_wrist"], target) < 0.002  # exact: under the cursor
        assert pose_after["left_wrist"][1] > pose_before["left_wrist"][1] + 0.1
        edited = page.evaluate(f"{m}.bvhText()")
        assert edited == last["response"]["bvh"]  # the answer is the file now
        assert_drawn_as_served(edited, edited_frame)
        world_after = page.evaluate(f"{m}.bvhWorld()")
        moved = [dist(a, b) for a, b in zip(world_before, world_after, strict=True)]
        assert max(moved) > 0.1
        assert page.locator("#viewport canvas").screenshot() != before_png
        assert "mm" in page.locator("#targets tbody tr[data-joint=left_wrist]").inner_text()

        shot = Path(os.environ.get("MARIONETTE_SCREENSHOT_BVH", tmp_path / "editor_bvh.png"))
        shot.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(shot))
        assert shot.stat().st_size > 10_000

        # -- undo / redo ---------------------------------------------------------------------
        page.click("#undo")
        assert page.evaluate(f"{m}.bvhText()") == original
        page.click("#redo")
        assert page.evaluate(f"{m}.bvhText()") == edited

        # -- another frame: the file's own, no targets -----------------------------------------
        scrub(80)
        assert page.evaluate(f"{m}.targets()") == {}
        assert_drawn_as_served(edited, 80)

        # -- export: the edited file; only the edited frame's line differs -------------------
        with page.expect_download() as dl:
            page.click("#export")
        assert dl.value.suggested_filename == "dropped-edited.bvh"
        exported = Path(dl.value.path()).read_text()
        assert exported == edited
        a, b = parse_bvh(original), parse_bvh(exported)
        assert a.joints == b.joints and a.frame_time == b.frame_time
        assert b.num_frames == a.num_frames
        old_lines, new_lines = original.split("\n"), exported.split("\n")
        assert len(old_lines) == len(new_lines)
        motion = old_lines.index("MOTION")
        changed = [i for i, (x, y) in enumerate(zip(old_lines, new_lines, strict=True)) if x != y]
        assert changed == [motion + 3 + edited_frame], changed

        # -- the units or up changed with the file open: read again, edits kept; Reset
        # returns to the file as opened (was: the edited text became the original) ------
        page.select_option("#bvh-up", "+Y")  # the file's own: the same figure
        page.wait_for_function(f"() => {m}.history().length === 1")
        assert page.evaluate(f"{m}.bvhText()") == edited
        assert page.evaluate(f"{m}.bvh()")["name"] == "dropped.bvh"
        page.click("#reset")
        assert page.evaluate(f"{m}.bvhText()") == original

        # -- an open refused (units auto), then units stated: THAT file opens (was: the
        # file still shown, under the refused one's name) -----------------------------------
        page.select_option("#bvh-units", "auto")  # re-reads dropped.bvh: refused, still shown
        page.wait_for_function(f"() => {m}.error() !== null")
        assert drop(edited, "other.bvh") == 422
        assert page.evaluate(f"{m}.bvh()")["name"] == "dropped.bvh"
        page.select_option("#bvh-units", str(units))
        page.wait_for_function(f"() => {m}.bvh().name === 'other.bvh'")
        assert page.evaluate(f"{m}.bvhText()") == edited

        assert page_errors == []
        # only the browser's own log line of the refused (422) first open
        unexpected = [e for e in console_errors if not e.startswith("Failed to load resource")]
        assert unexpected == [], unexpected
        assert all(u.startswith((server + "/", "blob:", "data:")) for u in urls), urls
    finally:
        context.close()


@pytest.mark.browser
def test_editor_writes_a_file_back_in_its_own_bytes(server: str, browser: Any) -> None:
    """A BVH with a UTF-8 byte order mark, and one in Latin-1 (an exporter's accented joint
    name), opened and exported unedited: the same bytes. file.text() read Latin-1 as
    U+FFFD, so the export wrote three bytes in place of one and the name was lost; the BOM
    was dropped."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    accented = text.replace("LeftHandIndex1", "LeftHandInd\u00e8x1")
    files = {
        "marked.bvh": b"\xef\xbb\xbf" + text.encode(),
        "latin.bvh": accented.encode("latin-1"),
    }
    context = browser.new_context(accept_downloads=True)
    page = context.new_page()
    page.set_default_timeout(WAIT_MS)
    m = "window.marionette"
    try:
        page.goto(server + "/editor")
        page.wait_for_function(f"() => {m} && {m}.ready()")
        for name, data in files.items():
            page.set_input_files(
                "#bvh-file", files=[{"name": name, "mimeType": "text/plain", "buffer": data}]
            )
            page.wait_for_function(f"() => {m}.bvh() && {m}.bvh().name === '{name}'")
            with page.expect_download() as dl:
                page.click("#export")
            assert Path(dl.value.path()).read_bytes() == data, name
        assert "LeftHandInd\u00e8x1" in page.evaluate(f"{m}.bvh()")["joints"]
    finally:
        context.close()


@pytest.mark.browser
def test_editor_reads_an_answer_by_its_frame_line(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """Each answer of a solve on a file is a new text, and the page read it whole to draw one
    frame: on a 1 MB file (ReActIdle, 918 frames) 12-30 ms of parsing per answer. Now only
    the frame's line is read (the whole file only when it does not hold one frame per line),
    and the frame drawn is the same."""
    path = next(more_mocap.rglob("genuine/003_genuine.bvh"))
    text = path.read_text()
    assert len(text) > 900_000
    lines = text.split("\n")
    body = lines.index("MOTION") + 3
    frames = [ln for ln in lines[body:] if ln.strip()]
    assert len(frames) == 918
    spaced = "\n".join(lines[:body] + [f"{ln}\n  " for ln in frames]) + "\n"
    halves = [ln.split(" ", 30) for ln in frames]  # each frame on two lines
    wrapped = "\n".join(lines[:body] + [" ".join(h[:30]) + "\n" + h[30] for h in halves]) + "\n"
    page = open_editor(browser, server)
    try:
        page.set_input_files("#bvh-file", str(path))
        page.wait_for_function(f"() => {M}.bvh() !== null")
        assert page.evaluate(f"{M}.bvh().frames") == 918
        timing = page.evaluate(
            """async ([spaced, wrapped]) => {
              const file = await import('/static/editor/file.js');
              const bvh = await import('/static/bvh.js');
              const text = window.marionette.bvhText();
              const median = (xs) => xs.sort((a, b) => a - b)[Math.floor(xs.length / 2)];
              const time = (f) => {
                const out = [];
                for (let i = 1; i <= 7; i += 1) {
                  const fresh = text + ' '.repeat(i);  // a new text, as each answer is
                  const t0 = performance.now();
                  f(fresh);
                  out.push(performance.now() - t0);
                }
                return median(out);
              };
              const same = (t, f) =>
                JSON.stringify(file.filePose(t, f)) === JSON.stringify(file.filePose(text, f));
              return {
                pose: time((t) => file.filePose(t, 700)),
                parse: time((t) => bvh.parseMotion(t)),
                spaced: [0, 500, 917].every((f) => same(spaced, f)),
                wrapped: [0, 500, 917].every((f) => same(wrapped, f)),  // read whole
              };
            }""",
            [spaced, wrapped],
        )
        print("a frame of a new 1 MB text:", timing)  # shown with pytest -s
        assert timing["spaced"] and timing["wrapped"], timing
        assert timing["pose"] < 0.3 * timing["parse"], timing

        # a drag: the answer's frame drawn as the service has it
        page.locator("#bvh-frame").fill("700")
        page.wait_for_function(f"() => {M}.bvh().frame === 700")
        drag_joint(page, "left_wrist", 30, -60)
        now = page.evaluate(f"{M}.bvhText()")
        assert now != text
        drawn_as_inspected(page, server, {"bvh": now, "frame": 700})
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_opens_a_file_with_a_joint_map(server: str, browser: Any, more_mocap: Path) -> None:
    """A file whose joint names the automatic map cannot resolve (ReActIdle 003, its left
    arm's joints renamed) was refused, and the page had no place to give a joint map. Now
    the refusal opens a Joint map field holding the unmapped joints to fill in, beside the
    file's joint names; the map given is sent with every inspect and solve of that file
    (its 422s shown), shown and sent again when the file is read or opened again, and
    another file opens without it."""
    path = next(more_mocap.rglob("genuine/003_genuine.bvh"))
    plain = path.read_text()
    text = plain.replace("JOINT upper_arm.L", "JOINT ArmUpper_Lft")
    text = text.replace("JOINT forearm.L", "JOINT ArmLower_Lft")
    assert text.count("ArmUpper_Lft") == text.count("ArmLower_Lft") == 1
    good = {
        "left_shoulder": "ArmUpper_Lft",
        "left_elbow": "ArmLower_Lft",
        "left_wrist": "ArmLower_Lft_end",  # its End Site, as the service names it
    }
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    sent: list[tuple[str, dict[str, Any]]] = []  # (inspect / solve, body)
    page.on(
        "request",
        lambda r: (
            sent.append((r.url.rsplit("/", 1)[-1], json.loads(r.post_data or "{}")))
            if "/v1/bvh/" in r.url
            else None
        ),
    )
    field = page.locator("#bvh-map")

    def apply(value: str) -> None:
        field.fill(value)
        page.click("#bvh-map-apply")

    def error_says(words: str) -> None:
        page.wait_for_function(
            f"() => {M}.error() !== null && {M}.error().detail.includes({json.dumps(words)})"
        )
        assert words in page.locator("#error").inner_text()

    try:
        # refused: the banner names the joints; the field opens with them to fill in
        give_file(page, text, "renamed.bvh")
        error_says("no joint found for ['left_shoulder', 'left_elbow', 'left_wrist']")
        error = page.evaluate(f"{M}.error()")
        assert error["status"] == 422
        assert error["detail"].startswith("renamed.bvh: joint_map: "), error
        assert page.evaluate(f"{M}.bvh()") is None
        assert page.locator("#bvh-map-box").get_attribute("open") is not None
        assert field.is_visible()
        assert json.loads(field.input_value()) == dict.fromkeys(good, "")
        joints = page.locator("#bvh-map-joints").inner_text()
        assert "ArmUpper_Lft" in joints and "ArmLower_Lft_end" in joints

        # not JSON: said, nothing sent; a joint the file lacks: the service's 422 shown
        count = len(sent)
        apply('{"left_shoulder": ')
        error_says("not JSON")
        assert page.evaluate(f"{M}.error()")["title"] == "Joint map"
        assert len(sent) == count
        apply(json.dumps({**good, "left_elbow": "Nope"}))
        error_says("joint_map.left_elbow: the skeleton has no joint 'Nope'")
        assert page.evaluate(f"{M}.error()")["status"] == 422
        assert sent[-1][0] == "inspect"
        assert sent[-1][1]["joint_map"]["left_elbow"] == "Nope"
        assert page.evaluate(f"{M}.bvh()") is None

        # the map: the file opens; a drag edits it, every solve sending the map
        apply(json.dumps(good))
        page.wait_for_function(f"() => {M}.bvh() !== null")
        said = page.evaluate(f"{M}.error()")  # (ReActIdle read the BVH way: the root's banner)
        assert said["title"] == "Root channels", said
        info = page.evaluate(f"{M}.bvh()")
        assert info["name"] == "renamed.bvh" and info["frames"] == 918
        assert info["jointMap"] == good
        assert sent[-1] == ("inspect", {"bvh": text, "frame": 0, "joint_map": good})
        page.locator("#bvh-frame").fill("300")
        page.wait_for_function(f"() => {M}.bvh().frame === 300")
        wrist = page.evaluate(f"{M}.pose()")["left_wrist"]
        drag_joint(page, "left_wrist", 40, -60)
        solves = [body for kind, body in sent if kind == "solve"]
        assert solves
        assert all(body["joint_map"] == good for body in solves)
        edited = page.evaluate(f"{M}.bvhText()")
        assert edited != text
        assert page.evaluate(f"{M}.lastSolve()")["response"]["targets"][0]["reached"]
        pose = page.evaluate(f"{M}.pose()")
        assert dist(pose["left_wrist"], page.evaluate(f"{M}.targets()")["left_wrist"]) < 0.002
        assert dist(pose["left_wrist"], wrist) > 0.05
        body = {"bvh": edited, "frame": 300, "joint_map": good}
        drawn_as_inspected(page, server, body)

        # read again (units stated): the map sent again and still shown; the edit kept
        page.select_option("#bvh-units", "m")
        page.wait_for_function(f"() => {M}.history().length === 1")
        assert sent[-1][0] == "inspect"
        assert sent[-1][1]["joint_map"] == good
        assert json.loads(field.input_value()) == good
        assert page.evaluate(f"{M}.bvhText()") == edited

        # the same file opened again (asked first: it has edits): its map shown and sent
        page.once("dialog", lambda d: d.accept())
        with page.expect_response("**/v1/bvh/inspect"):
            give_file(page, text, "renamed.bvh")
        page.wait_for_function(f"() => {M}.history().length === 1 && !{M}.bvh().edited")
        assert sent[-1][1]["joint_map"] == good
        assert page.evaluate(f"{M}.bvh()")["jointMap"] == good
        assert json.loads(field.input_value()) == good
        assert page.evaluate(f"{M}.error()")["title"] == "Root channels"

        # another file: opened without the map, the field empty, its solves send none
        give_file(page, plain, "plain.bvh")
        page.wait_for_function(f"() => {M}.bvh().name === 'plain.bvh'")
        assert "joint_map" not in sent[-1][1]
        assert field.input_value() == ""
        assert page.evaluate(f"{M}.bvh()")["jointMap"] is None
        drag_joint(page, "left_wrist", 30, -40)
        assert sent[-1][0] == "solve"
        assert "joint_map" not in sent[-1][1]
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_reads_a_root_whose_channels_are_a_displacement(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """ReActIdle's root channels are a displacement from its OFFSET: the Root channels menu
    (``root_position``) reads the open file again so, draws it where the service lays it
    out, sends it with the file's solves, and starts at the BVH way for the next file."""
    path = next(more_mocap.rglob("genuine/003_genuine.bvh"))
    text = path.read_text()
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    sent = recorded(page, lambda url: "/v1/bvh/" in url)
    try:
        open_file(page, text, "idle.bvh")
        assert page.evaluate(f"{M}.bvh()")["root"] == "replace"
        drawn_as_inspected(page, server, {"bvh": text, "frame": 0})
        said = page.evaluate(f"{M}.error()")  # (the service's root_warning, and the menu)
        assert said["title"] == "Root channels" and '"add"' in said["detail"], said
        low = page.evaluate(f"{M}.bvhPositions()")[0][1]
        with page.expect_response("**/v1/bvh/inspect"):
            page.select_option("#bvh-root", "add")
        page.wait_for_function(f"() => {M}.bvh().root === 'add'")
        assert sent[-1]["root_position"] == "add"
        drawn_as_inspected(page, server, {"bvh": text, "frame": 0, "root_position": "add"})
        high = page.evaluate(f"{M}.bvhPositions()")[0][1]
        root_offset = float(text.split("OFFSET", 1)[1].split()[1])  # the root's y, metres
        assert abs((high - low) - root_offset) < 1e-9, (low, high, root_offset)
        drag_joint(page, "left_wrist", 30, -40)
        settle(page)
        solves = [b for b in sent if "targets" in b]
        assert solves and all(b.get("root_position") == "add" for b in solves)
        assert page.evaluate(f"{M}.error()") is None
        # another file starts where BVH does
        page.once("dialog", lambda d: d.accept())  # (the edited file: asked before closing)
        open_file(page, text, "again.bvh")
        assert page.evaluate(f"{M}.bvh()")["root"] == "replace"
        assert page.locator("#bvh-root").input_value() == "replace"
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_scrubs_a_file_cut_short_only_as_far_as_its_text(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """A file cut inside a frame (an interrupted copy) opens saying so; the slider and the
    frame box reach the frame the cut is in, not the declared frames after it, which are
    not in the text (a file cut inside frame 235 of 339 scrubbed to 338, an empty view
    each: a user's audit)."""
    lines = next(more_mocap.rglob("genuine/003_genuine.bvh")).read_text().split("\n")
    first = lines.index("MOTION") + 3  # (MOTION, Frames:, Frame Time:)
    row = lines[first + 300].split()
    text = "\n".join([*lines[: first + 300], " ".join(row[: len(row) // 2])]) + "\n"
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        open_file(page, text, "cut.bvh")
        assert page.evaluate(f"{M}.error()")["title"] == "Broken file"
        assert page.locator("#bvh-frame").get_attribute("max") == "300"
        assert page.locator("#bvh-frame-number").get_attribute("max") == "300"
        box = page.locator("#bvh-frame-number")
        box.fill("301")
        box.press("Enter")
        page.wait_for_function(f"() => {M}.error() && {M}.error().title === 'No such frame'")
        assert "frames 0 to 300" in page.evaluate(f"{M}.error()")["detail"]
        box.fill("299")
        box.press("Enter")
        page.wait_for_function(f"() => {M}.bvh().frame === 299")
        assert page.locator("#bvh-frame-label").inner_text().startswith("/ 300 ")
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_says_when_a_file_s_root_stands_it_up_along_the_other_axis(
    server: str, browser: Any, bvh_files: dict[str, Path]
) -> None:
    """The Z-up child with its first frame turned upright along +Y by its root (a rig
    exported with its root turned a quarter turn): read as the rest pose says (+Z), it
    opens with the service's ``up_warning`` in an "Up axis" banner naming the menu; +Y
    picked there reads it again, upright, with no banner."""
    from tests.service.test_up_warning import turned_frame

    text = turned_frame(bvh_files["fair1-child-inches-zup"].read_text(), 0)
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        give_file(page, text, "turned.bvh")  # (inches, which are not plain from the file)
        page.wait_for_function(f"() => ({M}.error() || {{}}).detail?.includes('units')")
        page.click("#error-close")
        with page.expect_response("**/v1/bvh/inspect"):
            page.select_option("#bvh-units", "in")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'turned.bvh'")
        assert page.evaluate(f"{M}.bvh()")["up"] == "+Z"
        said = page.evaluate(f"{M}.error()")
        assert said["title"] == "Up axis", said
        assert 'give "up": "+Y"' in said["detail"] and "(the Up axis menu)" in said["detail"]
        with page.expect_response("**/v1/bvh/inspect"):
            page.select_option("#bvh-up", "+Y")
        page.wait_for_function(f"() => {M}.bvh().up === '+Y'")
        assert page.evaluate(f"{M}.error()") is None
        drawn_as_inspected(page, server, {"bvh": text, "frame": 0, "units": "in", "up": "+Y"})
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_says_when_a_file_s_sides_are_named_the_other_way(
    server: str, browser: Any, bvh_files: dict[str, Path]
) -> None:
    """A Bandai-Namco walk with every joint named for the other side opens with the
    service's ``sides_warning`` in a "Sides" banner; the file as it is opens without one."""
    from tests.character_files import swapped_file

    text = bvh_files["bandai"].read_text()
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        give_file(page, swapped_file(text), "swapped.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'swapped.bvh'")
        said = page.evaluate(f"{M}.error()")
        assert said["title"] == "Sides", said
        assert "named for the other side" in said["detail"], said
        page.click("#error-close")
        give_file(page, text, "plain.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'plain.bvh'")
        assert page.evaluate(f"{M}.error()") is None
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_says_a_file_whose_body_cannot_move_without_pointing_at_a_menu(
    server: str, browser: Any
) -> None:
    """A root of rotations alone (no position channel at or above the pelvis) cannot move
    its body: the opened file says so (the service's ``root_warning``), and not "the Root
    channels menu", which reads position channels the file has none of (an API audit)."""
    from tests.service.test_bvh_fixed_root import EXAMPLE, SAID, _fixed_root

    page = open_editor(browser, server)
    try:
        open_file(page, _fixed_root(EXAMPLE["bvh"]), "fixed.bvh")
        said = page.evaluate(f"{M}.error()")
        assert said["title"] == "Root channels" and SAID in said["detail"], said
        assert "menu" not in said["detail"], said
    finally:
        page.context.close()
