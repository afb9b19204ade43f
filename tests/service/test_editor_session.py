"""The browser editor through a session's rough edges (real Chromium, the real server): a
server that never answers a solve, or is busy; the page closed or reloaded with work on it;
the file picker from the keyboard; an empty file; a unit the menu does not list; a
character that walks away as the frames are scrubbed; a frame cut short. Shared parts:
``tests/service/editor_page.py``.
"""

from __future__ import annotations

import json
import re
from typing import Any

import pytest

from tests.service.editor_page import (
    REPO_ROOT,
    STATUS,
    WAIT_MS,
    M,
    drag_joint,
    found,
    gesture,
    give_file,
    open_editor,
    recorded,
    settle,
    tracked,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)


def walking_file() -> str:
    """docs/examples' three-frame file, its root 0, 1.5 and 3 m along X (centimetres): a
    character that walks away from where it was opened."""
    text: str = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    head, _, motion = text.partition("MOTION")
    lines = motion.split("\n")
    for k, i in enumerate(range(3, 6)):  # (the MOTION line's end, Frames:, Frame Time:)
        values = lines[i].split(" ")
        values[0] = f"{150.0 * k:.4f}"
        lines[i] = " ".join(values)
    return head + "MOTION" + "\n".join(lines)


@pytest.mark.browser
def test_editor_goes_on_when_a_solve_is_never_answered(server: str, browser: Any) -> None:
    """A solve the server never answers (a stalled server, a dropped connection a proxy
    holds open) froze editing until the page was reloaded: one solve in flight at a time,
    and that one never came back, so every later drag sent nothing, with no word (the status
    said "connected"). Now a solve is given up after a minute, saying so, and the drag's
    targets are kept to retry; an undo (or any action dropping the gesture) gives up its
    solve at once, so the next drag is solved without waiting for it. And a busy server's
    429 (Retry-After: 2) was asked again at each pointer move; now no solve goes before the
    Retry-After, and the drag's last one goes then. First, a service run with an API key:
    its 401 said "send the API key in the X-API-Key header" while the field sat in the
    closed Connection box, the status said "server not ready", and once the key was typed
    the 401 banner stayed."""
    context = browser.new_context(viewport={"width": 1280, "height": 800}, device_scale_factor=1)
    page = context.new_page()
    page.set_default_timeout(WAIT_MS)
    page.clock.install()  # (time flows; fast_forward jumps it)
    tracked(page)  # (found: the liveness check run on)
    solves = recorded(page, lambda url: url.endswith("/v1/solve"))
    held: list[Any] = []

    def hold_one(route: Any) -> None:  # the solves held are never answered
        if hold["next"] or hold["all"]:
            hold["next"] = False
            held.append(route)
        else:
            route.continue_()

    hold = {"next": True, "all": False}

    def keyed(route: Any) -> None:  # a service run with POSE_API_KEY=sekrit, as it answers
        if route.request.headers.get("x-api-key") == "sekrit":
            route.continue_()
            return
        detail = "send the API key in the X-API-Key header (or Authorization: Bearer <key>)"
        problem = {"title": "Missing or wrong API key", "status": 401, "detail": detail}
        route.fulfill(status=401, content_type="application/problem+json", body=json.dumps(problem))

    try:
        # a service with an API key: the field (in the closed Connection box) is shown and
        # focused, the status and banner say where it goes; typed, the page connects
        page.route("**/v1/**", keyed)
        page.goto(server + "/editor")
        page.wait_for_function(f"() => {M} && {M}.ready()")
        page.wait_for_function(f"() => {STATUS} === 'API key needed'")
        assert page.locator("#api-key").is_visible()
        assert page.evaluate("document.activeElement.id") == "api-key"
        err = page.evaluate(f"{M}.error()")
        assert err["status"] == 401 and "under Connection" in err["detail"], err
        page.keyboard.type("sekrit")
        page.keyboard.press("Tab")
        page.wait_for_function(f"() => {STATUS} === 'connected'")
        page.wait_for_function(f"() => {M}.error() === null")  # (it stayed, stale)
        assert page.locator("#api-key").get_attribute("aria-invalid") != "true"
        page.route("**/v1/solve", hold_one)
        gesture(page, "left_wrist", 30, -40)
        page.wait_for_function(f"() => {M}.solveCount().inflight")
        assert len(held) == 1
        # an undo drops the gesture, and gives up its solve: the next drag goes out
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => !{M}.solveCount().inflight")
        sent = len(solves)
        drag_joint(page, "right_wrist", -30, -40)
        assert len(solves) > sent and "right_wrist" in page.evaluate(f"{M}.targets()")
        assert page.evaluate(f"{M}.error()") is None
        # a drag whose last solve never comes back: given up after a minute, said, retried
        hold["all"] = True
        before = page.evaluate(f"{M}.committedPose()")
        xy = page.evaluate(f"{M}.projectJoint('left_knee')")
        page.mouse.move(xy["x"], xy["y"])
        page.mouse.down()
        page.mouse.move(xy["x"] + 20, xy["y"] - 20)
        page.wait_for_function(f"() => {M}.solveCount().inflight")
        page.mouse.up()
        page.clock.fast_forward(61_000)  # the drag's solve given up; its last one sent
        page.wait_for_function(f"() => {M}.error() !== null")
        err = page.evaluate(f"{M}.error()")
        assert err["title"] == "No answer" and "60 s" in err["detail"], err
        assert "v1/solve" in err["detail"]
        page.wait_for_function(f"() => {M}.solveCount().inflight")
        assert len(held) == 3
        page.route("**/v2/health/live", lambda route: route.abort())  # (not found back yet)
        page.clock.fast_forward(61_000)  # and that one too: the pose as it was
        settle(page)
        assert page.evaluate(f"{M}.pose()") == before  # the pose as it was, targets kept
        assert "left_knee" in page.evaluate(f"{M}.targets()")
        assert "sent again once the server is back" in page.evaluate(f"{M}.error().detail")
        # ("server not answering" said, then "connected" once the server's liveness answers
        # (api.js watch): it is up, only these solves were held; and the drag's edit, sent
        # again then, lands: test_editor_resend.py)
        hold["all"] = False
        page.unroute("**/v2/health/live")
        found(page)
        settle(page)
        assert page.evaluate(f"{M}.committedPose()") != before
        drag_joint(page, "left_knee", 10, -10)  # the next drag is solved, the banner clears
        assert page.evaluate(f"{M}.error()") is None
        assert page.evaluate(STATUS) == "connected"
        assert page.evaluate(f"{M}.lastSolve().request.targets")[0]["joint"] in (
            "right_wrist",
            "left_knee",
        )
        # a busy server (429, Retry-After: 2): no solve before then, the drag's last after
        busy: list[Any] = []

        def too_many(route: Any) -> None:
            busy.append(route.request)
            problem = {"title": "Too many requests", "status": 429, "detail": "busy"}
            route.fulfill(
                status=429,
                content_type="application/problem+json",
                headers={"Retry-After": "2"},
                body=json.dumps(problem),
            )

        page.route("**/v1/solve", too_many)  # (tried before hold_one)
        xy = page.evaluate(f"{M}.projectJoint('right_knee')")
        page.mouse.move(xy["x"], xy["y"])
        page.mouse.down()
        for i in range(1, 9):
            page.mouse.move(xy["x"] - 3 * i, xy["y"] - 3 * i)
            page.wait_for_timeout(40)
        page.mouse.up()
        page.wait_for_function(f"() => {M}.error() !== null")
        page.wait_for_timeout(300)
        assert len(busy) == 1  # (one per pointer move before)
        assert page.evaluate(f"{M}.error()")["status"] == 429
        page.unroute("**/v1/solve", too_many)
        page.clock.fast_forward(2_100)
        settle(page)
        assert page.evaluate(f"{M}.error()") is None  # the drag's last solve went, and landed
        assert "right_knee" in page.evaluate(f"{M}.targets()")
        assert page.evaluate(f"{M}.lastSolve().response.targets")[-1]["reached"]
        # the drag's last solve refused again after its wait: it snapped back, the targets
        # kept, and nothing was sent again; now it is sent again once the wait is over
        refused = [2]  # (a solve of the drag's, then its last one, after the wait)

        def busy_for(route: Any) -> None:
            if refused[0] <= 0:
                route.continue_()
                return
            refused[0] -= 1
            too_many(route)

        page.route("**/v1/solve", busy_for)
        detail = f"{M}.error() && {M}.error().detail"
        before = page.evaluate(f"{M}.committedPose()")
        xy = page.evaluate(f"{M}.projectJoint('left_elbow')")
        page.mouse.move(xy["x"], xy["y"])
        page.mouse.down()
        page.mouse.move(xy["x"] + 25, xy["y"] - 25)
        page.wait_for_function(f"() => {M}.error() !== null")  # (a solve of the drag's)
        page.mouse.up()
        page.clock.fast_forward(2_100)
        page.wait_for_function(f"() => ({detail} || '').includes('sent again in 2 s (try 2 of 4)')")
        assert page.evaluate(f"{M}.solveCount().dirty")  # (waiting to be sent again)
        page.clock.fast_forward(2_100)
        page.wait_for_function(f"() => {M}.error() === null")
        settle(page)
        assert page.evaluate(f"{M}.lastSolve().request.targets")[-1]["joint"] == "left_elbow"
        assert page.evaluate(f"{M}.committedPose()") != before  # the edit landed
        assert page.evaluate(f"{M}.pose()") == page.evaluate(f"{M}.committedPose()")
        # a server busy for good: the last solve sent 4 times, then given up, said plainly
        refused[0] = 1_000
        before = page.evaluate(f"{M}.committedPose()")
        steps = page.evaluate(f"{M}.history()")
        xy = page.evaluate(f"{M}.projectJoint('right_elbow')")
        page.mouse.move(xy["x"], xy["y"])
        page.mouse.down()
        page.mouse.move(xy["x"] - 25, xy["y"] - 25)
        page.wait_for_function(f"() => {M}.error() !== null")
        page.mouse.up()
        tried = "(d => d.includes('still busy') ? 9 : Number((/try (\\d) of 4/.exec(d) || [])[1]))"
        for k in (2, 3, 4):  # (or a later try: the clock runs on by itself too)
            page.clock.fast_forward(2_100)
            page.wait_for_function(f"() => {tried}({detail} || '') >= {k}")
        page.clock.fast_forward(2_100)
        page.wait_for_function(f"() => ({detail} || '').includes('still busy after 4 tries')")
        sent = refused[0]
        page.clock.fast_forward(5_000)
        page.wait_for_timeout(300)
        assert refused[0] == sent  # (no more)
        assert page.evaluate(f"{M}.pose()") == before  # as before the drag, its target kept
        assert "right_elbow" in page.evaluate(f"{M}.targets()")
        assert "drag again to retry" in page.evaluate(detail)
        # the banner belongs to that edit: undone, it goes (it stayed over the state before)
        page.keyboard.press("Control+z")
        page.wait_for_function(f"() => {M}.history().index === {steps['index']}")
        assert "right_elbow" not in page.evaluate(f"{M}.targets()")
        assert page.evaluate(f"{M}.error()") is None
        page.unroute("**/v1/solve", busy_for)
        # a server gone, then back: the status said "server unreachable" until the next
        # request; now the page asks the server's liveness meanwhile, and says it is back
        page.route("**/v1/solve", lambda route: route.abort())
        page.route("**/v2/health/live", lambda route: route.abort())  # (gone until read)
        drag_joint(page, "left_knee", 10, 10)
        assert page.evaluate(STATUS) == "server unreachable"
        page.unroute("**/v1/solve")
        page.unroute("**/v2/health/live")
        page.clock.fast_forward(3_100)
        page.wait_for_function(f"() => {STATUS} === 'connected'")
    finally:
        context.close()


