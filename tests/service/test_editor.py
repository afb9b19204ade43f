"""The browser editor, end to end: the real server (uvicorn, real models) and a real
headless Chromium driven by Playwright.

Chromium: ``$MARIONETTE_CHROMIUM``, else ``/usr/bin/chromium`` (Debian: ``apt-get install -y
chromium``), else ``chromium``/``chromium-browser``/``google-chrome`` on PATH. The test is
skipped, saying so, only when none exists. ``$MARIONETTE_SCREENSHOT`` names where the
screenshot goes (default: the test's temp folder); ``docs/img/editor.png`` is made that way.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from core.skeleton import JOINT_NAMES

REPO_ROOT = Path(__file__).resolve().parents[2]
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--no-first-run",
    # WebGL on the CPU (SwiftShader); without the flag newer Chromium refuses it headless.
    "--enable-unsafe-swiftshader",
]

# The service as `pose-service` runs it, plus the editor routes (a no-op once create_app
# mounts them itself).
SERVER = """
import sys
import uvicorn
from service.app import create_app
from service.editor import mount_editor
from service.settings import Settings

app = create_app(Settings(models_dir=sys.argv[1], access_log=False))
if not any(getattr(r, "path", None) == "/editor" for r in app.routes):
    mount_editor(app)
uvicorn.run(app, host="127.0.0.1", port=int(sys.argv[2]), log_level="warning")
"""


def find_chromium() -> str | None:
    env = os.environ.get("MARIONETTE_CHROMIUM")
    if env:
        return env
    if Path("/usr/bin/chromium").is_file():
        return "/usr/bin/chromium"
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def server(models_dir: Path) -> Iterator[str]:
    """The real service on a free loopback port; yields its base URL once it is ready."""
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-c", SERVER, str(models_dir), str(port)],
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 60
        while True:
            if proc.poll() is not None:
                out = proc.stdout.read().decode(errors="replace") if proc.stdout else ""
                pytest.fail(f"the server exited with {proc.returncode}:\n{out}")
            try:
                with urllib.request.urlopen(f"{base}/v2/health/ready", timeout=2) as r:
                    if r.status == 200:
                        break
            except urllib.error.HTTPError as exc:  # 503: loading, or failed for good
                detail = json.loads(exc.read() or b"{}").get("detail")
                if detail and detail != "loading models":
                    pytest.fail(f"the server cannot load the models in {models_dir}: {detail}")
            except OSError:
                pass
            if time.monotonic() > deadline:
                pytest.fail("the server was not ready within 60 s")
            time.sleep(0.2)
        yield base
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    executable = find_chromium()
    if executable is None:
        pytest.skip(
            "no Chromium found: install it (Debian: apt-get install -y chromium) "
            "or set MARIONETTE_CHROMIUM to a Chromium/Chrome executable"
        )
    sync_api = pytest.importorskip("playwright.sync_api", reason="the playwright package")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=executable, headless=True, args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


def dist(a: list[float], b: list[float]) -> float:
    return math.dist(a, b)


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
    context = browser.new_context(
        viewport={"width": 1280, "height": 800}, device_scale_factor=1, accept_downloads=True
    )
    page = context.new_page()
    page.set_default_timeout(15_000)
    console_errors: list[str] = []
    page_errors: list[str] = []
    page.on("console", lambda m: console_errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: page_errors.append(str(e)))
    urls: list[str] = []
    page.on("request", lambda r: urls.append(r.url))
    solves: list[dict[str, Any]] = []
    page.on(
        "request",
        lambda r: (
            solves.append(json.loads(r.post_data or "{}")) if r.url.endswith("/v1/solve") else None
        ),
    )
    m = "window.marionette"

    def settled() -> None:
        """Wait until no solve is waiting or in flight."""
        page.wait_for_function(
            f"() => {m} && (s => !s.dirty && !s.inflight)({m}.solveCount())", polling=50
        )

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
        settled()

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
        settled()
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
        page.fill("#tolerance", "0")
        page.press("#tolerance", "Tab")
        page.wait_for_function(f"() => {m}.error() !== null")
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
        settled()
        assert "carry" not in solves[-1]["options"]
        assert "models' default" in page.locator("#carry-label").inner_text()
        assert page.locator("#carry").input_value() == "0.5"  # GET /v1/models says so
        page.locator("#carry").fill("1")
        settled()
        assert solves[-1]["options"]["carry"] == 1
        last = page.evaluate(f"{m}.lastSolve()")
        direct = post_json(server + "/v1/solve", last["request"])
        assert direct["pose"] == last["response"]["pose"]

        # -- the turn search: the models' default until unchecked ------------------------
        assert "turn_search" not in solves[-1]["options"]
        page.get_by_label("Search the body's turn").uncheck()
        settled()
        assert solves[-1]["options"]["turn_search"] is False

        # Only the browser's own log lines of the two forced failures.
        assert page_errors == []
        unexpected = [e for e in console_errors if not e.startswith("Failed to load resource")]
        assert unexpected == [], unexpected
    finally:
        context.close()


def post_json(url: str, body: dict[str, Any]) -> Any:
    req = urllib.request.Request(
        url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"}
    )
    with urllib.request.urlopen(req, timeout=30) as r:
        return json.loads(r.read())


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
    context = browser.new_context(
        viewport={"width": 1280, "height": 800}, device_scale_factor=1, accept_downloads=True
    )
    page = context.new_page()
    page.set_default_timeout(20_000)
    console_errors: list[str] = []
    page_errors: list[str] = []
    page.on("console", lambda m: console_errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: page_errors.append(str(e)))
    urls: list[str] = []
    page.on("request", lambda r: urls.append(r.url))
    solves: list[dict[str, Any]] = []
    page.on(
        "request",
        lambda r: (
            solves.append(json.loads(r.post_data or "{}"))
            if r.url.endswith("/v1/bvh/solve")
            else None
        ),
    )
    m = "window.marionette"

    def settled() -> None:
        page.wait_for_function(
            f"() => {m} && (s => !s.dirty && !s.inflight)({m}.solveCount())", polling=50
        )

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
        assert "units" in err["detail"], err
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
        settled()

        assert solves, "dragging sent no /v1/bvh/solve"
        assert len(solves) <= 13  # throttled, latest wins
        first = solves[0]
        assert first["bvh"] == original  # every solve starts from the committed file
        assert first["frame"] == edited_frame
        assert first["units"] == units
        assert [t["joint"] for t in first["targets"]] == ["left_wrist"]
        assert first["options"]["reach"] == "exact"
        last = page.evaluate(f"{m}.lastSolve()")
        assert last["response"]["frame"] == edited_frame
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
    page.set_default_timeout(20_000)
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


# -- the review's defects: each found by a test run against the page before its fix ------------
M = "window.marionette"


def open_editor(browser: Any, server: str) -> Any:
    """A fresh page on the editor, loaded and connected (its context closed with the page's
    ``context``)."""
    context = browser.new_context(viewport={"width": 1280, "height": 800}, device_scale_factor=1)
    page = context.new_page()
    page.set_default_timeout(20_000)
    page.goto(server + "/editor")
    page.wait_for_function(f"() => {M} && {M}.ready()")
    page.wait_for_function("() => document.getElementById('status').textContent === 'connected'")
    return page


def give_file(page: Any, body: str, name: str) -> None:
    """``body`` given to the editor's file picker as the file ``name``."""
    page.set_input_files(
        "#bvh-file", files=[{"name": name, "mimeType": "text/plain", "buffer": body.encode()}]
    )


