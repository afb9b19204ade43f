"""The editor without a mouse (``service/static/editor/keys.js``, ``nudge.js``): a joint
selected from the keyboard ([ / ] in the view, the panel's picker), its target nudged by the
step (arrows, PageUp / PageDown, Shift / Alt) or typed (x, y, z in metres), each key press
one undo step, P pinning and Delete removing the target, and the view's keys left alone
while a field is typed in.

The real server and a real Chromium (``tests/service/editor_page.py``); the nudge's axes
and steps also run in Node.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from math import dist
from typing import Any

import pytest

from core.skeleton import JOINT_NAMES
from tests.conftest import REPO_ROOT
from tests.service.editor_page import (
    VIEW,
    M,
    open_editor,
    open_file,
    pick,
    recorded,
    settle,
    steps,
    watched_page,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

NUDGE_JS = REPO_ROOT / "service" / "static" / "editor" / "nudge.js"
STEP = 0.01  # the nudge step the page starts with (1 cm)
TOLERANCE = 0.001  # the page's default tolerance (m), exact reach on


# -- helpers ---------------------------------------------------------------------------------
def press(page: Any, key: str, *, then_steps: int | None = None) -> None:
    """``key`` pressed in the view (which must have the focus); waits for the solves and,
    given ``then_steps``, for the history to reach it (polled, no fixed wait)."""
    assert page.evaluate("document.activeElement.tagName") == "CANVAS"
    page.keyboard.press(key)
    settle(page)
    if then_steps is not None:
        page.wait_for_function(f"() => {M}.history().index === {then_steps}", polling=50)


def target(page: Any, joint: str) -> list[float] | None:
    got: list[float] | None = page.evaluate(f"{M}.targets()").get(joint)
    return got


def reached(page: Any, joint: str) -> float:
    """How far the drawn joint is from its target (m)."""
    goal = target(page, joint)
    assert goal is not None, joint
    return dist(page.evaluate(f"{M}.pose()")[joint], goal)


def moved_by(before: list[float], after: list[float] | None, by: list[float]) -> bool:
    return after is not None and all(
        abs(a - b - d) < 1e-9 for a, b, d in zip(after, before, by, strict=True)
    )


def select(page: Any, joint: str) -> None:
    """``joint`` chosen in the panel's picker, then the focus given back to the view."""
    pick(page, joint)
    page.focus(VIEW)


# -- without a browser: the axes and steps ---------------------------------------------------
RUN_NUDGE = """
const { nudgeDirection, nudgeStep } = await import(process.argv[1]);
const cases = JSON.parse(process.argv[2]);
console.log(JSON.stringify({
  directions: cases.map(([key, right, ahead, up]) => nudgeDirection(key, right, ahead, up)),
  steps: [nudgeStep(0.01), nudgeStep(0.01, { shiftKey: true }), nudgeStep(0.01, { altKey: true }),
          nudgeStep(0.01, { shiftKey: true, altKey: true })],
}));
"""


def test_nudge_axes_follow_the_view_and_the_modifiers_scale_the_step() -> None:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is needed to run the editor's module")
    front = ([1, 0, 0], [0, -0.2, -0.98], [0, 0.98, -0.2])  # the page's start: +Z side
    behind = ([-1, 0, 0], [0, -0.2, 0.98], [0, 0.98, 0.2])
    left_side = ([0, 0, -0.9], [0.9, 0, 0], [0, 1, 0])  # from -X, looking towards +X
    above = ([1, 0, 0], [0, -1, 0], [0, 0, -1])  # straight down, screen up = -Z
    cases = [
        ["ArrowRight", *front],
        ["ArrowLeft", *front],
        ["ArrowUp", *front],
        ["ArrowDown", *front],
        ["ArrowRight", *behind],
        ["ArrowUp", *behind],
        ["ArrowRight", *left_side],
        ["ArrowUp", *left_side],
        ["ArrowUp", *above],
        ["PageUp", *behind],
        ["PageDown", *front],
        ["Enter", *front],
    ]
    out = subprocess.run(
        [node, "--input-type=module", "-e", RUN_NUDGE, str(NUDGE_JS), json.dumps(cases)],
        capture_output=True,
        text=True,
        check=True,
        timeout=30,
    )
    got = json.loads(out.stdout)
    assert got["directions"] == [
        [1, 0, 0],
        [-1, 0, 0],
        [0, 0, -1],  # Up: away from the viewer
        [0, 0, 1],
        [-1, 0, 0],  # from behind: the screen's right is -X
        [0, 0, 1],
        [0, 0, -1],  # from the side: the screen's right is -Z
        [1, 0, 0],
        [0, 0, -1],  # from above: Up is the screen's up
        [0, 1, 0],
        [0, -1, 0],
        None,
    ]
    assert got["steps"] == pytest.approx([0.01, 0.1, 0.001, 0.01])


