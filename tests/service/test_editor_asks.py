"""The browser editor asking before it drops the user's work (real Chromium, the real
server): a Sample or a BVH file chosen over a sample's own edits, pins and targets, and the
questions naming what would be lost (a sample's, a file's). Shared parts:
``tests/service/editor_page.py``; a file's pins and targets asked about before a Sample or
another file: ``test_editor_edits.py -k dropping_a_files``.
"""

from __future__ import annotations

import json
from math import dist
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import REPO_ROOT
from tests.service.editor_page import M, drag_joint, give_file, open_editor, recorded, settle

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

SAMPLES = json.loads((REPO_ROOT / "service" / "static" / "samples.json").read_text())["samples"]
NAMES = [s["name"] for s in SAMPLES]


class Dialogs:
    """Every question the page asks, answered as ``yes`` says (no, unless set)."""

    def __init__(self, page: Any) -> None:
        self.asked: list[str] = []
        self.yes = False
        page.on("dialog", self.answer)

    def next(self, page: Any, n: int) -> str:
        """The question after the first ``n``, once asked (within 5 s)."""
        for _ in range(100):
            if len(self.asked) > n:
                break
            page.wait_for_timeout(50)
        assert len(self.asked) == n + 1, self.asked
        return self.asked[-1]

    def answer(self, dialog: Any) -> None:
        self.asked.append(dialog.message)
        if self.yes:
            dialog.accept()
        else:
            dialog.dismiss()


def shift_click(page: Any, joint: str) -> None:
    """Pin (or unpin) ``joint``, as a user does: Shift held, its handle clicked."""
    xy = page.evaluate(f"{M}.projectJoint('{joint}')")
    page.keyboard.down("Shift")
    page.mouse.click(xy["x"], xy["y"])
    page.keyboard.up("Shift")
    settle(page)


def drag_held(page: Any, joint: str) -> list[Any]:
    """``joint`` dragged a little, its solve held (routes of /v1/solve kept, unanswered):
    the held routes, once the answer is on its way."""
    held: list[Any] = []
    page.route("**/v1/solve", lambda route: held.append(route))
    xy = page.evaluate(f"{M}.projectJoint('{joint}')")
    page.mouse.move(xy["x"], xy["y"])
    page.mouse.down()
    page.mouse.move(xy["x"] - 30, xy["y"] - 40, steps=4)
    page.mouse.up()
    page.wait_for_function(f"() => {M}.solveCount().inflight")
    return held


