"""The editor's browser tests' shared parts: the real server (uvicorn, real models) on a free
loopback port, a real headless Chromium driven by Playwright, and helpers that drive the page.

Chromium: ``$MARIONETTE_CHROMIUM``, else ``/usr/bin/chromium`` (Debian: ``apt-get install -y
chromium``), else ``chromium``/``chromium-browser``/``google-chrome`` on PATH. The tests are
skipped, saying so, only when none exists.

The test modules name this module in ``pytest_plugins``, so its fixtures are found: ``server``
is session-scoped (one server, a subprocess, for every editor test module), ``browser``
module-scoped (each module's own Chromium, closed with it: Playwright's sync API keeps an
asyncio loop running in the main thread while it is open, so a session's Chromium made every
later ``asyncio.run``/``anyio.run`` test fail with "cannot be called from a running event
loop"); ``outages`` is a test's own server (:class:`Outages`), stopped and started at will.
It holds no asserts (PYTEST_DONT_REWRITE: the tests import it before it becomes their
plugin, and pytest would warn that it cannot rewrite it).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import pytest

from tests.conftest import REPO_ROOT
from tests.service.server import free_port, serve

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


#: The ceiling on a page's waits (ms; Playwright's default for each wait, navigation too).
#: Every wait is on a condition (an answer in, a file open, a step made) and ends as soon as
#: it holds, so a passing run is no slower; on a loaded machine (two cores, other suites
#: running) a solve's answer or a file's reading outlasted the 20 s it was.
WAIT_MS = 90_000
#: The ceiling on the server's start (s): it is polled for readiness every 0.2 s and used
#: as soon as it is ready (the models loaded); loaded, the machine took over the 60 s it was.
START_S = 300


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


@pytest.fixture(scope="session")
def server(models_dir: Path) -> Iterator[str]:
    """The real service on a free loopback port; yields its base URL once it is ready. Its
    output goes to a file, not a pipe nobody reads while the tests run: a pipe's 64 kB
    filled (its warnings: connections a test aborted) would block the server mid-session."""
    with tempfile.TemporaryFile() as log:
        yield from served(models_dir, log)


def served(models_dir: Path, log: IO[bytes]) -> Iterator[str]:
    """:func:`server`'s process, its output written to ``log``."""
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-c", SERVER, str(models_dir), str(port)],
        cwd=REPO_ROOT,
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    base = f"http://127.0.0.1:{port}"

    def output() -> str:
        log.seek(0)
        return log.read().decode(errors="replace")

    try:
        deadline = time.monotonic() + START_S
        while True:
            if proc.poll() is not None:
                pytest.fail(f"the server exited with {proc.returncode}:\n{output()}")
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
                pytest.fail(f"the server was not ready within {START_S} s:\n{output()}")
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


def post_json(url: str, body: dict[str, Any]) -> Any:
    req = urllib.request.Request(
        url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"}
    )
    with urllib.request.urlopen(req, timeout=30) as r:
        return json.loads(r.read())


# -- the review's defects: each found by a test run against the page before its fix ------------
M = "window.marionette"
#: The page's status line (``connected``, ``server unreachable``, ...), as a JS expression.
STATUS = "document.getElementById('status').textContent"


def work(page: Any, shown: bool = False) -> dict[str, Any]:
    """What the user made: the pose as committed (and as shown, ``shown``), the targets,
    pins and undo history."""
    made = {
        "committed": page.evaluate(f"{M}.committedPose()"),
        "targets": page.evaluate(f"{M}.targets()"),
        "pins": page.evaluate(f"{M}.pins()"),
        "history": page.evaluate(f"{M}.history()"),
    }
    return {**made, "pose": page.evaluate(f"{M}.pose()")} if shown else made


def unreachable(page: Any, joint: str = "left_knee", dx: float = 10, dy: float = 10) -> None:
    """A drag of ``joint`` whose solves find no server (the test's own, stopped): its banner
    and the status say so."""
    drag_joint(page, joint, dx, dy)
    err = page.evaluate(f"{M}.error()")
    assert err is not None and err["title"] == "Server unreachable", err
    assert page.evaluate(STATUS) == "server unreachable"