# -- in the browser --------------------------------------------------------------------------
# The width of ``text`` in the joint menu's font, and the room the closed menu has for it
# (its width less its padding, border and arrow: 20 px).
FITS = """(text) => {
  const menu = document.getElementById('joint-pick');
  const style = getComputedStyle(menu);
  const c = document.createElement('canvas').getContext('2d');
  c.font = `${style.fontSize} ${style.fontFamily}`;
  const padding = parseFloat(style.paddingLeft) + parseFloat(style.paddingRight);
  return [c.measureText(text).width, menu.clientWidth - padding - 20];
}"""


@pytest.mark.browser
def test_editor_selects_and_nudges_a_joint_from_the_keyboard(server: str, browser: Any) -> None:
    context, page, console_errors, page_errors, _, solves = watched_page(browser, "/v1/solve")
    try:
        page.goto(server + "/editor")
        page.wait_for_function(f"() => {M} && {M}.ready()")
        page.wait_for_function(
            "() => document.getElementById('status').textContent === 'connected'"
        )
        # Tab from the page's start reaches the view first; [ and ] cycle the joints round
        page.keyboard.press("Tab")
        assert page.evaluate("document.activeElement.tagName") == "CANVAS"
        assert page.get_attribute(VIEW, "aria-describedby") == "joint-state view-keys"
        assert page.evaluate(f"{M}.selected()") is None
        assert page.is_disabled("#joint-x") and page.is_disabled("#joint-pin")
        press(page, "]")
        assert page.evaluate(f"{M}.selected()") == JOINT_NAMES[0]
        press(page, "[")
        assert page.evaluate(f"{M}.selected()") == JOINT_NAMES[-1]  # round the start
        view_before = page.locator(VIEW).screenshot()
        for _ in range(JOINT_NAMES.index("left_wrist") + 1):
            press(page, "]")
        assert page.evaluate(f"{M}.selected()") == "left_wrist"
        # shown: the picker, the state line, and a ring in the view (the canvas changed)
        assert page.input_value("#joint-pick") == "left_wrist"
        assert page.inner_text("#joint-state").startswith("left_wrist, no target")
        assert page.locator(VIEW).screenshot() != view_before
        assert solves == []  # selecting is no edit

        # each press: the target moved by the step along its axis, the joint on it
        pose0 = page.evaluate(f"{M}.pose()")
        start = pose0["left_wrist"]
        n0 = steps(page)
        press(page, "ArrowRight", then_steps=n0 + 1)
        assert moved_by(start, target(page, "left_wrist"), [STEP, 0, 0])
        assert reached(page, "left_wrist") <= TOLERANCE * 1.01  # exact reach
        assert solves[-1]["targets"] == [
            {"joint": "left_wrist", "position": target(page, "left_wrist"), "weight": 1.0}
        ]
        assert solves[-1]["pose"] == pose0  # from the committed pose, as a drag's
        assert solves[-1]["options"]["reach"] == "exact"
        assert page.input_value("#joint-x") == f"{start[0] + STEP:.3f}"  # the fields follow
        assert page.inner_text("#joint-pick option[value=left_wrist]") == "left_wrist (reached)"
        # the menu shows it whole, and a longer joint's pinned, too (cut at 170 px before;
        # "(target reached, pinned)" at 237 px in DejaVu Sans, Debian's default font)
        for text in ("left_wrist (reached)", "right_shoulder (reached, pinned)"):
            width, room = page.evaluate(FITS, text)
            assert width <= room, (text, width, room)
        assert page.inner_text("#joint-state") == "left_wrist, target reached"
        after_right = target(page, "left_wrist")
        assert after_right is not None
        press(page, "ArrowUp", then_steps=n0 + 2)  # away from the viewer: -Z from the front
        assert moved_by(after_right, target(page, "left_wrist"), [0, 0, -STEP])
        press(page, "Shift+PageUp", then_steps=n0 + 3)  # coarse: 10 steps up
        assert moved_by(after_right, target(page, "left_wrist"), [0, 10 * STEP, -STEP])
        assert reached(page, "left_wrist") <= TOLERANCE * 1.01
        press(page, "Alt+ArrowLeft", then_steps=n0 + 4)  # fine: a tenth, not the browser's Back
        assert page.url.endswith("/editor")
        assert moved_by(after_right, target(page, "left_wrist"), [-STEP / 10, 10 * STEP, -STEP])
        # the step menu
        page.select_option("#nudge-step", "0.05")
        page.focus(VIEW)
        here = target(page, "left_wrist")
        assert here is not None
        press(page, "PageDown", then_steps=n0 + 5)
        assert moved_by(here, target(page, "left_wrist"), [0, -0.05, 0])

        # a key held: its repeats one gesture, one undo step
        here = target(page, "left_wrist")
        assert here is not None
        sent = len(solves)
        for _ in range(5):
            page.keyboard.down("ArrowRight")  # (the second and later: repeats)
        page.keyboard.up("ArrowRight")
        settle(page)
        page.wait_for_function(f"() => {M}.history().index === {n0 + 6}", polling=50)
        assert moved_by(here, target(page, "left_wrist"), [5 * 0.05, 0, 0])
        assert 1 <= len(solves) - sent <= 6  # throttled as a drag's moves
        assert steps(page) == n0 + 6
        held_end = target(page, "left_wrist")

        # undo takes back one press at a time; redo brings them back
        page.keyboard.press("Control+z")
        assert steps(page) == n0 + 5
        assert target(page, "left_wrist") == here
        page.keyboard.press("Control+z")
        assert moved_by(here, target(page, "left_wrist"), [0, 0.05, 0])
        page.keyboard.press("Control+Shift+z")
        page.keyboard.press("Control+y")
        assert steps(page) == n0 + 6
        assert target(page, "left_wrist") == held_end
        for _ in range(6):
            page.keyboard.press("Control+z")
        assert steps(page) == n0
        assert target(page, "left_wrist") is None
        assert page.evaluate(f"{M}.pose()") == pose0

        # Escape during a held nudge: back to before it, no step
        page.keyboard.down("ArrowRight")
        page.keyboard.down("ArrowRight")
        page.keyboard.press("Escape")
        page.keyboard.up("ArrowRight")
        settle(page)
        assert target(page, "left_wrist") is None
        assert steps(page) == n0

        # soft reach: the nudges' solves say so
        page.get_by_label("Exact reach").uncheck()
        page.focus(VIEW)
        press(page, "ArrowDown", then_steps=n0 + 1)
        assert solves[-1]["options"]["reach"] == "soft"
        assert moved_by(start, target(page, "left_wrist"), [0, 0, 0.05])

        # a click on a joint selects it and gives the view the keys
        xy = page.evaluate(f"{M}.projectJoint('right_elbow')")
        page.mouse.click(xy["x"], xy["y"])
        assert page.evaluate(f"{M}.selected()") == "right_elbow"
        elbow = page.evaluate(f"{M}.pose()")["right_elbow"]
        press(page, "PageUp", then_steps=n0 + 2)
        assert moved_by(elbow, target(page, "right_elbow"), [0, 0.05, 0])
        assert page_errors == []
        assert console_errors == [], console_errors
    finally:
        context.close()


