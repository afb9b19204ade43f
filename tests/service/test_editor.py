"""The browser editor, end to end: the page's files served (no browser), and in a real
headless Chromium (the real server, Playwright) a sample pose dragged, solved by both methods,
undone, exported; API errors shown; the nearest joint picked.

The server, the browser and the helpers are in ``tests/service/editor_page.py`` (Chromium:
how it is found, and the test skipped without one). ``$MARIONETTE_SCREENSHOT`` names where
the screenshot goes (default: the test's temp folder); ``docs/img/editor.png`` is made that
way. Users' files: ``test_editor_files.py``; editing a file (scrub, undo, in step):
``test_editor_edits.py``.
"""

from __future__ import annotations

import json
import math
import os
import re
from math import dist
from pathlib import Path
from typing import Any

import pytest

from core.skeleton import JOINT_NAMES
from tests.service.editor_page import (
    REPO_ROOT,
    M,
    drag_joint,
    give_file,
    open_editor,
    post_json,
    recorded,
    settle,
    watched_page,
)

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)


# -- without a browser: the files are there and served ------------------------------------
STATIC = REPO_ROOT / "service" / "static"
# The page's own modules: the entry editor.js, bvh.js and the editor's modules in editor/.
EDITOR_JS = [STATIC / "editor.js", STATIC / "bvh.js", *sorted((STATIC / "editor").glob("*.js"))]
RELATIVE_IMPORT = re.compile(r"^import [^;]*? from '(\.{1,2}/[^']+)';", re.M)


def test_editor_routes_serve_the_page_and_vendored_three() -> None:
    from fastapi import FastAPI
    from fastapi.testclient import TestClient

    from service.editor import mount_editor

    app = FastAPI()
    mount_editor(app)
    c = TestClient(app)
    page = c.get("/editor")
    assert page.status_code == 200
    assert page.headers["content-type"].startswith("text/html")
    assert 'src="static/editor.js"' in page.text
    assert "http://" not in page.text  # no CDN: everything comes from /static
    assert "https://" not in page.text
    assert len(EDITOR_JS) > 2  # the editor's modules are there
    for path in (
        *(f"/static/{js.relative_to(STATIC).as_posix()}" for js in EDITOR_JS),
        "/static/vendor/three/three.module.js",
        "/static/vendor/three/three.core.js",
        "/static/vendor/three/addons/controls/OrbitControls.js",
    ):
        r = c.get(path)
        assert r.status_code == 200, path
        assert "javascript" in r.headers["content-type"], (path, r.headers["content-type"])
    assert c.get("/static/editor.css").headers["content-type"].startswith("text/css")
    assert c.get("/static/nope.js").status_code == 404


def test_vendored_three_is_pinned_and_licensed() -> None:
    vendor = STATIC / "vendor" / "three"
    assert "MIT License" in (vendor / "LICENSE").read_text()
    version = (vendor / "VERSION").read_text().split()[0]
    assert version.startswith("three@0.")
    revision = version.removeprefix("three@0.").split(".")[0]
    assert f"REVISION = '{revision}'" in (vendor / "three.core.js").read_text()
    # offline: no module is fetched from anywhere but the vendored files
    for js in (*EDITOR_JS, vendor / "addons" / "controls" / "OrbitControls.js"):
        text = js.read_text()
        assert "from 'http" not in text, js
        assert 'from "http' not in text, js
    # ... and every relative import of the page's modules names one of its files
    imports = [(js, spec) for js in EDITOR_JS for spec in RELATIVE_IMPORT.findall(js.read_text())]
    assert len(imports) >= len(EDITOR_JS)
    for js, spec in imports:
        assert (js.parent / spec).resolve().is_file(), (js, spec)