def drawn_as_inspected(page: Any, server: str, body: dict[str, Any]) -> None:
    """The page draws the BVH frame as ``/v1/bvh/inspect`` lays out ``body`` (its text,
    frame, map), to 1e-6: the page's forward kinematics are the service's."""
    want = post_json(server + "/v1/bvh/inspect", body)["positions"]
    got = page.evaluate(f"{M}.bvhPositions()")
    assert max(math.dist(a, b) for a, b in zip(got, want, strict=True)) < 1e-6


def open_editor(browser: Any, server: str, clock: bool = False) -> Any:
    """A fresh page on the editor, loaded and connected (its context closed with the page's
    ``context``); ``clock``: its timers on Playwright's clock (``page.clock``, installed
    before it loads: they run in real time until a test runs the clock on)."""
    context = browser.new_context(viewport={"width": 1280, "height": 800}, device_scale_factor=1)
    page = context.new_page()
    page.set_default_timeout(WAIT_MS)
    if clock:
        page.clock.install()
    page.goto(server + "/editor")
    page.wait_for_function(f"() => {M} && {M}.ready()")
    page.wait_for_function("() => document.getElementById('status').textContent === 'connected'")
    return page


def give_file(page: Any, body: str, name: str) -> None:
    """``body`` given to the editor's file picker as the file ``name``."""
    page.set_input_files(
        "#bvh-file", files=[{"name": name, "mimeType": "text/plain", "buffer": body.encode()}]
    )


def open_file(page: Any, body: str, name: str) -> None:
    """:func:`give_file`, then waited for until the page shows it open."""
    give_file(page, body, name)
    page.wait_for_function(f"() => {M}.bvh() && {M}.bvh().name === '{name}'")


def gesture(page: Any, joint: str, dx: float, dy: float) -> None:
    """Press ``joint``'s handle, move it by (dx, dy) in four steps and let go: the gesture
    alone, its solve not waited for (:func:`drag_joint` waits)."""
    xy = page.evaluate(f"{M}.projectJoint('{joint}')")
    page.mouse.move(xy["x"], xy["y"])
    page.mouse.down()
    page.mouse.move(xy["x"] + dx, xy["y"] + dy, steps=4)
    page.mouse.up()


def held_drag(page: Any, joint: str, dx: float = 30, dy: float = -40) -> list[Any]:
    """Drag ``joint`` by (dx, dy) and release it while the answers are held back: the
    held routes, to continue."""
    held: list[Any] = []
    page.route("**/v1/bvh/solve", lambda route: held.append(route))
    gesture(page, joint, dx, dy)
    page.wait_for_function(f"() => {M}.solveCount().inflight")
    return held


def settle(page: Any) -> None:
    """Wait until the page has no solve waiting or in flight."""
    page.wait_for_function(
        f"() => {M} && (s => !s.dirty && !s.inflight)({M}.solveCount())", polling=50
    )


def release(page: Any, held: list[Any]) -> None:
    """Let the BVH solves a test held (``held_drag``) through, stop holding, and settle."""
    for route in held:
        route.continue_()
    page.unroute("**/v1/bvh/solve")
    settle(page)


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


def watched_page(
    browser: Any, solve_path: str
) -> tuple[Any, Any, list[str], list[str], list[str], list[dict[str, Any]]]:
    """A fresh context and page (1280 x 800, downloads on, waits up to ``WAIT_MS``)
    recording what a test checks: ``(context, page, console errors, page errors, every URL
    asked, the bodies POSTed to solve_path)``."""
    context = browser.new_context(
        viewport={"width": 1280, "height": 800}, device_scale_factor=1, accept_downloads=True
    )
    page = context.new_page()
    page.set_default_timeout(WAIT_MS)
    console_errors: list[str] = []
    page_errors: list[str] = []
    page.on("console", lambda m: console_errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: page_errors.append(str(e)))
    urls: list[str] = []
    page.on("request", lambda r: urls.append(r.url))
    solves = recorded(page, lambda url: url.endswith(solve_path))
    return context, page, console_errors, page_errors, urls, solves