@pytest.mark.browser
def test_editor_asks_before_a_sample_drops_a_samples_pins_and_targets(
    server: str, browser: Any
) -> None:
    """Found by an editor review: with no file open, choosing a Sample dropped the sample
    shown with its edited pose, pins and targets without asking (only an open file's edits
    were asked about). Now it asks whenever there is anything to drop, naming it, and "no"
    keeps everything (the pose, pins, targets, history, the menu); a pristine sample and
    Reset go unasked, as before; "yes" loads the sample, and Undo returns to the edits, as
    the question says."""
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    dialogs = Dialogs(page)

    def state() -> dict[str, Any]:
        return {
            "sample": page.locator("#sample").input_value(),
            "pose": page.evaluate(f"{M}.pose()"),
            "pins": page.evaluate(f"{M}.pins()"),
            "targets": page.evaluate(f"{M}.targets()"),
            "history": page.evaluate(f"{M}.history()"),
        }

    def is_sample(i: int) -> bool:
        pose = page.evaluate(f"{M}.pose()")
        return all(dist(pose[j], SAMPLES[i]["pose"][j]) < 1e-9 for j in pose)

    def asked_no(i: int, says: str) -> None:
        """Sample ``i`` chosen: asked once, saying ``says``; "no" kept all of it."""
        before, n = state(), len(dialogs.asked)
        page.select_option("#sample", index=i)
        page.wait_for_timeout(200)
        assert len(dialogs.asked) == n + 1, dialogs.asked
        assert dialogs.asked[-1] == says
        assert state() == before

    try:
        # -- nothing to drop: a Sample goes unasked ---------------------------------------
        page.select_option("#sample", index=1)
        assert is_sample(1) and dialogs.asked == []

        # -- a pin alone: asked, "no" keeps it; Reset (an undo step) is not asked about ----
        shift_click(page, "left_ankle")
        assert page.evaluate(f"{M}.pins()") == ["left_ankle"] and is_sample(1)
        asked_no(
            2,
            f'Load the sample "{NAMES[2]}"? This drops 1 pin on "{NAMES[1]}" '
            f'(Undo returns to "{NAMES[1]}" as it is now).',
        )
        page.click("#reset")
        assert page.evaluate(f"{M}.pins()") == [] and len(dialogs.asked) == 1

        # -- a target alone (its drag's solve failed: kept to retry, the pose as it was) --
        page.route("**/v1/solve", lambda route: route.abort())
        drag_joint(page, "left_wrist", 40, -60)
        page.unroute("**/v1/solve")
        assert list(page.evaluate(f"{M}.targets()")) == ["left_wrist"] and is_sample(1)
        asked_no(
            3,
            f'Load the sample "{NAMES[3]}"? This drops 1 target on "{NAMES[1]}" '
            f'(Undo returns to "{NAMES[1]}" as it is now).',
        )

        # -- the pose edited (a drag), two pins and a target ------------------------------
        page.click("#reset")
        drag_joint(page, "left_wrist", 40, -60)
        shift_click(page, "left_ankle")
        shift_click(page, "right_ankle")
        assert not is_sample(1)
        asked_no(
            2,
            f'Load the sample "{NAMES[2]}"? This drops your edits to the pose, 2 pins and '
            f'1 target on "{NAMES[1]}" (Undo returns to "{NAMES[1]}" as it is now).',
        )

        # -- an edit whose answer is on its way: asked too ---------------------------------
        held = drag_held(page, "right_wrist")
        n = len(dialogs.asked)
        page.select_option("#sample", index=2)
        assert len(dialogs.asked) == n + 1
        assert dialogs.asked[-1].endswith("as it was before the edit being solved).")
        assert page.locator("#sample").input_value() == "1"
        for route in held:
            route.continue_()
        page.unroute("**/v1/solve")
        settle(page)
        assert sorted(page.evaluate(f"{M}.targets()")) == ["left_wrist", "right_wrist"]
        edited = state()

        # -- "yes": the sample, and Undo returns to the edits as they were ---------------
        dialogs.yes = True
        page.select_option("#sample", index=2)
        assert len(dialogs.asked) == n + 2
        assert is_sample(2) and page.evaluate(f"{M}.pins()") == []
        assert page.evaluate(f"{M}.targets()") == {}
        page.click("#undo")
        back = state()
        assert {k: back[k] for k in ("sample", "pose", "pins", "targets")} == {
            k: edited[k] for k in ("sample", "pose", "pins", "targets")
        }
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_names_what_closing_a_file_loses(server: str, browser: Any) -> None:
    """Found by an editor review: a file about to be replaced or closed was asked about as
    "The edits to a.bvh are lost unless exported" even when it had no edit, only pins or
    targets (which Export BVH does not keep either). Now the question names what would be
    lost (edits to the file, so many pins, so many targets) and says what an export keeps,
    for another file opened and for a Sample alike."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    dialogs = Dialogs(page)  # (all answered "no": a.bvh stays open)

    def asked(opening: str) -> str:
        """The question asked when ``opening`` (a file name, or "sample") replaces a.bvh."""
        n = len(dialogs.asked)
        if opening == "sample":
            page.select_option("#sample", index=1)
        else:
            give_file(page, text, opening)
        said = dialogs.next(page, n)
        page.wait_for_timeout(100)
        assert page.evaluate(f"{M}.bvh()")["name"] == "a.bvh"
        return said

    try:
        give_file(page, text, "a.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'a.bvh'")

        # -- a pin alone: named, no "edits", nothing said of exporting --------------------
        shift_click(page, "left_ankle")
        assert asked("b.bvh") == "Open b.bvh? Closing a.bvh loses 1 pin."
        assert asked("sample") == f'Load the sample "{NAMES[1]}"? Closing a.bvh loses 1 pin.'

        # -- two pins and a target (its drag's solve failed), the text as opened ----------
        shift_click(page, "right_ankle")
        page.route("**/v1/bvh/solve", lambda route: route.abort())
        drag_joint(page, "left_wrist", 40, -60)
        page.unroute("**/v1/bvh/solve")
        assert not page.evaluate(f"{M}.bvh()")["edited"]
        assert asked("b.bvh") == "Open b.bvh? Closing a.bvh loses 2 pins and 1 target."

        # -- an edit to the file and its target: what Export BVH keeps ----------------------
        page.click("#reset")
        drag_joint(page, "left_wrist", 40, -60)
        assert page.evaluate(f"{M}.bvh()")["edited"]
        assert asked("b.bvh") == (
            "Open b.bvh? Closing a.bvh loses your edits to the file and 1 target "
            "(Export BVH keeps the edits, not pins or targets)."
        )

        # -- the edit alone (its target cleared) ------------------------------------------
        page.click("#clear-targets")
        settle(page)
        assert page.evaluate(f"{M}.targets()") == {} and page.evaluate(f"{M}.pins()") == []
        assert asked("sample") == (
            f'Load the sample "{NAMES[1]}"? Closing a.bvh loses your edits to the file '
            "unless exported."
        )
        assert not errors, errors
    finally:
        page.context.close()


def drop_file(page: Any, body: str, name: str) -> None:
    """``body`` dropped on the page as the file ``name`` (a drag from the desktop)."""
    page.evaluate(
        """([body, name]) => {
          const dt = new DataTransfer();
          dt.items.add(new File([body], name, { type: 'text/plain' }));
          window.dispatchEvent(
            new DragEvent('drop', { dataTransfer: dt, bubbles: true, cancelable: true }));
        }""",
        [body, name],
    )


def recorded_urls(page: Any, ending: str) -> list[str]:
    """The URLs ending with ``ending`` that ``page`` asks for, appended as they go out."""
    urls: list[str] = []
    page.on("request", lambda r: urls.append(r.url) if r.url.endswith(ending) else None)
    return urls


@pytest.mark.browser
def test_editor_asks_before_a_file_replaces_a_samples_work(server: str, browser: Any) -> None:
    """Found by an editor review: a BVH file opened (the picker, a drop, a refused file
    re-tried by a units change) over a sample with pins, targets or an edited pose dropped
    them without asking, and Undo could not bring them back (opening a file starts the
    undo history anew). Now it asks once, naming what is lost, and "no" keeps the pose,
    pins, targets, history (Undo still works) and the menu; "yes" opens the file; a
    pristine sample opens it unasked, as before."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    renamed = text.replace("JOINT LeftForeArm", "JOINT ForeArm_Lft")  # refused: unmapped
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    dialogs = Dialogs(page)  # "no", until set
    shown = NAMES[1]

    def question(name: str, lost: str) -> str:
        return (
            f'Open {name}? This drops {lost} on "{shown}" (Undo cannot return to '
            f'"{shown}": a file opened starts the undo history anew).'
        )

    def state() -> dict[str, Any]:
        return {
            "sample": page.locator("#sample").input_value(),
            "pose": page.evaluate(f"{M}.pose()"),
            "committed": page.evaluate(f"{M}.committedPose()"),
            "pins": page.evaluate(f"{M}.pins()"),
            "targets": page.evaluate(f"{M}.targets()"),
            "history": page.evaluate(f"{M}.history()"),
            "bvh": page.evaluate(f"{M}.bvh()"),
        }

    def asked_no(give: Any, name: str, lost: str) -> None:
        """The file ``name`` given (``give``) over the sample: asked once, exactly; "no"
        kept all of it (nothing opened, nothing sent)."""
        before, n = state(), len(dialogs.asked)
        give(page, text, name)
        assert dialogs.next(page, n) == question(name, lost)
        page.wait_for_timeout(300)
        assert len(dialogs.asked) == n + 1, dialogs.asked
        assert state() == before

    try:
        page.select_option("#sample", index=1)
        assert dialogs.asked == []
        inspected = recorded_urls(page, "/v1/bvh/inspect")

        # -- a pin alone: asked (picker and drop alike), "no" keeps it -------------------
        shift_click(page, "left_ankle")
        assert page.evaluate(f"{M}.pins()") == ["left_ankle"]
        asked_no(give_file, "b.bvh", "1 pin")
        asked_no(drop_file, "c.bvh", "1 pin")

        # -- a target alone (its drag's solve failed: kept to retry, the pose as it was) --
        page.click("#reset")
        page.route("**/v1/solve", lambda route: route.abort())
        drag_joint(page, "left_wrist", 40, -60)
        page.unroute("**/v1/solve")
        assert list(page.evaluate(f"{M}.targets()")) == ["left_wrist"]
        asked_no(give_file, "b.bvh", "1 target")

        # -- the pose edited alone (a drag, its target cleared): "no", and Undo still works
        page.click("#reset")
        drag_joint(page, "left_wrist", 40, -60)
        dragged = state()
        page.click("#clear-targets")
        settle(page)
        assert page.evaluate(f"{M}.targets()") == {} and page.evaluate(f"{M}.pins()") == []
        asked_no(give_file, "b.bvh", "your edits to the pose")
        asked_no(drop_file, "b.bvh", "your edits to the pose")
        assert inspected == []  # nothing was read
        page.click("#undo")  # back to the drag, its target
        assert {k: v for k, v in state().items() if k != "history"} == {
            k: v for k, v in dragged.items() if k != "history"
        }
        page.click("#redo")
        edited = state()

        # -- "yes" to a file the service refuses: the sample stays, its edits kept; re-tried
        # (units) with no edit since: not asked again; with a pin since: asked, "no" keeps
        # it, the menu back to how the file was last tried
        dialogs.yes = True
        n = len(dialogs.asked)
        give_file(page, renamed, "d.bvh")
        page.wait_for_function(f"() => ({M}.error() || {{}}).detail?.startsWith('d.bvh')")
        assert len(dialogs.asked) == n + 1
        assert state() == edited
        page.click("#error-close")
        page.select_option("#bvh-units", "cm")
        page.wait_for_function(f"() => {M}.error() !== null")
        assert len(dialogs.asked) == n + 1 and state() == edited
        page.click("#error-close")
        shift_click(page, "right_ankle")
        dialogs.yes = False
        page.select_option("#bvh-units", "m")
        assert dialogs.next(page, n + 1) == question("d.bvh", "your edits to the pose and 1 pin")
        page.wait_for_timeout(300)
        assert page.evaluate(f"{M}.bvh()") is None
        assert page.evaluate(f"{M}.pins()") == ["right_ankle"]
        assert page.locator("#bvh-units").input_value() == "cm"

        # -- "yes" opens the file ---------------------------------------------------------
        dialogs.yes = True
        n = len(dialogs.asked)
        give_file(page, text, "b.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'b.bvh'")
        assert len(dialogs.asked) == n + 1
        assert dialogs.asked[-1] == question("b.bvh", "your edits to the pose and 1 pin")

        # -- a pristine sample: the file opens unasked, as before --------------------------
        page.select_option("#sample", index=1)  # (b.bvh unedited: unasked)
        assert page.evaluate(f"{M}.bvh()") is None
        give_file(page, text, "e.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'e.bvh'")
        page.select_option("#sample", index=1)
        drop_file(page, text, "f.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'f.bvh'")
        assert len(dialogs.asked) == n + 1, dialogs.asked
        assert not errors, errors
    finally:
        page.context.close()