def test_sample_poses_are_small_complete_and_from_the_test_split() -> None:
    doc = json.loads((STATIC / "samples.json").read_text())
    assert (STATIC / "samples.json").stat().st_size < 50_000
    samples = doc["samples"]
    assert 5 <= len(samples) <= 8
    assert len({s["name"] for s in samples}) == len(samples)
    for s in samples:
        assert set(s["pose"]) == set(JOINT_NAMES), s["name"]
        assert all(len(v) == 3 and all(math.isfinite(x) for x in v) for v in s["pose"].values())
        pelvis = s["pose"]["pelvis"]
        assert abs(pelvis[0]) < 1e-6, s["name"]
        assert abs(pelvis[2]) < 1e-6, s["name"]
        lowest = min(v[1] for v in s["pose"].values())
        assert -0.05 < lowest < 0.5, s["name"]  # on (or just above) the floor
    dataset = REPO_ROOT / "data" / "poses.npz"
    if dataset.is_file():
        from trainer.data.dataset import load_dataset

        ds = load_dataset(dataset)
        split = dict(zip(ds.clip_name.tolist(), ds.clip_split.tolist(), strict=True))
        for s in samples:
            assert split.get(s["clip"]) == "test", s["clip"]


# -- in the browser -------------------------------------------------------------------------
@pytest.mark.browser
def test_editor_drag_solve_fabrik_errors(server: str, browser: Any, tmp_path: Path) -> None:
    context, page, console_errors, page_errors, urls, solves = watched_page(browser, "/v1/solve")
    m = "window.marionette"

    try:
        # -- the page: / redirects to /editor, the skeleton comes from the samples ----------
        page.goto(server + "/")
        assert page.url == server + "/editor"
        page.wait_for_function(f"() => {m} && {m}.ready()")
        page.wait_for_function(
            "() => document.getElementById('status').textContent === 'connected'"
        )
        pose0 = page.evaluate(f"{m}.pose()")
        assert set(pose0) == set(JOINT_NAMES)
        assert page.evaluate(f"{m}.lastSolve()") is None

        # -- pin both ankles (shift-click) ------------------------------------------------
        for ankle in ("left_ankle", "right_ankle"):
            xy = page.evaluate(f"{m}.projectJoint('{ankle}')")
            page.keyboard.down("Shift")
            page.mouse.click(xy["x"], xy["y"])
            page.keyboard.up("Shift")
        assert sorted(page.evaluate(f"{m}.pins()")) == ["left_ankle", "right_ankle"]
        assert solves == []  # no target yet: nothing to solve

        # -- drag the left wrist up and outwards with the mouse --------------------------
        before_png = page.locator("#viewport canvas").screenshot()
        wrist = page.evaluate(f"{m}.projectJoint('left_wrist')")
        end = (wrist["x"] + 70, wrist["y"] - 160)
        page.mouse.move(wrist["x"], wrist["y"])
        page.mouse.down()
        for i in range(1, 13):
            t = i / 12
            page.mouse.move(wrist["x"] + t * 70, wrist["y"] - t * 160)
            page.wait_for_timeout(16)
        page.mouse.up()
        settle(page)

        assert solves, "dragging sent no /v1/solve"
        first = solves[0]
        assert [t["joint"] for t in first["targets"]] == ["left_wrist"]
        assert sorted(first["pins"]) == ["left_ankle", "right_ankle"]
        assert first["options"]["method"] == "neural"
        assert set(first["pose"]) == set(JOINT_NAMES)
        # throttled: one request per frame at most, never more than the pointer moves
        assert len(solves) <= 13

        last = page.evaluate(f"{m}.lastSolve()")
        assert last is not None
        assert last["response"]["method"] == "neural"
        assert last["serverTime"].endswith("ms")
        target = page.evaluate(f"{m}.targets()")["left_wrist"]
        on_screen = page.evaluate(f"{m}.projectPoint({json.dumps(target)})")
        assert abs(on_screen["x"] - end[0]) < 2
        assert abs(on_screen["y"] - end[1]) < 2
        pose1 = page.evaluate(f"{m}.pose()")
        assert pose1 == last["response"]["pose"]  # the drawn pose is the server's answer
        assert dist(pose1["left_wrist"], pose0["left_wrist"]) > 0.1
        assert pose1["left_wrist"][1] > pose0["left_wrist"][1] + 0.1  # it went up
        after_png = page.locator("#viewport canvas").screenshot()
        assert after_png != before_png, "the canvas did not change"
        # the panel shows the latency and the target's reach error
        assert page.locator("#latency").inner_text().endswith(")")
        assert "ms" in page.locator("#latency").inner_text()
        row = page.locator("#targets tbody tr[data-joint=left_wrist]")
        assert "mm" in row.inner_text()
        assert page.evaluate(f"{m}.history()") == {"length": 4, "index": 3}

        # -- FABRIK --------------------------------------------------------------------------
        n = len(solves)
        page.locator(".segmented label", has_text="FABRIK").click()  # as a user does
        settle(page)
        assert len(solves) == n + 1
        assert solves[-1]["options"]["method"] == "fabrik"
        last = page.evaluate(f"{m}.lastSolve()")
        assert last["response"]["method"] == "fabrik"
        assert "fabrik" in page.locator("#solve-method").inner_text()
        pose2 = page.evaluate(f"{m}.pose()")
        # FABRIK reaches a reachable target and holds the pins where its input had them
        # (its input is the committed pose: the neural answer to the drag)
        assert last["request"]["pose"] == pose1
        assert last["response"]["targets"][0]["error"] < 0.01
        for ankle in ("left_ankle", "right_ankle"):
            assert dist(pose2[ankle], pose1[ankle]) < 1e-3

        # -- undo / redo, export -------------------------------------------------------------
        page.click("#undo")
        assert page.evaluate(f"{m}.pose()") == pose1
        page.click("#redo")
        assert page.evaluate(f"{m}.pose()") == pose2
        with page.expect_download() as dl:
            page.click("#export")
        exported = json.loads(Path(dl.value.path()).read_text())
        assert exported["pose"] == pose2
        assert exported["options"]["method"] == "fabrik"
        assert [t["joint"] for t in exported["targets"]] == ["left_wrist"]

        shot = Path(os.environ.get("MARIONETTE_SCREENSHOT", tmp_path / "editor.png"))
        shot.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(shot))
        assert shot.stat().st_size > 10_000

        assert page_errors == []
        assert console_errors == [], console_errors
        # offline: nothing but the service itself (and the download's blob:) was fetched
        assert all(u.startswith((server + "/", "blob:", "data:")) for u in urls), urls

        # -- API errors are shown: a bad tolerance is the server's 422 ----------------------
        # (the page refuses one typed: test_editor_refuses_out_of_range_options_in_the_page;
        # here the request is altered on its way, to the real service)
        def zero_tolerance(route: Any) -> None:
            body = json.loads(route.request.post_data or "{}")
            body["options"]["tolerance"] = 0
            route.continue_(post_data=json.dumps(body))

        page.route("**/v1/solve", zero_tolerance)
        page.fill("#tolerance", "0.002")
        page.press("#tolerance", "Tab")
        page.wait_for_function(f"() => {m}.error() !== null")
        page.unroute("**/v1/solve")
        err = page.evaluate(f"{m}.error()")
        assert err["status"] == 422, err
        assert "tolerance" in err["detail"], err
        banner = page.locator("#error")
        assert banner.is_visible()
        assert "422" in banner.inner_text()
        assert "tolerance" in banner.inner_text()
        assert page.evaluate(f"{m}.pose()") == pose2  # the failed solve changed nothing
        page.fill("#tolerance", "0.001")
        page.press("#tolerance", "Tab")
        page.wait_for_function(f"() => {m}.error() === null")
        assert not banner.is_visible()

        # -- ... and so is an unreachable server ----------------------------------------
        page.route("**/v1/solve", lambda route: route.abort())
        page.get_by_label("Exact reach").uncheck()  # on by default (issue 11)
        page.wait_for_function(f"() => {m}.error() !== null")
        assert page.evaluate(f"{m}.error()")["status"] == 0
        assert "unreachable" in banner.inner_text()
        page.unroute("**/v1/solve")

        # -- the branch carry: the models' default until the slider moves ----------------
        page.locator(".segmented label", has_text="Neural").click()
        page.wait_for_function(f"() => {m}.error() === null")
        settle(page)
        assert "carry" not in solves[-1]["options"]
        assert "models' default" in page.locator("#carry-label").inner_text()
        assert page.locator("#carry").input_value() == "0.5"  # GET /v1/models says so
        page.locator("#carry").fill("1")
        settle(page)
        assert solves[-1]["options"]["carry"] == 1
        last = page.evaluate(f"{m}.lastSolve()")
        direct = post_json(server + "/v1/solve", last["request"])
        assert direct["pose"] == last["response"]["pose"]

        # -- the turn search: the models' default until unchecked ------------------------
        assert "turn_search" not in solves[-1]["options"]
        page.get_by_label("Search the body's turn").uncheck()
        settle(page)
        assert solves[-1]["options"]["turn_search"] is False

        # Only the browser's own log lines of the two forced failures.
        assert page_errors == []
        unexpected = [e for e in console_errors if not e.startswith("Failed to load resource")]
        assert unexpected == [], unexpected
    finally:
        context.close()