def recorded(page: Any, wanted: Any) -> list[dict[str, Any]]:
    """The JSON bodies of the requests ``page`` sends to a URL ``wanted(url)`` accepts,
    appended as they go out."""
    bodies: list[dict[str, Any]] = []
    page.on(
        "request",
        lambda r: bodies.append(json.loads(r.post_data or "{}")) if wanted(r.url) else None,
    )
    return bodies


#: The 3D view's canvas (the keys' target: editor/keys.js)
VIEW = "#viewport canvas"


def steps(page: Any) -> int:
    """The undo history's steps up to the one shown."""
    return int(page.evaluate(f"{M}.history().index"))


def pick(page: Any, joint: str) -> None:
    """``joint`` chosen in the panel's picker (the focus left there)."""
    page.select_option("#joint-pick", joint)
    page.wait_for_function(f"() => {M}.selected() === '{joint}'")


def show_frame(page: Any, frame: int) -> None:
    """Frame ``frame`` shown, typed in the frame box and Enter pressed."""
    page.locator("#bvh-frame-number").fill(str(frame))
    page.keyboard.press("Enter")
    page.wait_for_function(f"() => {M}.bvh().frame === {frame}")


#: The page time (ms) :func:`found` runs a page's clock on at a time (test_editor_resend's
#: ``quiet`` too).
STEP_MS = 100
#: Each page's requests on their way (sent, not yet answered or failed): :func:`opened`.
OPEN: dict[Any, set[Any]] = {}


def opened(browser: Any, base: str) -> Any:
    """:func:`open_editor`, its timers on Playwright's clock (real time until a test runs it
    on: :func:`found`), its requests on their way kept in ``OPEN[page]``."""
    return tracked(open_editor(browser, base, clock=True))


def tracked(page: Any) -> Any:
    """``page``, its requests on their way from now on kept in ``OPEN[page]``."""
    OPEN[page] = on_way = set()
    page.on("request", lambda r: on_way.add(r))
    page.on("requestfinished", lambda r: on_way.discard(r))
    page.on("requestfailed", lambda r: on_way.discard(r))
    return page


def drained(page: Any, wanted: Any, deadline: float) -> None:
    """Wait until none of the page's requests to a URL ``wanted(url)`` is on its way."""
    while any(wanted(r.url) for r in OPEN[page]):
        if time.monotonic() > deadline:
            pytest.fail(f"requests never finished: {[r.url for r in OPEN[page]]}")
        page.wait_for_timeout(5)


def found(page: Any) -> None:
    """The page's next liveness check (api.js: every WATCH_MS, 3 s, while its status says
    the server is down) made now, and again until it finds the server: its clock run on
    ``STEP_MS`` at a time, each check let finish before the next step, until the status
    says "connected" (a real wait of up to 3 s for each)."""
    deadline = time.monotonic() + WAIT_MS / 1000  # (a ceiling, as each page wait has)
    while page.evaluate(STATUS) != "connected":
        if time.monotonic() > deadline:
            pytest.fail(f"the server not found back: {page.evaluate(STATUS)}")
        page.clock.run_for(STEP_MS)
        drained(page, lambda url: url.endswith("/v2/health/live"), deadline)


class Outages:
    """The test's own server on a port of its own, started and stopped at will."""

    def __init__(self, models_dir: Path, tmp: Path) -> None:
        self.models_dir, self.tmp, self.port = models_dir, tmp, free_port()
        self.base = f"http://127.0.0.1:{self.port}"

    def up(self) -> Any:
        return serve(self.models_dir, self.tmp, port=self.port)

    @contextlib.contextmanager
    def ready(self, *pages: Any) -> Iterator[None]:
        """Up, and found by the pages only once its models are loaded (a start answers its
        liveness before: a solve then is a 503 with Retry-After, the edit sent again after)."""
        for page in pages:
            page.route("**/v2/health/live", lambda route: route.abort())
        with self.up():
            for page in pages:
                page.unroute("**/v2/health/live")
            yield


@pytest.fixture
def outages(models_dir: Path, tmp_path: Path) -> Outages:
    """The test's own server, stopped and started at will (an outage the page meets)."""
    return Outages(models_dir, tmp_path)
