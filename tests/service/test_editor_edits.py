"""The browser editor editing a file (real Chromium, the real server): undo and redo
across scrubs, and the screen, the file and the history kept in step through failed solves,
early undos, scrubs, exports, units changes and other files opened while a drag's last
answer is on its way. Shared parts: ``tests/service/editor_page.py``."""

from __future__ import annotations

import json
import re
from math import dist
from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import (
    REPO_ROOT,
    M,
    drag_joint,
    drawn_as_inspected,
    give_file,
    held_drag,
    open_editor,
    recorded,
    release,
    settle,
)

pytest_plugins = ("tests.service.editor_page",)  # fixtures: server (a session), browser


@pytest.mark.browser
def test_editor_undo_after_scrubbing_returns_to_the_state_before(server: str, browser: Any) -> None:
    """Scrubbing rewrote the current undo step with the frame scrubbed to (and no targets):
    after an edit at frame 1 was undone, a scrub to frame 0 and a redo, undo showed frame 0
    (the scrubbed frame) instead of frame 1 before the edit, and a redo after a scrub lost
    the edit's frame and target. Now scrubbing changes no step: undo and redo show the frame
    of the edit they undo or redo (with its targets)."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    page = open_editor(browser, server)

    def scrub(frame: int) -> None:
        page.locator("#bvh-frame").fill(str(frame))
        page.wait_for_function(f"() => {M}.bvh().frame === {frame}")

    def shown() -> tuple[bool, int, list[str]]:
        """(the original text?, frame, targets), and the frame drawn is the text's."""
        now = page.evaluate(f"{M}.bvhText()")
        frame = page.evaluate(f"{M}.bvh().frame")
        drawn_as_inspected(page, server, {"bvh": now, "frame": frame})
        return now == text, frame, sorted(page.evaluate(f"{M}.targets()"))

    try:
        page.set_input_files(
            "#bvh-file",
            files=[{"name": "three.bvh", "mimeType": "text/plain", "buffer": text.encode()}],
        )
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'three.bvh'")
        scrub(1)
        drag_joint(page, "left_wrist", 40, -60)
        edited = page.evaluate(f"{M}.bvhText()")
        assert edited != text
        assert page.evaluate(f"{M}.history()") == {"length": 2, "index": 1}
        assert shown() == (False, 1, ["left_wrist"])

        scrub(2)  # not an undo step
        assert page.evaluate(f"{M}.history()") == {"length": 2, "index": 1}
        assert shown() == (False, 2, [])
        page.click("#undo")  # the state before the edit: the file as opened, frame 1
        assert shown() == (True, 1, [])
        scrub(0)
        page.click("#redo")  # the edit, at its frame, with its target
        assert shown() == (False, 1, ["left_wrist"])
        assert page.evaluate(f"{M}.bvhText()") == edited
        page.click("#undo")  # was: frame 0, the frame scrubbed to
        assert shown() == (True, 1, [])
        page.click("#redo")

        # an edit after a scrub: undoing it shows its frame, the step before it the first
        # edit's frame
        scrub(2)
        drag_joint(page, "right_wrist", -40, -60)
        assert page.evaluate(f"{M}.history()") == {"length": 3, "index": 2}
        assert shown() == (False, 2, ["right_wrist"])
        page.click("#undo")
        assert page.evaluate(f"{M}.bvhText()") == edited
        assert shown() == (False, 2, [])
        page.click("#undo")
        assert shown() == (True, 1, [])
        page.click("#redo")
        page.click("#redo")
        assert shown() == (False, 2, ["right_wrist"])
        # a scrub, then an option changed with no targets: still no step of its own
        scrub(0)
        page.get_by_label("Preserve bone lengths").click()
        settle(page)
        assert page.evaluate(f"{M}.history()") == {"length": 3, "index": 2}
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_keeps_screen_file_and_history_in_step(server: str, browser: Any) -> None:
    """Found by a browser audit (2026-12-05): a drag whose last solve failed left a
    mid-drag answer on screen while Export wrote the file unedited; picking a sample threw
    an edited file's work away unasked; a units change re-opened a closed file; re-reading
    the open file jumped to frame 0; a file whose lines end in CR alone broke the page;
    Ctrl+Z before a drag's last answer undid the edit before it too."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))

    def open_file(body: str, name: str) -> None:
        give_file(page, body, name)
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === '{name}'")

    def shown_is_committed() -> bool:
        got, want = page.evaluate(f"{M}.pose()"), page.evaluate(f"{M}.committedPose()")
        return all(dist(got[j], want[j]) < 1e-9 for j in want)

    try:
        # a file whose lines end in CR alone opens, is drawn as served, and can be edited
        open_file(text.replace("\n", "\r"), "cr.bvh")
        assert page.evaluate(f"{M}.bvhText()") == text  # read as LF, as the service reads it
        drag_joint(page, "left_wrist", 40, -60)
        assert page.evaluate(f"{M}.bvh()")["edited"]

        # the drag's answers arrive, its last solve fails: the screen shows the pose as it was
        before = page.evaluate(f"{M}.bvhText()")
        xy = page.evaluate(f"{M}.projectJoint('right_wrist')")
        page.mouse.move(xy["x"], xy["y"])
        page.mouse.down()
        page.mouse.move(xy["x"] - 40, xy["y"] - 60, steps=6)
        settle(page)
        assert not shown_is_committed()  # a mid-drag answer on screen
        gone = re.compile(r".*/(v1/bvh/solve|v2/health/live)$")  # (no recovery before read)
        page.route(gone, lambda route: route.abort())
        page.mouse.up()
        page.wait_for_function(f"() => {M}.error() !== null")
        settle(page)
        assert page.evaluate(f"{M}.error()")["status"] == 0
        assert shown_is_committed() and page.evaluate(f"{M}.bvhText()") == before
        assert page.locator("#status").inner_text() == "server unreachable"
        page.unroute(gone)

        # Ctrl+Z while a drag's answer is on its way drops that drag alone
        steps = page.evaluate(f"{M}.history()")
        held = held_drag(page, "head", 30, -30)
        page.keyboard.press("Control+z")
        for route in held:
            route.continue_()
        page.unroute("**/v1/bvh/solve")
        settle(page)
        assert page.evaluate(f"{M}.history()") == steps
        assert page.evaluate(f"{M}.bvhText()") == before and shown_is_committed()

        # re-read with other units: the frame shown stays
        page.locator("#bvh-frame").fill("2")
        page.wait_for_function(f"() => {M}.bvh().frame === 2")
        page.select_option("#bvh-units", "cm")
        page.wait_for_function(f"() => {M}.bvh().units === 'cm'")
        assert page.evaluate(f"{M}.bvh()")["frame"] == 2

        # a sample while the file is edited: asked first; "no" keeps the file, "yes" closes
        page.once("dialog", lambda d: d.dismiss())
        page.select_option("#sample", index=1)
        assert page.evaluate(f"{M}.bvh()") is not None and page.evaluate(f"{M}.bvh()")["edited"]
        page.once("dialog", lambda d: d.accept())
        page.select_option("#sample", index=1)
        page.wait_for_function(f"() => {M}.bvh() === null")
        # units changed now: the closed file is not opened again
        page.select_option("#bvh-units", "m")
        page.wait_for_timeout(300)
        assert page.evaluate(f"{M}.bvh()") is None
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_never_drops_an_edit_when_the_file_changes(server: str, browser: Any) -> None:
    """Found by a browser audit on users' own files (2026-12-05): opening another file (or
    the same again) threw an edited file away unasked; a scrub or a units change while a
    drag's last answer was on its way dropped the edit, and Export wrote the file without
    it; a units choice made for one file (inches) drew the next (centimetres) as a giant;
    after a refused units change the menu showed the refused unit; a refusal did not say
    which file; a file cut short in its last frame opened without a word."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))

    try:
        give_file(page, text, "a.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'a.bvh'")
        drag_joint(page, "left_wrist", 40, -60)
        edited = page.evaluate(f"{M}.bvhText()")
        # another file over an edited one: asked; "no" keeps the edits
        page.once("dialog", lambda d: d.dismiss())
        give_file(page, text, "b.bvh")
        page.wait_for_timeout(300)
        assert page.evaluate(f"{M}.bvh()")["name"] == "a.bvh"
        assert page.evaluate(f"{M}.bvhText()") == edited

        # a scrub, then Export, while the drag's last answer is on its way: both wait for it
        held = held_drag(page, "right_wrist")
        page.locator("#bvh-frame").fill("2")
        with page.expect_download() as download:
            page.click("#export")
            release(page, held)
        page.wait_for_function(f"() => {M}.bvh().frame === 2")
        saved = Path(download.value.path()).read_text()
        assert saved == page.evaluate(f"{M}.bvhText()") != edited  # the drag is in it

        # scrubbed away and back while waiting: the frame asked last (it ended on the other)
        held = held_drag(page, "left_wrist")
        page.locator("#bvh-frame").fill("0")
        page.locator("#bvh-frame").fill("2")
        release(page, held)
        page.wait_for_timeout(200)
        assert page.evaluate(f"{M}.bvh()")["frame"] == 2

        # a file opened while waiting asks too: the edit on its way counts
        held = held_drag(page, "right_wrist")
        dialogs: list[str] = []
        page.once("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
        give_file(page, text, "b.bvh")
        page.wait_for_timeout(300)
        release(page, held)
        assert dialogs and page.evaluate(f"{M}.bvh()")["name"] == "a.bvh"

        # a press released without moving while the drag's answer came back: that answer
        # was held for the press and never asked again, and Export waited for ever
        held = held_drag(page, "head")
        xy = page.evaluate(f"{M}.projectJoint('left_ankle')")
        page.mouse.move(xy["x"], xy["y"])
        page.mouse.down()
        for route in held:
            route.continue_()
        page.unroute("**/v1/bvh/solve")
        page.wait_for_timeout(300)
        page.mouse.up()
        with page.expect_download() as download:  # (within the page's WAIT_MS)
            page.click("#export")
        settle(page)
        assert Path(download.value.path()).read_text() == page.evaluate(f"{M}.bvhText()")

        # a units change the service refuses: the menu goes back to what the file was read with
        page.select_option("#bvh-units", "mm")
        page.wait_for_function(f"() => {M}.error() !== null")
        detail = page.evaluate(f"{M}.error()")["detail"]
        assert detail.startswith("a.bvh: units: 'mm' makes the rest-pose leg"), detail
        assert page.locator("#bvh-units").input_value() == "auto"
        assert page.evaluate(f"{M}.bvh()")["units"] == "cm"

        # inches chosen for this file do not carry over to the next one
        page.select_option("#bvh-units", "in")
        page.wait_for_function(f"() => {M}.bvh().units === 'in'")
        error = page.evaluate(f"{M}.error()")  # (and said: cm read as inches is a giant's leg)
        assert error and error["title"] == "Units" and "a.bvh: " in error["detail"], error
        page.once("dialog", lambda d: d.accept())
        give_file(page, text, "b.bvh")
        page.wait_for_function(f"() => {M}.bvh().name === 'b.bvh'")
        assert page.evaluate(f"{M}.bvh()")["units"] == "cm"
        assert page.locator("#bvh-units").input_value() == "auto"

        # a file cut short in its last frame opens, saying so
        cut = text.rstrip("\n")
        cut = cut[: cut.rindex(" ", 0, len(cut) - 40)] + "\n"
        give_file(page, cut, "cut.bvh")
        page.wait_for_function(f"() => {M}.bvh().name === 'cut.bvh'")
        error = page.evaluate(f"{M}.error()")
        assert error is not None and error["title"] == "Broken file", error
        assert error["detail"].startswith("cut.bvh: the file is cut short: "), error
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_frame_box_jumps_to_a_typed_frame(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """A long file (ReActIdle 003, 918 frames) could only be scrubbed: the frame box beside
    the slider shows the frame (0-based, the API's `frame`), jumps to a typed one on Enter,
    refuses one out of range saying so, follows the slider and its keys (and steps with its
    own arrows), keeps what is being typed while an answer redraws the panel, and waits for
    a drag's last answer as a scrub does."""
    path = next(more_mocap.rglob("genuine/003_genuine.bvh"))
    text = path.read_text()
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    box, slider = page.locator("#bvh-frame-number"), page.locator("#bvh-frame")

    def jump(value: str) -> None:
        box.fill(value)
        box.press("Enter")

    def shows(frame: int) -> None:
        page.wait_for_function(f"() => {M}.bvh().frame === {frame}")
        assert box.input_value() == slider.input_value() == str(frame)

    try:
        page.set_input_files("#bvh-file", str(path))
        page.wait_for_function(f"() => {M}.bvh() !== null")
        assert page.evaluate(f"{M}.bvh().frames") == 918
        assert box.is_visible()
        assert box.input_value() == "0"
        assert box.get_attribute("max") == "917"

        # typed, then Enter: that frame, drawn as the service has it
        jump("700")
        shows(700)
        drawn_as_inspected(page, server, {"bvh": text, "frame": 700})
        assert page.locator("#bvh-frame-label").inner_text().startswith("/ 917 (")

        # the slider and its keys move the box; the box's own arrows step
        slider.focus()
        page.keyboard.press("ArrowRight")
        shows(701)
        page.keyboard.press("End")
        shows(917)
        box.focus()
        page.keyboard.press("ArrowDown")
        shows(916)

        # out of range, or not a whole frame: refused, saying so; the frame stays
        for bad in ("918", "-1", "12.5"):
            jump(bad)
            error = page.evaluate(f"{M}.error()")
            assert error is not None and error["title"] == "No such frame", error
            assert f"003_genuine.bvh: frame {bad}: it has frames 0 to 917" in error["detail"]
            assert page.locator("#error").is_visible()
            shows(916)
        jump("10")  # a frame it has: shown, the refusal gone
        shows(10)
        assert page.evaluate(f"{M}.error()") is None

        # a jump while a drag's last answer is on its way waits for it: the edit is kept
        held = held_drag(page, "left_wrist")
        jump("20")
        page.wait_for_timeout(200)
        assert page.evaluate(f"{M}.bvh().frame") == 10
        release(page, held)
        shows(20)
        assert page.evaluate(f"{M}.history()") == {"length": 2, "index": 1}
        assert page.evaluate(f"{M}.bvhText()") != text

        # what is being typed stays while the answer to a drag redraws the panel
        held = held_drag(page, "right_wrist")
        box.fill("3")
        release(page, held)
        assert page.evaluate(f"{M}.history()") == {"length": 3, "index": 2}
        assert box.input_value() == "3"
        assert page.evaluate(f"{M}.bvh().frame") == 20
        box.press("Enter")
        shows(3)
        page.click("#undo")  # the state before the edit, at its frame: the box follows
        shows(20)
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_keys_late_answers_samples_and_status_after_an_editor_audit(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """An editor audit (2026-12-05): a frame typed in its box kept the focus through a drag,
    so Ctrl+Z undid the box's text and not the drag; a target removed (its x) or pinned
    (Shift-click) while its drag's answer was on the way left that late answer drawn and
    never committed (Export wrote the file unedited); a Sample closed a file whose drag's
    answer was on its way without asking; a file refused for an unreachable server left
    the status saying "connected"."""
    path = next(more_mocap.rglob("genuine/003_genuine.bvh"))
    text = path.read_text()
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        give_file(page, text, "idle.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'idle.bvh'")
        # a frame typed, then a drag: the keys are the page's again
        box = page.locator("#bvh-frame-number")
        box.fill("120")
        box.press("Enter")
        page.wait_for_function(f"() => {M}.bvh().frame === 120")
        steps = page.evaluate(f"{M}.history()")
        drag_joint(page, "left_wrist", 30, -40)
        settle(page)
        assert page.evaluate(f"{M}.history()") != steps
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => {M}.history().index === {steps['index']}")  # undone
        assert page.evaluate(f"{M}.bvh().frame") == 120 and box.input_value() == "120"

        # the target removed, and a target pinned, while the drag's answer is held: the
        # screen shows what is committed, which is what Export writes
        for how in ("remove", "pin"):
            held = held_drag(page, "right_wrist", 30, -40)
            page.wait_for_function(f"() => {M}.solveCount().inflight")
            if how == "remove":
                page.click("#targets tbody button")
            else:
                xy = page.evaluate(f"{M}.projectJoint('right_wrist')")
                page.keyboard.down("Shift")
                page.mouse.click(xy["x"], xy["y"])
                page.keyboard.up("Shift")
            release(page, held)
            page.wait_for_timeout(200)
            got, want = page.evaluate(f"{M}.pose()"), page.evaluate(f"{M}.committedPose()")
            assert all(dist(got[j], want[j]) < 1e-9 for j in want), how

        # a Sample while a drag's answer is on its way asks first; "no" keeps the file
        held = held_drag(page, "head", 20, -20)
        asked: list[str] = []

        def no(dialog: Any) -> None:
            asked.append(dialog.message)
            dialog.dismiss()

        page.once("dialog", no)
        page.select_option("#sample", index=1)
        assert asked and page.evaluate(f"{M}.bvh()") is not None
        release(page, held)
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_status_stays_unreachable_after_a_file_refused_for_it(
    server: str, browser: Any, more_mocap: Path
) -> None:
    text = next(more_mocap.rglob("genuine/003_genuine.bvh")).read_text()
    page = open_editor(browser, server)
    try:
        page.route(re.compile(r".*/(v1/bvh/inspect|v2/health/live)$"), lambda r: r.abort())
        give_file(page, text, "idle.bvh")
        page.wait_for_function(f"() => {M}.error() !== null")
        assert page.evaluate(f"{M}.error()")["status"] == 0
        assert page.locator("#status").inner_text() == "server unreachable"
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_a_sample_chosen_while_a_file_opens_stands(
    server: str, browser: Any, more_mocap: Path
) -> None:
    """An editor audit (2026-12-05): a Sample chosen, and edited, while a file was still
    opening was overwritten by the file when its answer came, the edits lost unasked. The
    later choice stands: the file's late answer is dropped."""
    text = next(more_mocap.rglob("genuine/003_genuine.bvh")).read_text()
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    try:
        held: list[Any] = []
        page.route("**/v1/bvh/inspect", lambda route: held.append(route))
        give_file(page, text, "idle.bvh")
        page.wait_for_function(f"() => {M}.bvh() === null")
        page.wait_for_timeout(200)
        assert held  # the file's inspection is on its way
        page.select_option("#sample", index=2)
        drag_joint(page, "left_wrist", 30, -40)
        settle(page)
        steps = page.evaluate(f"{M}.history()")
        for route in held:
            route.continue_()
        page.unroute("**/v1/bvh/inspect")
        page.wait_for_timeout(1000)
        assert page.evaluate(f"{M}.bvh()") is None  # the sample stands, its edit kept
        assert page.evaluate(f"{M}.history()") == steps
        assert page.locator("#status").inner_text() == "connected"
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_asks_again_when_a_refused_file_would_replace_new_edits(
    server: str, browser: Any
) -> None:
    """An editor audit: the "yes" to replacing an edited file by one whose opening was then
    refused was kept for good, so a joint map (or units) applied later opened the refused
    file without asking, and the edits made to the open file since the "yes" were lost
    unasked. Now the yes covers the edits it was given for: re-trying with no new edits
    does not ask again, with new edits it asks (and "no" keeps them, the menus as the open
    file was read)."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    renamed = text.replace("JOINT LeftForeArm", "JOINT ForeArm_Lft")
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    asked: list[str] = []
    answer = {"yes": True}

    def dialog(d: Any) -> None:
        asked.append(d.message)
        if answer["yes"]:
            d.accept()
        else:
            d.dismiss()

    page.on("dialog", dialog)

    def apply(value: dict[str, str]) -> None:
        page.locator("#bvh-map").fill(json.dumps(value))
        page.click("#bvh-map-apply")

    def error_says(words: str) -> None:
        page.wait_for_function(
            f"() => {M}.error() !== null && {M}.error().detail.includes({json.dumps(words)})"
        )

    try:
        give_file(page, text, "a.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'a.bvh'")
        drag_joint(page, "left_wrist", 40, -60)
        edited = page.evaluate(f"{M}.bvhText()")

        # b.bvh over the edited a.bvh: asked, yes; refused (its left elbow has no name)
        give_file(page, renamed, "b.bvh")
        page.wait_for_function(f"() => {M}.error() !== null")
        assert page.evaluate(f"{M}.error()")["detail"].startswith("b.bvh (a.bvh stays open)")
        assert len(asked) == 1
        assert page.evaluate(f"{M}.bvhText()") == edited

        # new edits to a.bvh, then b.bvh re-tried (units): asked again; "no" keeps them,
        # the menu back to how a.bvh was read
        drag_joint(page, "right_wrist", -40, -60)
        newer = page.evaluate(f"{M}.bvhText()")
        assert newer != edited
        answer["yes"] = False
        page.select_option("#bvh-units", "cm")
        assert len(asked) == 2, asked
        assert "a.bvh" in asked[-1]
        page.wait_for_timeout(300)
        assert page.evaluate(f"{M}.bvh()")["name"] == "a.bvh"
        assert page.evaluate(f"{M}.bvhText()") == newer
        assert page.locator("#bvh-units").input_value() == "auto"

        # asked, yes (refused again: a wrong name); re-tried with no new edits since: the
        # yes holds, through a second refusal too
        answer["yes"] = True
        apply({"left_elbow": "Nope"})
        error_says("Nope")
        assert len(asked) == 3
        page.click("#error-close")
        apply({"left_elbow": "Nope2"})
        error_says("Nope2")
        apply({"left_elbow": "ForeArm_Lft"})
        page.wait_for_function(f"() => {M}.bvh().name === 'b.bvh'")
        assert len(asked) == 3, asked
        assert page.evaluate(f"{M}.bvh()")["jointMap"] == {"left_elbow": "ForeArm_Lft"}
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_keeps_edits_made_while_the_file_is_read_again(server: str, browser: Any) -> None:
    """An editor audit: a units / up axis / root channels / joint map change reads the open
    file again, and its answer replaced the state with the file and frame as they were when
    it was asked: a drag or a pin made meanwhile was drawn, then silently lost. Now editing
    waits, visibly, while the file is read again (a grab, a pin, undo, redo, Reset refused;
    the status says so), and the answer keeps what did change meanwhile: the frame scrubbed
    to, and an option's re-solve (the answer waits for it)."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))

    def held_inspect() -> list[Any]:
        held: list[Any] = []
        page.route("**/v1/bvh/inspect", lambda route: held.append(route))
        return held

    def wait_for(held: list[Any]) -> None:
        for _ in range(100):
            if held:
                return
            page.wait_for_timeout(50)
        raise AssertionError("no request was held")

    def state() -> tuple[str, int, list[str], dict[str, Any]]:
        return (
            page.evaluate(f"{M}.bvhText()"),
            page.evaluate(f"{M}.bvh().frame"),
            page.evaluate(f"{M}.pins()"),
            page.evaluate(f"{M}.history()"),
        )

    try:
        give_file(page, text, "a.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'a.bvh'")
        drag_joint(page, "left_wrist", 40, -60)
        edited = page.evaluate(f"{M}.bvhText()")
        assert edited != text

        # the units changed: while the file is read again, editing waits, and says so
        held = held_inspect()
        page.select_option("#bvh-units", "in")
        wait_for(held)
        assert "editing waits" in page.locator("#status").inner_text()
        for button in ("#undo", "#reset", "#clear-targets"):
            assert page.locator(button).is_disabled(), button
        sent = page.evaluate(f"{M}.solveCount().sent")
        drag_joint(page, "right_wrist", -40, -60)  # refused
        xy = page.evaluate(f"{M}.projectJoint('left_ankle')")
        page.keyboard.down("Shift")
        page.mouse.click(xy["x"], xy["y"])  # a pin: refused
        page.keyboard.up("Shift")
        page.keyboard.press("Control+z")  # refused
        assert page.evaluate(f"{M}.solveCount().sent") == sent
        page.locator("#bvh-frame").fill("2")  # not an edit: shown
        page.wait_for_function(f"() => {M}.bvh().frame === 2")
        during = state()
        assert during[0] == edited and during[2] == []
        for route in held:
            route.continue_()
        page.unroute("**/v1/bvh/inspect")
        page.wait_for_function(f"() => {M}.bvh().units === 'in'")
        assert state()[:3] == during[:3]  # nothing shown meanwhile is lost (was: frame 0)
        assert "editing waits" not in page.locator("#status").inner_text()
        drag_joint(page, "right_wrist", -40, -60)  # editing again
        assert page.evaluate(f"{M}.bvhText()") != edited
        assert not page.locator("#undo").is_disabled()

        # an option changed while the file is read again: its re-solve is an edit too; the
        # answer to the read waits for it and keeps it
        held = held_inspect()
        page.select_option("#bvh-units", "cm")
        wait_for(held)
        solves = held_solves(page)
        page.locator(".segmented label", has_text="FABRIK").click()
        page.wait_for_function(f"() => {M}.solveCount().inflight")
        for route in held:
            route.continue_()
        page.unroute("**/v1/bvh/inspect")
        page.wait_for_timeout(300)
        release(page, solves)
        page.wait_for_function(f"() => {M}.bvh().units === 'cm'")
        last = page.evaluate(f"{M}.lastSolve()")
        assert last["request"]["options"]["method"] == "fabrik"  # its answer was not dropped
        assert page.evaluate(f"{M}.bvhText()") == last["response"]["bvh"]
        assert "editing waits" not in page.locator("#status").inner_text()
        assert not errors, errors
    finally:
        page.context.close()


def held_solves(page: Any) -> list[Any]:
    """Hold the page's BVH solves from now on (``release`` lets them through)."""
    held: list[Any] = []
    page.route("**/v1/bvh/solve", lambda route: held.append(route))
    return held


@pytest.mark.browser
def test_editor_keeps_pins_and_targets_when_the_file_is_read_again(
    server: str, browser: Any
) -> None:
    """An editor audit: reading the open file again (units, up axis, root channels, joint
    map) kept its edits but dropped its pins and targets without a word, so the next drag
    moved the feet the user had pinned and let go of the wrist placed before. Now they are
    kept, each target carried with its joint (at the same place on the figure, in the
    file's units), and the next solve sends them."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    sent = recorded(page, lambda url: "/v1/bvh/solve" in url)
    ankles = ["left_ankle", "right_ankle"]

    def on_its_joint() -> float:
        """How far the left wrist's target is from the wrist drawn (exact reach: ~0)."""
        return float(
            dist(
                page.evaluate(f"{M}.targets()")["left_wrist"],
                page.evaluate(f"{M}.pose()")["left_wrist"],
            )
        )

    try:
        give_file(page, text, "a.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'a.bvh'")
        for ankle in ankles:
            xy = page.evaluate(f"{M}.projectJoint('{ankle}')")
            page.keyboard.down("Shift")
            page.mouse.click(xy["x"], xy["y"])
            page.keyboard.up("Shift")
        drag_joint(page, "left_wrist", 40, -60)
        assert sorted(page.evaluate(f"{M}.pins()")) == ankles
        assert on_its_joint() < 0.002
        placed = sent[-1]["targets"][0]["position"]  # the target in the file's units
        edited = page.evaluate(f"{M}.bvhText()")

        for menu, value in (("#bvh-units", "in"), ("#bvh-root", "add"), ("#bvh-up", "+Y")):
            page.select_option(menu, value)
            page.wait_for_function(
                f"() => {M}.history().length === 1 && !{M}.solveCount().inflight"
            )
            page.wait_for_timeout(100)
            assert sorted(page.evaluate(f"{M}.pins()")) == ankles, menu
            assert list(page.evaluate(f"{M}.targets()")) == ["left_wrist"], menu
            assert on_its_joint() < 0.002 * 2.54, menu  # (read in inches: 2.54 times larger)
            assert page.evaluate(f"{M}.bvhText()") == edited
        assert "left_ankle" in page.locator("#pins").inner_text()

        # the next drag sends them: the pins, and the wrist's target where it was placed
        page.select_option("#bvh-root", "replace")
        page.wait_for_function(f"() => {M}.bvh().root === 'replace'")
        drag_joint(page, "right_wrist", -40, -60)
        last = sent[-1]
        assert sorted(last["pins"]) == ankles
        targets = {t["joint"]: t["position"] for t in last["targets"]}
        assert sorted(targets) == ["left_wrist", "right_wrist"]
        assert dist(targets["left_wrist"], placed) < 1e-6
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_asks_before_dropping_a_files_pins_and_targets(server: str, browser: Any) -> None:
    """Found by an editor review: the "has edits?" question before a file is replaced or
    closed looked at its text only, so pins (a shift-click) and targets placed without a
    drag committed (its solve failed: the targets are kept to retry) were dropped unasked
    when a Sample was chosen or another file opened. Now they count as edits: both ask,
    and "no" keeps the file with them; a file with none still goes unasked."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    asked: list[str] = []

    def no(dialog: Any) -> None:
        asked.append(dialog.message)
        dialog.dismiss()

    page.on("dialog", no)

    def shift_click(joint: str) -> None:
        xy = page.evaluate(f"{M}.projectJoint('{joint}')")
        page.keyboard.down("Shift")
        page.mouse.click(xy["x"], xy["y"])
        page.keyboard.up("Shift")

    def kept(pins: list[str], targets: list[str]) -> None:
        """Asked once more, and "no" kept a.bvh as it was, with its pins and targets."""
        page.wait_for_timeout(300)
        assert len(asked) == n + 1, asked
        assert "a.bvh" in asked[-1]
        assert page.evaluate(f"{M}.bvh()")["name"] == "a.bvh"
        assert page.evaluate(f"{M}.bvhText()") == text
        assert page.evaluate(f"{M}.pins()") == pins
        assert sorted(page.evaluate(f"{M}.targets()")) == targets

    try:
        give_file(page, text, "a.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'a.bvh'")

        # -- a pin alone (no drag): a Sample, another file: both ask ------------------------
        shift_click("left_ankle")
        assert page.evaluate(f"{M}.pins()") == ["left_ankle"]
        assert not page.evaluate(f"{M}.bvh()")["edited"]  # (the text is as opened)
        n = len(asked)
        page.select_option("#sample", index=1)
        kept(["left_ankle"], [])
        n = len(asked)
        give_file(page, text, "b.bvh")
        kept(["left_ankle"], [])
        shift_click("left_ankle")  # unpinned
        assert page.evaluate(f"{M}.pins()") == []

        # -- a target alone (its drag's solve failed: kept to retry, the text unchanged) --
        page.route("**/v1/bvh/solve", lambda route: route.abort())
        drag_joint(page, "left_wrist", 40, -60)
        page.unroute("**/v1/bvh/solve")
        assert page.evaluate(f"{M}.error()")["status"] == 0
        n = len(asked)
        page.select_option("#sample", index=1)
        kept([], ["left_wrist"])
        n = len(asked)
        give_file(page, text, "b.bvh")
        kept([], ["left_wrist"])

        # -- with neither (Reset): a Sample closes the file unasked ----------------------
        page.click("#reset")
        assert page.evaluate(f"{M}.targets()") == {} and page.evaluate(f"{M}.pins()") == []
        n = len(asked)
        page.select_option("#sample", index=1)
        page.wait_for_function(f"() => {M}.bvh() === null")
        assert len(asked) == n
        assert not errors, errors
    finally:
        page.context.close()
