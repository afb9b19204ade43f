"""The view's `P` (pin) and Delete pressed while the mouse drags a joint. The drag goes on
after the key, so `P` left the dragged joint pinned and targeted at once (the service
refuses a pin on a targeted joint: every solve after it a 422), and Delete's removed target
came back at the next move (an audit, 2026-12-07). During a drag the two keys do nothing:
the drag is the joint's edit until it is released (``editor/keys.js``).

The real server and a real Chromium (``tests/service/editor_page.py``), on a sample.
"""

from __future__ import annotations

from typing import Any

import pytest

from tests.service.editor_page import M, open_editor, recorded, settle

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)


@pytest.mark.browser
@pytest.mark.parametrize("key", ["p", "Delete"])
def test_pin_and_delete_keys_during_a_mouse_drag_leave_a_consistent_edit(
    server: str, browser: Any, key: str
) -> None:
    page = open_editor(browser, server)
    statuses: list[int] = []
    page.on("response", lambda r: statuses.append(r.status) if "/v1/solve" in r.url else None)
    solves = recorded(page, lambda url: url.endswith("/v1/solve"))
    try:
        xy = page.evaluate(f"{M}.projectJoint('left_wrist')")
        page.mouse.move(xy["x"], xy["y"])
        page.mouse.down()  # (the view takes the focus, the wrist selected)
        for i in range(1, 5):
            page.mouse.move(xy["x"] + 6 * i, xy["y"] - 8 * i)
            page.wait_for_timeout(16)
        assert page.evaluate(f"{M}.selected()") == "left_wrist"
        page.keyboard.press(key)
        for i in range(5, 9):
            page.mouse.move(xy["x"] + 6 * i, xy["y"] - 8 * i)
            page.wait_for_timeout(16)
        page.mouse.up()
        settle(page)
        assert page.evaluate(f"{M}.error()") is None
        assert 422 not in statuses and statuses
        for body in solves:  # (no solve pins a targeted joint)
            targeted = {t["joint"] for t in body.get("targets", [])}
            assert not targeted & set(body.get("pins", [])), body
        # the drag's edit, whole: the wrist targeted under the pointer, not pinned
        assert set(page.evaluate(f"{M}.targets()")) == {"left_wrist"}
        assert page.evaluate(f"{M}.pins()") == []
        assert page.evaluate(f"{M}.history().index") == 1
        # the key works once the drag is over
        page.keyboard.press(key)
        settle(page)
        assert page.evaluate(f"{M}.targets()") == {}
        assert page.evaluate(f"{M}.pins()") == (["left_wrist"] if key == "p" else [])
        assert page.evaluate(f"{M}.error()") is None and 422 not in statuses
    finally:
        page.context.close()