@pytest.mark.browser
def test_editor_sets_a_target_typed_pins_and_removes_from_the_keyboard(
    server: str, browser: Any
) -> None:
    page = open_editor(browser, server)
    solves = recorded(page, lambda url: url.endswith("/v1/solve"))
    try:
        select(page, "right_ankle")
        ankle = page.evaluate(f"{M}.pose()")["right_ankle"]
        # no target: the fields show where the joint is
        assert [page.input_value(f"#joint-{a}") for a in "xyz"] == [f"{v:.3f}" for v in ankle]
        n0 = steps(page)

        # a coordinate typed (Enter): the target there, the others the joint's, exactly
        typed_y = f"{ankle[1] + 0.08:.3f}"
        page.fill("#joint-y", typed_y)
        page.press("#joint-y", "Enter")
        settle(page)
        page.wait_for_function(f"() => {M}.history().index === {n0 + 1}", polling=50)
        goal = [ankle[0], float(typed_y), ankle[2]]
        assert target(page, "right_ankle") == pytest.approx(goal, abs=1e-12)
        assert reached(page, "right_ankle") <= TOLERANCE * 1.01
        assert solves[-1]["targets"][0]["position"] == target(page, "right_ankle")
        # another, left by Tab: one more step, the target's other coordinates kept
        page.fill("#joint-x", "0.25")
        page.press("#joint-x", "Tab")
        settle(page)
        page.wait_for_function(f"() => {M}.history().index === {n0 + 2}", polling=50)
        assert target(page, "right_ankle") == pytest.approx([0.25, goal[1], goal[2]], abs=1e-12)
        assert page.evaluate("document.activeElement.id") == "joint-y"  # focus order: x, y, z
        # out of range: refused in the page, marked, nothing sent
        sent = len(solves)
        page.fill("#joint-z", "20000")
        page.press("#joint-z", "Enter")
        assert page.get_attribute("#joint-z", "aria-invalid") == "true"
        assert page.is_visible("#joint-xyz-problem")
        assert "nothing was sent" in page.inner_text("#joint-xyz-problem")
        assert len(solves) == sent
        assert target(page, "right_ankle") == pytest.approx([0.25, goal[1], goal[2]], abs=1e-12)
        page.press("#joint-z", "Escape")  # back to the value shown
        assert page.input_value("#joint-z") == f"{goal[2]:.3f}"
        # undo: the typed values go one at a time
        page.focus(VIEW)
        page.keyboard.press("Control+z")
        assert target(page, "right_ankle") == pytest.approx(goal, abs=1e-12)
        page.keyboard.press("Control+y")
        settle(page)

        # P pins the selected joint (a targeted one: its target dropped, as Shift-click)
        press(page, "p")
        assert page.evaluate(f"{M}.pins()") == ["right_ankle"]
        assert target(page, "right_ankle") is None
        assert page.get_attribute("#joint-pin", "aria-pressed") == "true"
        assert "pinned" in page.inner_text("#joint-state")
        press(page, "P")  # and unpins it
        assert page.evaluate(f"{M}.pins()") == []
        assert page.get_attribute("#joint-pin", "aria-pressed") == "false"
        # the button does the same; a nudge unpins the joint, as a drag does
        page.click("#joint-pin")
        assert page.evaluate(f"{M}.pins()") == ["right_ankle"]
        page.focus(VIEW)
        pinned = steps(page)
        press(page, "ArrowLeft", then_steps=pinned + 1)
        assert page.evaluate(f"{M}.pins()") == []
        assert target(page, "right_ankle") is not None
        # a pin elsewhere goes with the nudges' solves
        select(page, "left_ankle")
        press(page, "p")
        select(page, "right_ankle")
        press(page, "ArrowRight")
        assert solves[-1]["pins"] == ["left_ankle"]

        # Delete removes the selected joint's target (one step); the button too
        before = steps(page)
        press(page, "Delete", then_steps=before + 1)
        assert target(page, "right_ankle") is None
        assert page.is_disabled("#joint-unset")
        press(page, "PageUp")
        assert page.is_enabled("#joint-unset")
        page.click("#joint-unset")
        settle(page)
        assert target(page, "right_ankle") is None
        assert page.evaluate(f"{M}.pins()") == ["left_ankle"]

        # a target out of reach (2 m above the wrist): the picker and the line say how far
        select(page, "right_wrist")
        page.select_option("#nudge-step", "0.1")
        page.focus(VIEW)
        press(page, "Shift+PageUp")
        press(page, "Shift+PageUp")
        error = page.evaluate(f"{M}.lastSolve().response.targets")[0]["error"]
        assert error > 0.5
        off = f"{error * 1000:.1f} mm off"
        assert page.inner_text("#joint-state") == f"right_wrist, target {off}"
        assert page.inner_text("#joint-pick option[value=right_wrist]") == f"right_wrist ({off})"
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_view_keys_do_nothing_while_a_field_is_typed_in(server: str, browser: Any) -> None:
    page = open_editor(browser, server)
    solves = recorded(page, lambda url: url.endswith("/v1/solve"))
    try:
        select(page, "left_wrist")
        press(page, "ArrowRight")  # a step to undo, had Ctrl+Z reached the page
        n = steps(page)
        sent = len(solves)
        targets = page.evaluate(f"{M}.targets()")
        # (no ArrowUp / ArrowDown in a number field: they step its value, a change of its own)
        number_keys = ["]", "[", "p", "P", "ArrowRight", "ArrowLeft"]
        text_keys = [*number_keys, "PageUp", "PageDown", "Delete", "Backspace"]
        page.click("#bvh-map-box summary")
        page.click("#panel details:has(#api-key) summary")
        for field, keys in (
            ("#tolerance", number_keys),
            ("#joint-x", number_keys),
            ("#bvh-map", text_keys),
            ("#api-key", text_keys),
        ):
            page.focus(field)
            for key in keys:
                page.keyboard.press(key)
            page.keyboard.press("Control+z")  # the field's own undo, not the page's
            assert page.evaluate(f"{M}.selected()") == "left_wrist", field
            assert page.evaluate(f"{M}.pins()") == [], field
            assert page.evaluate(f"{M}.targets()") == targets, field
            assert steps(page) == n, field
            if keys is text_keys:  # what was typed, emptied (the key field left as it was)
                page.keyboard.press("Control+a")
                page.keyboard.press("Backspace")
        page.focus("#sample")  # (the fields left: nothing of theirs to take)
        settle(page)
        assert len(solves) == sent
        assert page.evaluate(f"{M}.targets()") == targets
        assert page.evaluate(f"{M}.error()") is None
        # focus order through the joint's part of the panel
        order = []
        page.focus("#joint-pick")
        for _ in range(6):
            page.keyboard.press("Tab")
            order.append(page.evaluate("document.activeElement.id"))
        assert order == ["joint-x", "joint-y", "joint-z", "nudge-step", "joint-pin", "joint-unset"]
        # the joint picker takes its own arrows (the next joint), not the view's
        page.focus("#joint-pick")
        page.keyboard.press("ArrowDown")
        page.wait_for_function(f"() => {M}.selected() === 'right_collar'")
        assert page.evaluate(f"{M}.targets()") == targets
        # and the view's keys are back once it has the focus
        page.focus(VIEW)
        press(page, "]")
        assert page.evaluate(f"{M}.selected()") == "right_shoulder"
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_nudges_a_files_joint_and_waits_while_the_file_is_read(
    server: str, browser: Any
) -> None:
    """A BVH file's handle edited from the keyboard, as one dragged: each nudge a
    ``/v1/bvh/solve``, reached; while the file is read again (other units) the keys and the
    fields edit nothing, as a drag does not, and selecting still works (it is no edit)."""
    text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    page = open_editor(browser, server)
    bvh_solves = recorded(page, lambda url: url.endswith("/v1/bvh/solve"))
    try:
        open_file(page, text, "a.bvh")
        select(page, "left_wrist")
        wrist = page.evaluate(f"{M}.pose()")["left_wrist"]
        n0 = steps(page)
        press(page, "PageUp", then_steps=n0 + 1)
        assert moved_by(wrist, target(page, "left_wrist"), [0, STEP, 0])
        assert [t["joint"] for t in bvh_solves[-1]["targets"]] == ["left_wrist"]
        assert reached(page, "left_wrist") <= TOLERANCE * 1.01
        assert page.evaluate(f"{M}.lastSolve().response.targets[0].reached")
        assert page.evaluate(f"{M}.bvhText()") != text  # the file edited
        press(page, "p")  # a pin on the file (its target dropped)
        assert page.evaluate(f"{M}.pins()") == ["left_wrist"]
        press(page, "p")
        press(page, "ArrowRight", then_steps=n0 + 4)

        # the file read again: editing waits, the keys and the fields with it
        held: list[Any] = []
        page.route("**/v1/bvh/inspect", lambda route: held.append(route))
        page.select_option("#bvh-units", "in")
        page.wait_for_function(
            "() => document.getElementById('status').textContent.includes('editing waits')"
        )
        page.focus(VIEW)
        sent = page.evaluate(f"{M}.solveCount().sent")
        before = (page.evaluate(f"{M}.targets()"), page.evaluate(f"{M}.pins()"), steps(page))
        for key in ("ArrowRight", "PageUp", "Shift+ArrowUp", "p", "Delete"):
            page.keyboard.press(key)
        for control in ("#joint-x", "#joint-y", "#joint-z", "#joint-pin", "#joint-unset"):
            assert page.is_disabled(control), control
        assert (
            page.evaluate(f"{M}.targets()"),
            page.evaluate(f"{M}.pins()"),
            steps(page),
        ) == before
        assert page.evaluate(f"{M}.solveCount().sent") == sent
        page.keyboard.press("]")  # selecting is no edit: it goes on
        assert page.evaluate(f"{M}.selected()") == "right_collar"
        page.wait_for_function(
            "() => document.getElementById('joint-pick').value === 'right_collar'"
        )
        for route in held:
            route.continue_()
        page.unroute("**/v1/bvh/inspect")
        page.wait_for_function(f"() => {M}.bvh().units === 'in'")
        page.wait_for_function("() => !document.getElementById('joint-pin').disabled")

        # read: the keys edit again (the target carried with its joint into the new reading)
        press(page, "[")
        here = target(page, "left_wrist")
        assert here is not None
        press(page, "ArrowLeft")
        assert moved_by(here, target(page, "left_wrist"), [-STEP, 0, 0])
        assert page.evaluate(f"{M}.lastSolve().response.targets[0].reached")
    finally:
        page.context.close()