def held_drag(page: Any, joint: str, dx: float = 30, dy: float = -40) -> list[Any]:
    """Drag ``joint`` by (dx, dy) and release it while the answers are held back: the
    held routes, to continue."""
    held: list[Any] = []
    page.route("**/v1/bvh/solve", lambda route: held.append(route))
    xy = page.evaluate(f"{M}.projectJoint('{joint}')")
    page.mouse.move(xy["x"], xy["y"])
    page.mouse.down()
    page.mouse.move(xy["x"] + dx, xy["y"] + dy, steps=4)
    page.mouse.up()
    page.wait_for_function(f"() => {M}.solveCount().inflight")
    return held


def settle(page: Any) -> None:
    page.wait_for_function(f"() => (s => !s.dirty && !s.inflight)({M}.solveCount())", polling=50)


def drag_joint(page: Any, joint: str, dx: float, dy: float, steps: int = 8) -> None:
    """Drag ``joint``'s handle by (dx, dy) pixels and wait for the gesture's last solve."""
    xy = page.evaluate(f"{M}.projectJoint('{joint}')")
    page.mouse.move(xy["x"], xy["y"])
    page.mouse.down()
    for i in range(1, steps + 1):
        page.mouse.move(xy["x"] + dx * i / steps, xy["y"] + dy * i / steps)
        page.wait_for_timeout(16)
    page.mouse.up()
    settle(page)


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
        want = post_json(server + "/v1/bvh/inspect", {"bvh": now, "frame": frame})["positions"]
        got = page.evaluate(f"{M}.bvhPositions()")
        assert max(dist(a, b) for a, b in zip(got, want, strict=True)) < 1e-6
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
        want = post_json(server + "/v1/bvh/inspect", {"bvh": now, "frame": 700})["positions"]
        got = page.evaluate(f"{M}.bvhPositions()")
        assert max(dist(a, b) for a, b in zip(got, want, strict=True)) < 1e-6
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
        page.route("**/v1/bvh/solve", lambda route: route.abort())
        page.mouse.up()
        page.wait_for_function(f"() => {M}.error() !== null")
        settle(page)
        assert page.evaluate(f"{M}.error()")["status"] == 0
        assert shown_is_committed() and page.evaluate(f"{M}.bvhText()") == before
        assert page.locator("#status").inner_text() == "server unreachable"
        page.unroute("**/v1/bvh/solve")

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

    def release(held: list[Any]) -> None:
        for route in held:
            route.continue_()
        page.unroute("**/v1/bvh/solve")
        settle(page)

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
            release(held)
        page.wait_for_function(f"() => {M}.bvh().frame === 2")
        saved = Path(download.value.path()).read_text()
        assert saved == page.evaluate(f"{M}.bvhText()") != edited  # the drag is in it

        # scrubbed away and back while waiting: the frame asked last (it ended on the other)
        held = held_drag(page, "left_wrist")
        page.locator("#bvh-frame").fill("0")
        page.locator("#bvh-frame").fill("2")
        release(held)
        page.wait_for_timeout(200)
        assert page.evaluate(f"{M}.bvh()")["frame"] == 2

        # a file opened while waiting asks too: the edit on its way counts
        held = held_drag(page, "right_wrist")
        dialogs: list[str] = []
        page.once("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
        give_file(page, text, "b.bvh")
        page.wait_for_timeout(300)
        release(held)
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
        with page.expect_download(timeout=5_000) as download:
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
        assert "cut.bvh: its last frame (2) holds" in error["detail"]
        assert not errors, errors
    finally:
        page.context.close()