def hovered(page: Any, x: float, y: float) -> str | None:
    """What the pointer at (x, y) would grab: the hover label's text, or None."""
    page.mouse.move(x - 3, y)
    page.mouse.move(x, y)
    hud = page.locator("#hud")
    return str(hud.inner_text()) if hud.is_visible() else None


@pytest.mark.browser
def test_editor_picks_the_nearest_joint_fairly(server: str, browser: Any) -> None:
    """The head's picking bias (10 px) won over the neck: in the 'bow' sample the neck is
    8 px from the head on screen and could not be grabbed at all, even with the pointer
    on it; elsewhere a pointer 40% of the way from the neck to the head took the head. Now
    the nearest joint wins, and the head is still grabbed anywhere on its (larger) sphere."""
    page = open_editor(browser, server)
    try:
        names = page.locator("#sample option").all_inner_texts()
        for name in names:
            page.select_option("#sample", label=name)
            neck = page.evaluate(f"{M}.projectJoint('neck')")
            head = page.evaluate(f"{M}.projectJoint('head')")
            assert hovered(page, neck["x"], neck["y"]) == "neck", name
            near = (
                neck["x"] + 0.4 * (head["x"] - neck["x"]),
                neck["y"] + 0.4 * (head["y"] - neck["y"]),
            )
            assert hovered(page, *near) == "neck", name
            assert hovered(page, head["x"], head["y"]) == "head", name
            # 6 cm above the head's centre: on its 7.5 cm sphere, beyond PICK_PIXELS
            pose = page.evaluate(f"{M}.pose()")
            top = [pose["head"][0], pose["head"][1] + 0.06, pose["head"][2]]
            on = page.evaluate(f"{M}.projectPoint({json.dumps(top)})")
            assert math.dist((on["x"], on["y"]), (head["x"], head["y"])) > 18
            assert hovered(page, on["x"], on["y"]) == "head", name
        # ... and the bow's neck is dragged, not its head
        page.select_option("#sample", label=next(n for n in names if n.endswith("bow")))
        drag_joint(page, "neck", 0, -40)
        assert list(page.evaluate(f"{M}.targets()")) == ["neck"]
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_undo_across_a_sample_change_restores_that_sample(server: str, browser: Any) -> None:
    """An editor audit: the sample shown was not part of an undo step, so undoing a Sample
    change brought back the edited pose of the sample before while the menu, Export's
    ``sample`` and Reset still named (and went back to) the newer sample. Now undo and redo
    restore the sample with the step: menu, export and Reset agree with the pose."""
    samples = json.loads((STATIC / "samples.json").read_text())["samples"]
    page = open_editor(browser, server)
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))

    def shows(i: int) -> None:
        assert page.locator("#sample").input_value() == str(i)
        assert page.evaluate(f"{M}.exportDocument()")["sample"] == samples[i]["name"]

    def is_sample(i: int) -> bool:
        pose = page.evaluate(f"{M}.pose()")
        return all(dist(pose[j], samples[i]["pose"][j]) < 1e-9 for j in JOINT_NAMES)

    try:
        shows(0)
        drag_joint(page, "left_wrist", 40, -60)
        edited = page.evaluate(f"{M}.pose()")
        assert not is_sample(0)
        page.once("dialog", lambda d: d.accept())  # (the edits dropped: asked first)
        page.select_option("#sample", index=3)
        assert is_sample(3)
        shows(3)

        page.click("#undo")  # the edit on sample 0: its name, not sample 3's
        assert page.evaluate(f"{M}.pose()") == edited
        shows(0)
        page.click("#redo")
        assert is_sample(3)
        shows(3)
        page.click("#undo")
        shows(0)
        page.click("#reset")  # back to the sample shown (was: sample 3)
        assert is_sample(0)
        shows(0)
        page.click("#undo")  # before the reset: the edit, on sample 0
        assert page.evaluate(f"{M}.pose()") == edited
        shows(0)
        assert not errors, errors
    finally:
        page.context.close()


