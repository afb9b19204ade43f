"""The editor's banner once what it said no longer holds, and its menus' long choices (an
editor review, 2026-12-07; real Chromium, a real server of the test's own where it is
stopped, restarted or kept busy; ``docs/editor-recovery.md``):

- a server gone and back: the status said "connected" again (the page asks its liveness
  every 3 s) while the "Server unreachable" banner stayed up until the next solve landed;
- Reset, or a sample chosen: a busy server's 429 banner stayed over the pose that replaced
  the edit it was about, and a file's "Broken file" banner over the sample that closed it
  (an undo already took a failed solve's banner);
- a sample's name longer than its menu (170 px) was cut mid-word, with no tooltip.

Shared parts: ``tests/service/editor_page.py``.
"""

from __future__ import annotations

import contextlib
import json
import re
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import (
    REPO_ROOT,
    STATUS,
    M,
    drag_joint,
    found,
    gesture,
    open_editor,
    open_file,
    opened,
    settle,
    unreachable,
    work,
)
from tests.service.server import free_port, serve

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)


@pytest.mark.browser
def test_the_unreachable_banner_goes_once_the_server_is_back(
    browser: Any, models_dir: Path, tmp_path: Path
) -> None:
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    with contextlib.ExitStack() as first:
        first.enter_context(serve(models_dir, tmp_path, port=port))
        page = opened(browser, base)
        reset = opened(browser, base)  # (Reset while it is gone: below, the same outage)
        drag_joint(page, "right_wrist", 30, -40)  # an edit, solved
    try:  # (the server stopped)
        unreachable(page)
        made = work(page)
        assert "right_wrist" in made["targets"] and "left_knee" in made["targets"]
        # gone: Reset (or a sample) replaces the pose, but the server is still unreachable,
        # and the banner saying so stays until it is back
        unreachable(reset)
        reset.click("#reset")
        assert reset.evaluate(f"{M}.targets()") == {}
        assert reset.evaluate(f"{M}.error()")["title"] == "Server unreachable"
        assert reset.locator("#error").is_visible()
        with serve(models_dir, tmp_path, port=port):
            # no click, no drag: the page's liveness check finds it, and the banner goes
            found(page)
            page.wait_for_function(f"() => {M}.error() === null")
            assert page.locator("#error").is_hidden()
            settle(page)  # (the drag the outage interrupted sent again: test_editor_resend.py)
            now = work(page)
            assert {k: now[k] for k in ("targets", "pins", "history")} == {
                k: made[k] for k in ("targets", "pins", "history")
            }  # the user's work as it was, its last drag solved
            assert now["committed"] != made["committed"]
            drag_joint(page, "right_wrist", -10, -10)  # and it edits on
            assert page.evaluate(f"{M}.error()") is None
            assert page.evaluate(f"{M}.lastSolve().response.targets")
            found(reset)
            reset.wait_for_function(f"() => {M}.error() === null")
            assert reset.evaluate(STATUS) == "connected"
    finally:
        page.context.close()
        reset.context.close()


def stalled(port: int) -> socket.socket:
    """An upload that sends its head and one byte of its body, then nothing: it holds one of
    the server's admission slots (its 429s are real, with Retry-After) until closed."""
    sock = socket.create_connection(("127.0.0.1", port))
    sock.sendall(
        b"POST /v1/solve HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\n"
        b"content-length: 1000\r\n\r\n{"
    )
    return sock


@contextlib.contextmanager
def busy(port: int) -> Iterator[None]:
    sock = stalled(port)
    try:
        yield
    finally:
        sock.close()


def refused_drag(page: Any) -> None:
    """A drag the busy server refuses: its 429 banner."""
    gesture(page, "left_wrist", 30, -30)
    page.wait_for_function(f"() => {M}.error() !== null && {M}.error().status === 429")


def cut_file() -> str:
    """docs/examples' three-frame file cut inside its last frame: a "Broken file" banner."""
    text: str = json.loads((REPO_ROOT / "docs" / "examples" / "bvh_solve.json").read_text())["bvh"]
    body = text.rstrip("\n")
    return body[: body.rfind(" ", 0, len(body) - 200)] + "\n"


