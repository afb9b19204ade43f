"""A BVH file saved as UTF-16 with its byte order mark (Windows tools' "Unicode", Notepad's
"UTF-16 LE"): the page read bytes that are not UTF-8 as Latin-1, every other character a NUL,
and the service refused the file as "not a BVH file (no HIERARCHY keyword)" (an audit,
2026-12-07). It is read as UTF-16 (``editor/file.js`` ``decodeFile``), edited as any file,
and exported in its own bytes: the same encoding and mark, its other lines byte for byte.

The real server and a real Chromium (``tests/service/editor_page.py``); a real
AnimatedDrawings file (``fair1/dab.bvh``: inches, +Z up) from the mocap archives.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.service.editor_page import M, drag_joint, open_editor, show_frame

# the fixtures `server` (one for the session) and `browser` (one per module)
pytest_plugins = ("tests.service.editor_page",)


@pytest.mark.browser
@pytest.mark.parametrize("codec", ["utf-16-le", "utf-16-be"])
def test_a_utf16_file_opens_edits_and_exports_in_its_own_bytes(
    server: str, browser: Any, more_mocap: Path, codec: str
) -> None:
    text = next(more_mocap.rglob("fair1/dab.bvh")).read_text().replace("\n", "\r\n")
    data = "\ufeff".encode(codec) + text.encode(codec)
    page = open_editor(browser, server)
    try:
        page.select_option("#bvh-units", "in")
        page.set_input_files(
            "#bvh-file", files=[{"name": "dab.bvh", "mimeType": "text/plain", "buffer": data}]
        )
        page.wait_for_function(f"() => {M}.bvh() || {M}.error()")
        assert page.evaluate(f"{M}.error()") is None
        info = page.evaluate(f"{M}.bvh()")
        assert (info["frames"], info["joints"][0]) == (339, "Hips")
        assert page.evaluate(f"{M}.bvhText()") == "\ufeff" + text

        show_frame(page, 3)
        drag_joint(page, "left_wrist", 30, -40)
        assert page.evaluate(f"{M}.error()") is None and page.evaluate(f"{M}.bvh()")["edited"]
        with page.expect_download() as download:
            page.click("#export")
        out = Path(download.value.path()).read_bytes()
        assert out[:2] == data[:2]  # (the mark, in the file's byte order)
        was, got = text.split("\r\n"), out[2:].decode(codec).split("\r\n")
        changed = [i for i, (a, b) in enumerate(zip(was, got, strict=True)) if a != b]
        assert changed == [167 + 3]  # frame 3's line alone (frame 0 is line 168)
    finally:
        page.context.close()