@pytest.mark.browser
def test_editor_keyboard_empty_file_scrub_follows_and_unload_asks(
    server: str, browser: Any
) -> None:
    """Defects of one session: "Open BVH…" was a label no Tab reached (a keyboard user
    could not open a file); an empty file was sent and refused as "bvh: String should have
    at least 1 character"; a character that walks (its root 3 m along) left the view as the
    frames were scrubbed, the camera staying where the file opened (and once it followed,
    off the floor's 4 m grid, standing on nothing); closing or reloading
    the page dropped a file's edits (and pins, targets) without a word, though every other
    way of dropping them asks first. And: a file in a unit the Units menu did not list
    (decimetres) could not be opened (now "other…" asks for metres per unit); a frame cut
    short (no pose) grabbed a press anywhere, and the view could not be orbited there; a
    420 px window left the view 120 px wide beside the panel, the figure cut; a change of
    the screen's pixel density (a zoom) left the view drawn at the ratio it started with."""
    page = open_editor(browser, server)
    context = page.context
    try:
        inspects = recorded(page, lambda url: url.endswith("/v1/bvh/inspect"))
        # a narrow window (420 px): the whole figure in the view, the panel clear of it
        page.set_viewport_size({"width": 420, "height": 800})
        page.wait_for_timeout(200)  # (the view's ResizeObserver)
        box = page.locator("#viewport").bounding_box()
        panel = page.locator("#panel").bounding_box()
        assert box is not None and panel is not None
        for joint in page.evaluate(f"{M}.joints()"):
            xy = page.evaluate(f"{M}.projectJoint('{joint}')")
            assert box["x"] < xy["x"] < box["x"] + box["width"], (joint, xy, box)
            assert box["y"] < xy["y"] < box["y"] + box["height"], (joint, xy, box)
        assert (
            panel["y"] >= box["y"] + box["height"] - 1 or panel["x"] >= box["x"] + box["width"] - 1
        )
        page.set_viewport_size({"width": 1280, "height": 800})
        page.wait_for_timeout(200)
        # the screen's density changed (the browser zoomed, the window moved to a HiDPI
        # screen): the view drawn at the new ratio (it kept the first: stretched, blurred)
        cdp = context.new_cdp_session(page)
        metrics = {"width": 1280, "height": 800, "mobile": False}
        cdp.send("Emulation.setDeviceMetricsOverride", {**metrics, "deviceScaleFactor": 2})
        scaled = "r => (c => c.width === r * c.clientWidth && c.height === r * c.clientHeight)"
        scaled += "(document.querySelector('#viewport canvas'))"
        page.wait_for_function(scaled, arg=2)
        cdp.send("Emulation.setDeviceMetricsOverride", {**metrics, "deviceScaleFactor": 1})
        page.wait_for_function(scaled, arg=1)
        # the file picker from the keyboard: Tab reaches "Open BVH…", Enter opens it
        page.focus("#sample")
        for _ in range(3):
            page.keyboard.press("Tab")
            if page.evaluate("document.activeElement.id") == "bvh-open":
                break
        assert page.evaluate("document.activeElement.id") == "bvh-open"
        page.evaluate(  # (the chooser itself not opened: a headless one came and went)
            """() => document.getElementById('bvh-file').addEventListener('click', (ev) => {
                 window.chooserAsked = true;
                 ev.preventDefault();
               }, { once: true })"""
        )
        page.keyboard.press("Enter")
        page.wait_for_function("() => window.chooserAsked === true")
        give_file(page, "", "empty.bvh")
        # an empty file: said in the page, nothing sent
        page.wait_for_function(f"() => {M}.error() !== null")
        err = page.evaluate(f"{M}.error()")
        assert err["title"] == "Empty file" and "empty.bvh" in err["detail"], err
        assert inspects == []
        # an Acclaim ASF or AMC file (by its name, or by its first keyword): said plainly that
        # the editor reads BVH only, and how to convert it (it was sent, and refused as "not a
        # BVH file (no HIERARCHY keyword)"); nothing sent
        asf = "# AST/ASF file generated using VICON BodyLanguage\n:version 1.10\n:name VICON\n"
        amc = "#!OML:ASF F:\\VICON\\USERDATA\\07.asf\n:FULLY-SPECIFIED\n:DEGREES\n1\n"
        for body, name in ((asf, "07.asf"), (amc, "07_01.txt"), ("1\nroot 0 0 0\n", "07_01.AMC")):
            page.evaluate(f"{M}.error() && document.getElementById('error-close').click()")
            give_file(page, body, name)
            page.wait_for_function(f"() => {M}.error() !== null")
            err = page.evaluate(f"{M}.error()")
            assert err["title"] == "Not a BVH file" and err["detail"].startswith(name), err
            assert "ASF/AMC file" in err["detail"] and "reads BVH only" in err["detail"], err
            assert "Convert the pair to one BVH file" in err["detail"], err
        assert inspects == []
        # a walking character scrubbed: each frame's pelvis in the view
        give_file(page, walking_file(), "walk.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'walk.bvh'")
        width = page.evaluate("document.getElementById('viewport').clientWidth")
        for frame in (1, 2, 0, 2):
            page.locator("#bvh-frame").fill(str(frame))
            page.wait_for_function(f"() => {M}.bvh().frame === {frame}")
            x = page.evaluate(f"{M}.projectJoint('pelvis').x")
            assert 0.25 * width < x < 0.75 * width, (frame, x, width)
            # and the floor (a 4 m grid) under it, its lines where they were (0.25 m cells)
            pelvis = page.evaluate(f"{M}.pose().pelvis")
            floor = page.evaluate(f"{M}.floor()")
            assert abs(floor[0] - pelvis[0]) <= 0.125 + 1e-9, (frame, floor, pelvis)
            assert abs(floor[2] - pelvis[2]) <= 0.125 + 1e-9, (frame, floor, pelvis)
            assert all(abs(v / 0.25 - round(v / 0.25)) < 1e-9 for v in floor), floor
        # a file in decimetres: no unit of the menu fits; "other…" asks for metres per unit
        head, _, motion = walking_file().partition("MOTION")
        head = re.sub(
            r"OFFSET\s+(\S+)\s+(\S+)\s+(\S+)",
            lambda m: "OFFSET " + " ".join(f"{float(v) / 10:.4f}" for v in m.groups()),
            head,
        )
        rows = motion.split("\n")
        for i in range(3, 6):  # (the root's position: the first three values)
            values = rows[i].split(" ")
            values[:3] = [f"{float(v) / 10:.4f}" for v in values[:3]]
            rows[i] = " ".join(values)
        give_file(page, head + "MOTION" + "\n".join(rows), "dm.bvh")
        page.wait_for_function(f"() => {M}.error() !== null && {M}.error().status === 422")
        assert "state them" in page.evaluate(f"{M}.error()")["detail"]
        sent = len(inspects)
        page.once("dialog", lambda d: d.accept("abc"))
        page.select_option("#bvh-units", "other")
        assert page.evaluate(f"{M}.error()")["title"] == "Units"
        assert page.locator("#bvh-units").input_value() == "auto" and len(inspects) == sent
        page.once("dialog", lambda d: d.accept("0.1"))
        page.select_option("#bvh-units", "other")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'dm.bvh'")
        assert inspects[-1]["units"] == 0.1 and page.evaluate(f"{M}.bvh().units") == 0.1
        assert page.locator("#bvh-units").input_value() == "0.1"
        # the same cut short in its last frame: at that frame (no pose to draw) a press on
        # empty space grabbed a joint whose place is NaN (every distance test failed
        # open), and the view could not be orbited; now it orbits, grabbing nothing
        walk = walking_file().rstrip("\n")
        give_file(page, walk[: walk.rindex(" ", 0, len(walk) - 40)] + "\n", "cut.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'cut.bvh'")
        page.locator("#bvh-frame").fill("2")
        page.wait_for_function(f"() => {M}.bvh().frame === 2")
        view = page.evaluate(f"{M}.projectPoint([0, 1, 0])")
        page.mouse.move(60, 500)
        assert page.evaluate("document.getElementById('hud').hidden")
        page.mouse.down()
        page.mouse.move(160, 530, steps=5)
        page.mouse.up()
        assert page.evaluate(f"{M}.projectPoint([0, 1, 0])") != view  # orbited
        assert page.evaluate(f"{M}.targets()") == {}
        page.locator("#bvh-frame").fill("1")
        page.wait_for_function(f"() => {M}.bvh().frame === 1")
        # closing the page with a file's edits asks; a pristine one closes unasked
        dialogs: list[str] = []
        page.on("dialog", lambda d: (dialogs.append(d.type), d.dismiss()))
        drag_joint(page, "left_wrist", 30, -40)
        assert page.evaluate(f"{M}.bvh().edited")
        with page.expect_event("dialog"):
            page.close(run_before_unload=True)
        page.wait_for_timeout(200)
        assert dialogs == ["beforeunload"]
        assert not page.is_closed()  # dismissed: the page and its edits stay
        page.click("#reset")
        settle(page)
        assert not page.evaluate(f"{M}.bvh().edited")
        with page.expect_event("close"):
            page.close(run_before_unload=True)
        assert dialogs == ["beforeunload"]  # nothing to lose: closed unasked
    finally:
        context.close()


