"""The server found back after an outage (real Chromium; a real server, the session's or the
test's own stopped and started again on its port; ``docs/editor-recovery.md``). A review's
defects, 2026-12-08:

- a drag under way as the server is found back: the banner saying the edit its outage
  interrupted is not applied (``Edit not applied``, a lasting banner) went with the drag's
  first answer, on its way, nothing committed; Escape then dropped the drag, the kept
  targets unsolved, without a word;
- the edit sent again answered with the server's error (a 500): the banner said only the
  server's error, not that the edit sent again failed and is not applied;
- ``GET /v1/models`` read at start-up only: a server restarted with other models or
  settings (the carry's default, the body limit) was never read again.

Shared parts: ``tests/service/editor_page.py``.
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import (
    STATUS,
    WAIT_MS,
    M,
    Outages,
    drag_joint,
    found,
    open_file,
    opened,
    recorded,
    settle,
    unreachable,
    work,
)
from tests.service.server import serve
from tests.service.test_editor_resend import example_file, quiet, sent
from tests.service.test_editor_resend_outcomes import LIVE, SOLVE, banner, interrupted, press

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)

#: The command ``serve`` runs the service with (its ``wrap``): the service as ``pose-service``
#: runs it, its models loaded and warmed up as ever, then every solve raising (an unexpected
#: error in the server: its own 500, problem+json and request id, as a fault would give).
FAULTY = [
    sys.executable,
    "-c",
    "import sys\n"
    "from service.engine import Engine\n"
    "def fault(*_args, **_kwargs):\n"
    "    raise RuntimeError('injected fault')\n"
    "warm = Engine.warmup\n"
    "def warmup(self):\n"
    "    warm(self)\n"
    "    self.solve = self.solve_lone = fault\n"
    "Engine.warmup = warmup\n"
    "exec(sys.argv[-1])\n",  # (serve's own command: the service's main)
]


@pytest.mark.browser
def test_the_edit_not_applied_banner_outlasts_a_drag_under_way_as_the_server_is_back(
    server: str, browser: Any
) -> None:
    """The server found back while a joint is dragged (by the page's liveness check as it is
    pressed, or by the drag's own answer; each on a page of its own, the outage the page's
    own): the interrupted edit is not sent again, and its ``Edit not applied`` banner stays
    through the drag's answers on its way (nothing committed: not an edit solved), and
    through Escape, which drops the drag (the kept targets still unsolved). It goes once an
    edit is solved: a drag let go, its answer (the kept targets with it) committed."""
    hows = ("liveness", "answer")
    pages = {how: opened(browser, server) for how in hows}
    try:
        for how, page in pages.items():
            start, made = interrupted(page)
            page.unroute(SOLVE)
            if how == "liveness":
                page.unroute(LIVE)
            xy = press(page, "right_wrist")
            if how == "liveness":
                found(page)  # (while pressed)
                assert banner(page)["title"] == "Edit not applied", how
            answered = page.evaluate(f"{M}.solveCount().answered")
            page.mouse.move(xy["x"] + 10, xy["y"] - 10, steps=2)
            page.wait_for_function(f"() => {M}.solveCount().answered > {answered}")
            settle(page)
            said = banner(page)
            assert said["status"] == "connected", how
            assert said["shown"] and said["title"] == "Edit not applied", (how, said)
            assert "not sent again" in said["detail"] and "drag again to retry" in said["detail"]
            page.keyboard.press("Escape")  # the drag dropped: the kept, unsolved targets shown
            settle(page)
            assert work(page, shown=True) == made, how
            said = banner(page)
            assert said["shown"] and said["title"] == "Edit not applied", (how, said)
            drag_joint(page, "right_wrist", 20, -20)  # let go: its answer committed
            assert page.evaluate(f"{M}.error()") is None, how
            assert page.locator("#error").is_hidden()
            now = work(page, shown=True)
            assert now["pose"] == now["committed"] != start["committed"]
            assert now["history"]["index"] == made["history"]["index"] + 1
            joints = {t["joint"] for t in page.evaluate(f"{M}.lastSolve().request.targets")}
            assert {"left_knee", "right_wrist"} <= joints, how  # (the kept targets solved)
            page.unroute(LIVE)
    finally:
        for page in pages.values():
            page.context.close()


@pytest.mark.browser
def test_the_edit_sent_again_that_the_server_fails_says_it_is_not_applied(
    browser: Any, outages: Outages
) -> None:
    """The server back after an outage, its solves failing (``FAULTY``: a real 500): the edit
    sent again is answered 500, and the banner says the server's error and detail, and that
    the edit sent again failed on the server and is not applied (the pose as before it, its
    targets kept); it is not sent a third time, and the banner stays. It said only "500
    Internal error: an unexpected error occurred; see the server log"."""
    with outages.up():
        page = opened(browser, outages.base)
    try:
        start = work(page, shown=True)
        unreachable(page, "left_knee")
        made, count = work(page, shown=True), sent(page)
        page.route(LIVE, lambda route: route.abort())  # (found once its models are loaded)
        with serve(outages.models_dir, outages.tmp, port=outages.port, wrap=FAULTY):
            page.unroute(LIVE)
            found(page)
            page.wait_for_function(f"() => ({M}.error() || {{}}).status === 500")
            settle(page)
            said = banner(page)
            assert said["shown"] and said["title"] == "500 Internal error", said
            detail = said["detail"]
            assert detail.startswith("an unexpected error occurred; see the server log; "), detail
            assert (
                "the edit, sent again once the server was back, failed on the server: it is "
                "not applied (the pose is as before it, its targets kept: drag again to retry)"
            ) in detail
            assert page.text_content("#error-meta").startswith("request id ")
            assert sent(page) == count + 1
            now = work(page, shown=True)
            assert now == made and now["committed"] == start["committed"]
            assert "left_knee" in now["targets"]
            quiet(page)
            assert sent(page) == count + 1  # (not a third time)
            assert banner(page) == said
    finally:
        page.context.close()


