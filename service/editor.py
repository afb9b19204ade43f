"""The browser pose editor: ``GET /editor`` (the page) and ``/static/...`` (its files).

Everything the page needs ships in ``service/static/`` (three.js is vendored, see
``scripts/vendor_three.sh``), so the editor works offline. The page talks to the same
service through relative URLs (``v1/solve``, ``v1/skeleton``), so it also works behind a
path prefix. The page is served with a Content-Security-Policy that allows its own
files only, plus its inline import map by hash (computed from the page as served).
"""

from __future__ import annotations

import base64
import hashlib
import re
from pathlib import Path

from fastapi import FastAPI

from service.files import File, Files

STATIC_DIR = Path(__file__).resolve().parent / "static"
EDITOR_PAGE = STATIC_DIR / "editor.html"
_INLINE = re.compile(rb"<script(?![^>]*\bsrc=)[^>]*>(.*?)</script>", re.S)


def page_csp(page: bytes) -> str:
    """A CSP for ``page``: scripts, styles, images and requests from this origin only,
    each inline script allowed by its sha256."""
    hashes = " ".join(
        f"'sha256-{base64.b64encode(hashlib.sha256(m).digest()).decode()}'"
        for m in _INLINE.findall(page)
    )
    return (
        f"default-src 'self'; script-src 'self' {hashes}; style-src 'self' 'unsafe-inline'; "
        "img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; "
        "frame-ancestors 'none'; form-action 'none'"
    )


def mount_editor(app: FastAPI) -> None:
    """Serve the editor page at ``/editor`` and its assets under ``/static``."""

    @app.get("/editor", include_in_schema=False)
    async def editor() -> File:
        # no-cache: the page is tiny and must match the (versioned) API it talks to.
        headers = {
            "Cache-Control": "no-cache",
            "Content-Security-Policy": page_csp(EDITOR_PAGE.read_bytes()),
        }
        return File(EDITOR_PAGE, media_type="text/html", headers=headers)

    app.mount("/static", Files(directory=STATIC_DIR), name="static")