@pytest.mark.browser
def test_editor_sends_soft_ik_in_metres_and_re_solves_when_it_changes(
    server: str, browser: Any
) -> None:
    """The Soft IK field (cm; 0 = off) is ``options.soft_ik`` in metres on every solve the
    page sends (a drag's, an option's re-solve, a file's ``/v1/bvh/solve``), absent when 0;
    changing it re-solves the current targets once; FABRIK's solves carry it too (the
    service ignores it there)."""
    context, page, console_errors, page_errors, _, solves = watched_page(browser, "/v1/solve")
    bvh_solves = recorded(page, lambda url: url.endswith("/v1/bvh/solve"))

    def set_soft_ik(cm: str) -> None:
        field.fill(cm)
        field.press("Tab")  # a number field's change: on leaving it, as a user does
        settle(page)

    try:
        page.goto(server + "/editor")
        page.wait_for_function(f"() => {M} && {M}.ready()")
        page.wait_for_function(
            "() => document.getElementById('status').textContent === 'connected'"
        )
        field = page.get_by_label("Soft IK (cm)")
        assert field.input_value() == "0"  # off by default, as the service

        # -- off: a drag's solves carry no soft_ik ---------------------------------------
        drag_joint(page, "left_wrist", 60, -90)
        assert solves, "dragging sent no /v1/solve"
        assert all(s["options"].get("soft_ik", 0) == 0 for s in solves)
        assert "soft_ik" not in page.evaluate(f"{M}.options()")

        # -- 1 cm: the current targets re-solved once, with 0.01 m -----------------------
        n = len(solves)
        set_soft_ik("1")
        assert len(solves) == n + 1, "changing Soft IK did not re-solve"
        assert solves[-1]["options"]["soft_ik"] == 0.01
        assert [t["joint"] for t in solves[-1]["targets"]] == ["left_wrist"]
        last = page.evaluate(f"{M}.lastSolve()")
        assert last["request"]["options"]["soft_ik"] == 0.01
        assert page.evaluate(f"{M}.error()") is None
        # the pose drawn is the service's answer to that request
        assert post_json(server + "/v1/solve", last["request"])["pose"] == page.evaluate(
            f"{M}.pose()"
        )

        # -- a drag with it on: every solve of the gesture carries it ---------------------
        n = len(solves)
        drag_joint(page, "right_wrist", -60, -90)
        assert len(solves) > n
        assert all(s["options"]["soft_ik"] == 0.01 for s in solves[n:])
        assert page.evaluate(f"{M}.exportDocument()")["options"]["soft_ik"] == 0.01

        # -- FABRIK: sent as well, ignored by the service (no error) ----------------------
        page.locator(".segmented label", has_text="FABRIK").click()
        settle(page)
        assert solves[-1]["options"]["method"] == "fabrik"
        assert solves[-1]["options"]["soft_ik"] == 0.01
        assert page.evaluate(f"{M}.error()") is None
        page.locator(".segmented label", has_text="Neural").click()
        settle(page)

        # -- (out of range: refused in the page, test_editor_refuses_out_of_range_options_
        # in_the_page); 0 puts it off -----------------------------------------------------
        n = len(solves)
        set_soft_ik("0")
        assert len(solves) == n + 1
        assert "soft_ik" not in solves[-1]["options"]

        # -- 0.5 cm, then a file: its /v1/bvh/solve requests carry 0.005 m ---------------
        n = len(solves)
        set_soft_ik("0.5")
        assert len(solves) == n + 1
        assert solves[-1]["options"]["soft_ik"] == 0.005
        text = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
        asked: list[str] = []  # the sample's edited pose dropped: asked first, "yes"

        def yes(dialog: Any) -> None:
            asked.append(dialog.message)
            dialog.accept()

        page.once("dialog", yes)
        give_file(page, text, "three.bvh")
        page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === 'three.bvh'")
        assert len(asked) == 1 and asked[0].startswith("Open three.bvh? This drops"), asked
        drag_joint(page, "left_wrist", 40, -60)
        assert bvh_solves, "dragging the file's wrist sent no /v1/bvh/solve"
        assert all(s["options"]["soft_ik"] == 0.005 for s in bvh_solves)
        n = len(bvh_solves)
        set_soft_ik("2")  # ... and a change re-solves the file's target
        assert len(bvh_solves) == n + 1
        assert bvh_solves[-1]["options"]["soft_ik"] == 0.02
        assert page.evaluate(f"{M}.error()") is None

        assert page_errors == []
        assert console_errors == [], console_errors
    finally:
        context.close()