def until(page: Any, done: Any) -> None:
    """Wait (up to 5 s) until ``done()``, a check on what the test recorded, holds."""
    for _ in range(100):
        if done():
            return
        page.wait_for_timeout(50)
    assert done()


def inspect_held(page: Any) -> list[Any]:
    """Hold back every ``/v1/bvh/inspect`` (a file being read stays so): the held routes."""
    held: list[Any] = []
    page.route("**/v1/bvh/inspect", lambda route: held.append(route))
    return held


def let_through(page: Any, held: list[Any]) -> None:
    """Let the held inspections through, and stop holding them."""
    for route in held:
        route.continue_()
    page.unroute("**/v1/bvh/inspect")


def drop_files(page: Any, files: list[tuple[str, str]]) -> None:
    """Each ``(body, name)`` dropped on the page in turn, in one task (the second while the
    first one's bytes are still being read: a large file's take seconds)."""
    page.evaluate(
        """(files) => {
          for (const [body, name] of files) {
            const dt = new DataTransfer();
            dt.items.add(new File([body], name, { type: 'text/plain' }));
            window.dispatchEvent(
              new DragEvent('drop', { dataTransfer: dt, bubbles: true, cancelable: true }));
          }
        }""",
        [list(f) for f in files],
    )


@pytest.mark.browser
def test_editor_asks_once_while_a_file_is_read(server: str, browser: Any) -> None:
    """Found by a review: the user said yes to a file dropping a sample's work; while that
    file was still being read (its bytes, or the service's inspection), the page asked the
    same again for a second file picked, a Sample chosen or the units changed, and a "no"
    kept nothing: the first file opened over the work all the same. Asked twice, word for
    word, when the yes came while a drag's answer was on its way and the answer landed
    during the read. Now a yes covers the state it was given for until the read ends (a
    later choice takes its place unasked), and of two files dropped at once only the later
    is asked about and read."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    dialogs = Dialogs(page)
    inspected = recorded(page, lambda url: url.endswith("/v1/bvh/inspect"))  # the bodies
    shown = NAMES[1]

    def question(name: str, lost: str) -> str:
        return (
            f'Open {name}? This drops {lost} on "{shown}" (Undo cannot return to '
            f'"{shown}": a file opened starts the undo history anew).'
        )

    def opened(name: str) -> None:
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === '{name}'")

    try:
        page.select_option("#sample", index=1)

        # -- a second file picked while the first is inspected: not asked again; it opens
        shift_click(page, "left_ankle")
        dialogs.yes = True
        held = inspect_held(page)
        give_file(page, text, "a.bvh")
        assert dialogs.next(page, 0) == question("a.bvh", "1 pin")
        page.wait_for_function(
            "() => document.getElementById('status').textContent"
            " === 'opening a.bvh… (editing waits)'"
        )
        give_file(page, text, "b.bvh")
        until(page, lambda: len(inspected) == 2)
        page.wait_for_timeout(200)
        assert len(dialogs.asked) == 1, dialogs.asked
        assert page.evaluate(f"{M}.pins()") == ["left_ankle"]  # (still being read)
        let_through(page, held)
        opened("b.bvh")
        assert len(dialogs.asked) == 1, dialogs.asked

        # -- a Sample chosen while a file is inspected: not asked again; the file never opens
        shift_click(page, "left_ankle")  # a pin on b.bvh
        held = inspect_held(page)
        give_file(page, text, "c.bvh")
        assert dialogs.next(page, 1) == "Open c.bvh? Closing b.bvh loses 1 pin."
        until(page, lambda: len(inspected) == 3)
        page.select_option("#sample", index=1)
        assert len(dialogs.asked) == 2, dialogs.asked
        assert page.evaluate(f"{M}.bvh()") is None and page.evaluate(f"{M}.pins()") == []
        let_through(page, held)
        page.wait_for_timeout(300)
        assert page.evaluate(f"{M}.bvh()") is None  # (its late answer dropped)

        # -- the yes given while a drag's answer was on its way, the answer landing during
        # the read: the units changed then read the file again unasked (was: asked again)
        solves = drag_held(page, "left_wrist")
        held = inspect_held(page)
        give_file(page, text, "d.bvh")
        assert dialogs.next(page, 2) == question("d.bvh", "your edits to the pose and 1 target")
        for route in solves:
            route.continue_()
        page.unroute("**/v1/solve")
        settle(page)  # (the drag's answer committed: an undo step, during the read)
        assert page.evaluate(f"{M}.history()")["index"] == 1
        page.select_option("#bvh-units", "m")
        until(page, lambda: len(inspected) == 5)
        assert inspected[-1]["units"] == "m" and len(dialogs.asked) == 3, dialogs.asked
        give_file(page, text, "e.bvh")  # and a file picked then
        until(page, lambda: len(inspected) == 6)
        assert len(dialogs.asked) == 3, dialogs.asked
        let_through(page, held)
        opened("e.bvh")
        assert len(dialogs.asked) == 3, dialogs.asked

        # -- two files dropped at once (the second while the first one's bytes are read):
        # one question, of the later; "no" reads neither, "yes" opens the later
        page.select_option("#sample", index=1)  # (e.bvh unedited: unasked)
        shift_click(page, "left_ankle")
        dialogs.yes = False
        before = len(inspected)
        drop_files(page, [(text, "f.bvh"), (text, "g.bvh")])
        assert dialogs.next(page, 3) == question("g.bvh", "1 pin")
        page.wait_for_timeout(300)
        assert len(dialogs.asked) == 4 and len(inspected) == before, dialogs.asked
        assert page.evaluate(f"{M}.pins()") == ["left_ankle"]
        dialogs.yes = True
        drop_files(page, [(text, "f.bvh"), (text, "g.bvh")])
        assert dialogs.next(page, 4) == question("g.bvh", "1 pin")
        opened("g.bvh")
        assert len(dialogs.asked) == 5 and len(inspected) == before + 1, dialogs.asked
        assert not errors, errors
    finally:
        page.context.close()


def pick_file(page: Any, path: Path) -> None:
    """``path`` chosen in the file chooser that "Open BVH…" opens, as a user does (the same
    file chosen again fires no change unless the page emptied the input)."""
    with page.expect_file_chooser() as chooser:
        page.click("#bvh-open")
    chooser.value.set_files(str(path))


@pytest.mark.browser
def test_editor_asks_once_about_a_refused_file_picked_again(
    server: str, browser: Any, tmp_path: Path
) -> None:
    """Found by a review: a file the service refused, picked again in the file chooser
    (or dropped again), asked again the question the user had said yes to, though nothing
    new would be lost (a units change re-trying it did not ask). Now re-picking the same
    file re-tries it (the chooser's change fires for the same file), asking only about
    edits newer than the yes, once; with the joint map filled in, it opens. The file open
    re-picked with edits is still asked about (re-opening drops them)."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    refused = tmp_path / "d.bvh"
    refused.write_text(text.replace("JOINT LeftForeArm", "JOINT ForeArm_Lft"))  # unmapped
    broken = tmp_path / "e.bvh"
    broken.write_text(text.split("MOTION")[0][:400])  # cut short in its hierarchy
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    dialogs = Dialogs(page)
    inspected = recorded_urls(page, "/v1/bvh/inspect")
    shown = NAMES[1]

    def question(name: str, lost: str) -> str:
        return (
            f'Open {name}? This drops {lost} on "{shown}" (Undo cannot return to '
            f'"{shown}": a file opened starts the undo history anew).'
        )

    def refused_again(pick: Any, name: str, asked: int) -> None:
        """``pick()`` re-tries the file ``name``: read (one more inspection), refused, and
        ``asked`` questions in all."""
        n = len(inspected)
        if page.evaluate(f"{M}.error()") is not None:
            page.click("#error-close")
        pick()
        until(page, lambda: len(inspected) == n + 1)
        page.wait_for_function(
            f"() => ({M}.error() || {{}}).detail?.startsWith({json.dumps(name)})"
        )
        page.wait_for_timeout(200)
        assert len(dialogs.asked) == asked, dialogs.asked

    try:
        page.select_option("#sample", index=1)
        shift_click(page, "left_ankle")

        # -- refused after a yes; picked again (and dropped again): re-tried, not asked ----
        dialogs.yes = True
        refused_again(lambda: pick_file(page, refused), "d.bvh", 1)
        assert dialogs.asked[0] == question("d.bvh", "1 pin")
        refused_again(lambda: pick_file(page, refused), "d.bvh", 1)
        refused_again(lambda: drop_file(page, refused.read_text(), "d.bvh"), "d.bvh", 1)
        assert page.evaluate(f"{M}.pins()") == ["left_ankle"]  # (the sample kept)

        # -- a pin since, the joint map field unreadable: said, not asked, nothing read ------
        shift_click(page, "right_ankle")
        dialogs.yes = False
        n = len(inspected)
        page.click("#error-close")
        page.locator("#bvh-map").fill('{"left_elbow": ')
        pick_file(page, refused)
        page.wait_for_function(f"() => ({M}.error() || {{}}).title === 'Joint map'")
        page.wait_for_timeout(200)
        assert len(dialogs.asked) == 1 and len(inspected) == n, dialogs.asked
        page.locator("#bvh-map").fill("")

        # -- the pin since: asked once, of both; "no" reads nothing; "yes" re-tries it -----
        pick_file(page, refused)
        assert dialogs.next(page, 1) == question("d.bvh", "2 pins")
        page.wait_for_timeout(300)
        assert len(inspected) == n and page.evaluate(f"{M}.pins()") == ["left_ankle", "right_ankle"]
        dialogs.yes = True
        refused_again(lambda: pick_file(page, refused), "d.bvh", 3)
        refused_again(lambda: pick_file(page, refused), "d.bvh", 3)

        # -- the joint map filled in, the file picked again: it opens, unasked -------------
        page.locator("#bvh-map").fill(json.dumps({"left_elbow": "ForeArm_Lft"}))
        pick_file(page, refused)
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'd.bvh'")
        assert page.evaluate(f"{M}.bvh()")["jointMap"] == {"left_elbow": "ForeArm_Lft"}
        assert len(dialogs.asked) == 3, dialogs.asked

        # -- over the file open, edited: a refused file picked again is not asked about
        # again; the open file picked again is (re-opening it drops the edit) -------------
        drag_joint(page, "left_wrist", 40, -60)
        assert page.evaluate(f"{M}.bvh()")["edited"]
        refused_again(lambda: pick_file(page, broken), "e.bvh", 4)
        assert dialogs.asked[3] == (
            "Open e.bvh? Closing d.bvh loses your edits to the file and 1 target "
            "(Export BVH keeps the edits, not pins or targets)."
        )
        assert "(d.bvh stays open)" in page.evaluate(f"{M}.error()")["detail"]
        refused_again(lambda: pick_file(page, broken), "e.bvh", 4)
        dialogs.yes = False
        pick_file(page, refused)
        assert dialogs.next(page, 4).startswith("Open d.bvh? Closing d.bvh loses your edits")
        page.wait_for_timeout(300)
        assert page.evaluate(f"{M}.bvh()")["edited"]
        assert not errors, errors
    finally:
        page.context.close()