@pytest.mark.browser
def test_editor_says_connected_once_the_models_answer(server: str, browser: Any) -> None:
    """The models loading (``GET v1/models``: 503), the skeleton answering: the status said
    "connected", then "server not ready" at the models' 503, at each retry. Now "connected"
    only once the models answer too."""
    context = browser.new_context(viewport={"width": 1280, "height": 800})
    page = context.new_page()
    page.set_default_timeout(WAIT_MS)
    loading = [True]  # (the first answer: 503)

    def models(route: Any) -> None:
        if not loading:
            route.continue_()
            return
        loading.clear()
        problem = {"title": "Service Unavailable", "status": 503, "detail": "loading models"}
        route.fulfill(status=503, content_type="application/problem+json", body=json.dumps(problem))

    try:
        page.route("**/v1/models", models)
        page.add_init_script(
            "window.said = []; new MutationObserver(() => { const s = document.getElementById"
            "('status'); if (s && s.textContent !== said.at(-1)) said.push(s.textContent); })"
            ".observe(document, { subtree: true, childList: true, characterData: true });"
        )
        page.goto(server + "/editor")
        page.wait_for_function(f"() => {STATUS} === 'connected'")
        said = page.evaluate("said")
        assert said[-2:] == ["server not ready", "connected"] and said.count("connected") == 1, said
    finally:
        context.close()