@pytest.mark.browser
def test_editor_refuses_out_of_range_options_in_the_page(server: str, browser: Any) -> None:
    """Found by an editor review: Tolerance (m) and Soft IK (cm) were sent as typed, so a
    value out of the service's range (tolerance 1e-6 to 1 m, soft IK 0 to 10 cm) made every
    solve fail with its 422 until mended. Now the page refuses it at once: the field is
    marked invalid and says the range, nothing is sent for it, and the solves (a drag's,
    an option's re-solve) keep the last valid value until the field is mended."""
    context, page, console_errors, page_errors, _, solves = watched_page(browser, "/v1/solve")

    def enter(field_id: str, typed: str) -> None:
        page.fill(f"#{field_id}", "")
        page.locator(f"#{field_id}").press_sequentially(typed)  # as typed ("1e" too)
        page.press(f"#{field_id}", "Tab")  # a number field's change: on leaving it
        settle(page)

    def refused(field_id: str, says: str) -> None:
        assert page.get_attribute(f"#{field_id}", "aria-invalid") == "true"
        note = page.locator(f"#{field_id}-problem")
        assert note.is_visible() and says in note.inner_text(), note.inner_text()

    def accepted(field_id: str) -> None:
        assert page.get_attribute(f"#{field_id}", "aria-invalid") != "true"
        assert not page.locator(f"#{field_id}-problem").is_visible()

    try:
        page.goto(server + "/editor")
        page.wait_for_function(f"() => {M} && {M}.ready()")
        page.wait_for_function(
            "() => document.getElementById('status').textContent === 'connected'"
        )
        accepted("tolerance")
        accepted("soft-ik")
        drag_joint(page, "left_wrist", 60, -90)
        enter("soft-ik", "1")
        assert solves[-1]["options"]["soft_ik"] == 0.01

        # -- out of range, or not a number: refused at once, nothing sent -----------------
        for typed in ("0", "-0.001", "2", "1e-7"):
            n = len(solves)
            enter("tolerance", typed)
            assert len(solves) == n, f"tolerance {typed} was sent"
            refused("tolerance", "0.000001 to 1 m")
        for typed in ("12", "-1", "1e"):
            n = len(solves)
            enter("soft-ik", typed)
            assert len(solves) == n, f"soft IK {typed} was sent"
            refused("soft-ik", "0 to 10 cm")
        assert page.evaluate(f"{M}.error()") is None

        # -- a drag meanwhile solves with the last valid values -------------------------
        n = len(solves)
        drag_joint(page, "right_wrist", -60, -90)
        assert len(solves) > n
        assert all(s["options"]["tolerance"] == 0.001 for s in solves[n:])
        assert all(s["options"]["soft_ik"] == 0.01 for s in solves[n:])
        assert page.evaluate(f"{M}.error()") is None
        assert page.evaluate(f"{M}.options()")["tolerance"] == 0.001

        # -- mended: accepted, and the targets re-solved with it ------------------------
        n = len(solves)
        enter("tolerance", "0.002")
        accepted("tolerance")
        assert len(solves) == n + 1 and solves[-1]["options"]["tolerance"] == 0.002
        enter("soft-ik", "10")
        accepted("soft-ik")
        assert len(solves) == n + 2 and solves[-1]["options"]["soft_ik"] == 0.1
        assert page.evaluate(f"{M}.error()") is None
        assert page_errors == []
        assert console_errors == [], console_errors
    finally:
        context.close()