def other_models(models_dir: Path, tmp: Path, carry: float) -> Path:
    """The models of ``models_dir`` (copied to ``tmp``), their manifest's carry ``carry``."""
    out = tmp / "other-models"
    shutil.copytree(models_dir, out)
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["serving"]["carry"] = carry
    (out / "manifest.json").write_text(json.dumps(manifest))
    return out


def long_file(frames: int) -> str:
    """The example file (docs/examples/bvh_solve.json) with ``frames`` frames, its own
    repeated."""
    head, motion = example_file().split("MOTION\n", 1)
    rows = [row for row in motion.split("\n")[2:] if row.strip()]
    body = "\n".join(rows[i % len(rows)] for i in range(frames))
    return f"{head}MOTION\nFrames: {frames}\nFrame Time: 0.033333\n{body}\n"


@pytest.mark.browser
def test_the_models_are_read_again_once_the_server_is_back(browser: Any, outages: Outages) -> None:
    """A server restarted with other models (the carry's default 0.8, not 0.5) and a lower
    body limit (16 KiB, not 8 MiB), found back as soon as it answers (its models loading,
    as a rule): the page reads ``GET /v1/models`` again, once (a 503 while they load asked
    again after its Retry-After), and
    applies it as at start-up: the carry slider shows the new default where it was not
    moved (a moved one keeps the user's value, sent as before), and a file over the new
    limit goes as its first frame's excerpt at once. It read them at start-up only: the
    slider said 0.50, and the file went whole to be refused (413) first."""
    other = other_models(outages.models_dir, outages.tmp, 0.8)
    limit = 16 * 1024
    with outages.up():
        pages = [opened(browser, outages.base) for _ in range(2)]
        mine = pages[1]  # (its slider moved)
        mine.locator("#carry").fill("1")
        for page in pages:
            assert page.locator("#carry").input_value() == ("1" if page is mine else "0.5")
    reads: list[list[int]] = [[] for _ in pages]
    for page, statuses in zip(pages, reads, strict=True):
        page.on("dialog", lambda d: d.accept())  # (a file over the sample's edits asks first)
        page.on(
            "response",
            lambda r, s=statuses: s.append(r.status) if r.url.endswith("/v1/models") else None,
        )
    try:
        for page in pages:
            unreachable(page, "left_knee")
        env = {"POSE_MAX_BODY_BYTES": str(limit)}
        with serve(other, outages.tmp, ready=False, port=outages.port, **env) as again:
            for page in pages:
                found(page)  # (as it loads its models)
            deadline = time.monotonic() + WAIT_MS / 1000
            while again.request("GET", "/v2/health/ready", timeout=2)[0] != 200:
                assert time.monotonic() < deadline, "the models not loaded"
                time.sleep(0.05)
            quiet(*pages)  # (a read refused as they load: asked again after its Retry-After)
            quiet(*pages)
            for page, statuses in zip(pages, reads, strict=True):
                assert statuses.count(200) == 1 and statuses[-1] == 200, statuses
                assert set(statuses) <= {200, 503}, statuses
                assert page.evaluate(STATUS) == "connected"
                assert page.evaluate(f"{M}.error()") is None  # (the edit sent again, solved)
            page = pages[0]
            assert page.locator("#carry").input_value() == "0.8"
            assert page.text_content("#carry-label") == "0.80 (models' default)"
            assert mine.locator("#carry").input_value() == "1"
            assert mine.text_content("#carry-label") == "1.00"
            solves = recorded(mine, lambda url: url.endswith("/v1/solve"))
            drag_joint(mine, "right_wrist", 20, -20)
            assert solves and all(b["options"]["carry"] == 1 for b in solves)
            # the new limit: a file over it sent as its first frame's excerpt at once
            text = long_file(60)
            assert len(json.dumps({"bvh": text})) > limit
            inspected = recorded(page, lambda url: url.endswith("/v1/bvh/inspect"))
            answered: list[int] = []
            page.on(
                "response",
                lambda r: answered.append(r.status) if r.url.endswith("/v1/bvh/inspect") else None,
            )
            open_file(page, text, "long.bvh")
            settle(page)
            assert answered == [200] and len(inspected[0]["bvh"]) < limit, answered
            assert page.evaluate(f"{M}.bvh()")["frames"] == 60
            quiet(*pages)
            assert [statuses.count(200) for statuses in reads] == [1, 1]  # (once)
    finally:
        for page in pages:
            page.context.close()