@pytest.mark.browser
def test_reset_and_a_sample_take_the_banner_of_the_pose_they_replace(
    browser: Any, models_dir: Path, tmp_path: Path
) -> None:
    port = free_port()
    env = {"POSE_MAX_CONCURRENCY": "1", "POSE_DEADLINE_SECONDS": "30"}
    with serve(models_dir, tmp_path, port=port, **env):
        page = open_editor(browser, f"http://127.0.0.1:{port}")
        try:
            page.on("dialog", lambda d: d.accept())  # (a sample over edits asks first)
            with busy(port):
                refused_drag(page)
                page.click("#reset")
                page.wait_for_function(f"() => {M}.error() === null")
                assert page.locator("#error").is_hidden()
                assert page.evaluate(f"{M}.targets()") == {}
                refused_drag(page)
                page.select_option("#sample", "2")
                page.wait_for_function(f"() => {M}.error() === null")
                assert page.evaluate("document.getElementById('sample').value") == "2"
            settle(page)
            drag_joint(page, "left_wrist", 20, -20)  # (free again: solved, no banner)
            assert page.evaluate(f"{M}.error()") is None
            # a file's warning: Reset shows the file as opened, of which it still holds;
            # a sample closes the file, and the banner goes with it
            open_file(page, cut_file(), "cut.bvh")
            assert page.evaluate(f"{M}.error()")["title"] == "Broken file"
            drag_joint(page, "left_wrist", 20, -20)
            assert page.evaluate(f"{M}.error()") is None  # (a solve landed: as before)
            open_file(page, cut_file(), "cut2.bvh")
            page.click("#reset")
            assert page.evaluate(f"{M}.error()")["title"] == "Broken file"
            with busy(port):  # a failed solve's banner on the file: Reset takes it
                refused_drag(page)
                page.click("#reset")
                page.wait_for_function(f"() => {M}.error() === null")
            open_file(page, cut_file(), "cut3.bvh")
            assert page.evaluate(f"{M}.error()")["title"] == "Broken file"
            page.select_option("#sample", "1")
            page.wait_for_function(f"() => {M}.bvh() === null")
            assert page.evaluate(f"{M}.error()") is None
        finally:
            page.context.close()


# the shown option's text against the room the menu gives it (its box less padding and
# the arrow's 20 px), in the menu's font
FITS = """(id) => {
  const menu = document.getElementById(id);
  const css = getComputedStyle(menu);
  const ctx = document.createElement('canvas').getContext('2d');
  ctx.font = css.font;
  const room = menu.clientWidth - parseFloat(css.paddingLeft) - parseFloat(css.paddingRight) - 20;
  return ctx.measureText(menu.selectedOptions[0].textContent).width <= room;
}"""


@pytest.mark.browser
def test_a_menus_long_choice_is_readable_whole(server: str, browser: Any) -> None:
    samples = json.loads((REPO_ROOT / "service" / "static" / "samples.json").read_text())
    page = open_editor(browser, server)
    try:
        for i, sample in enumerate(samples["samples"]):
            page.select_option("#sample", str(i))  # (no edits: unasked)
            page.wait_for_function(f"() => {M}.pose() !== null")
            assert page.evaluate(FITS, "sample"), sample["name"]  # shown whole
            title = page.get_attribute("#sample", "title") or ""
            assert title.startswith(f"{sample['name']}: {sample['clip']}, frame {sample['frame']}")
        # a choice longer than any menu's room ends in an ellipsis, and the tooltip names it
        menus = "[...document.querySelectorAll('#panel select')]"
        assert set(page.evaluate(f"{menus}.map(s => getComputedStyle(s).textOverflow)")) == {
            "ellipsis"
        }
        drag_joint(page, "right_shoulder", 20, -20)
        page.select_option("#joint-pick", "right_shoulder")
        shown = page.evaluate(
            "document.getElementById('joint-pick').selectedOptions[0].textContent"
        )
        assert re.fullmatch(r"right_shoulder \((reached|[\d.]+ mm off)\)", shown), shown
        assert (page.get_attribute("#joint-pick", "title") or "").startswith(shown + "\n")
        # arrowed to from the keyboard (taken only on Enter), the tooltip names it already
        page.focus("#sample")
        page.keyboard.press("ArrowUp")
        name = samples["samples"][len(samples["samples"]) - 2]["name"]
        assert (page.get_attribute("#sample", "title") or "").startswith(name + ": ")
    finally:
        page.context.close()