@pytest.mark.browser
def test_editor_checks_option_fields_as_they_are_typed(server: str, browser: Any) -> None:
    """Found by an editor review: Tolerance and Soft IK were checked only when the field was
    left (``change``), so a value out of range typed in the field showed nothing wrong until
    then. Now each keystroke checks it: out of range (or not a number), the field is marked
    with its line at once; back in range, cleared at once; nothing is sent while typing,
    and leaving the field takes the value (refused or re-solved) as before."""
    context, page, console_errors, page_errors, _, solves = watched_page(browser, "/v1/solve")

    def typed(field_id: str, key: str) -> None:
        page.keyboard.press(key)
        assert page.evaluate(f"document.activeElement.id === '{field_id}'")  # not left

    def refused(field_id: str, says: str) -> None:
        assert page.get_attribute(f"#{field_id}", "aria-invalid") == "true"
        note = page.locator(f"#{field_id}-problem")
        assert note.is_visible() and says in note.inner_text(), note.inner_text()

    def accepted(field_id: str) -> None:
        assert page.get_attribute(f"#{field_id}", "aria-invalid") == "false"
        assert not page.locator(f"#{field_id}-problem").is_visible()

    try:
        page.goto(server + "/editor")
        page.wait_for_function(f"() => {M} && {M}.ready()")
        page.wait_for_function(
            "() => document.getElementById('status').textContent === 'connected'"
        )
        drag_joint(page, "left_wrist", 60, -90)
        n = len(solves)

        # -- Tolerance: "0.002" typed over "0.001" -------------------------------------------
        page.click("#tolerance")
        page.keyboard.press("Control+a")
        for key in ("0", ".", "0", "0"):  # 0, 0., 0.0, 0.00: out of range at each key
            typed("tolerance", key)
            refused("tolerance", "Tolerance: 0.000001 to 1 m; the solves use 0.001 m")
        typed("tolerance", "2")  # 0.002: cleared at once, still typing
        accepted("tolerance")
        assert page.evaluate(f"{M}.options()")["tolerance"] == 0.001  # (not taken yet)
        typed("tolerance", "Backspace")  # 0.00 again
        refused("tolerance", "0.000001 to 1 m")
        typed("tolerance", "5")
        accepted("tolerance")
        assert len(solves) == n, "a solve was sent while typing"
        page.keyboard.press("Tab")  # left: taken, the targets re-solved with it
        settle(page)
        accepted("tolerance")
        assert len(solves) == n + 1 and solves[-1]["options"]["tolerance"] == 0.005

        # -- Soft IK: 1, 12, 1, (empty: off), 1e, 1 ------------------------------------------
        n = len(solves)
        page.click("#soft-ik")
        page.keyboard.press("Control+a")
        typed("soft-ik", "1")
        accepted("soft-ik")
        typed("soft-ik", "2")  # 12 cm
        refused("soft-ik", "Soft IK: 0 to 10 cm (0: off); the solves use 0 cm")
        typed("soft-ik", "Backspace")
        accepted("soft-ik")
        typed("soft-ik", "Backspace")  # emptied: off, a valid value
        accepted("soft-ik")
        for key in ("1", "e"):
            page.keyboard.press(key)
        refused("soft-ik", "0 to 10 cm")  # 1e: not a number
        # Enter on a refused value: still refused, nothing sent
        page.keyboard.press("Enter")
        settle(page)
        refused("soft-ik", "the solves use 0 cm")
        assert len(solves) == n
        typed("soft-ik", "Backspace")  # 1
        accepted("soft-ik")
        page.keyboard.press("Enter")
        settle(page)
        assert len(solves) == n + 1 and solves[-1]["options"]["soft_ik"] == 0.01
        assert solves[-1]["options"]["tolerance"] == 0.005
        assert page.evaluate(f"{M}.error()") is None
        assert page_errors == []
        assert console_errors == [], console_errors
    finally:
        context.close()
