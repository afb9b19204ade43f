"""The browser pose editor: ``GET /editor`` (the page) and ``/static/...`` (its files).

Everything the page needs ships in ``service/static/`` (three.js is vendored, see
``scripts/vendor_three.sh``), so the editor works offline. The page talks to the same
service through relative URLs (``v1/solve``, ``v1/skeleton``), so it also works behind a
path prefix.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

STATIC_DIR = Path(__file__).resolve().parent / "static"
EDITOR_PAGE = STATIC_DIR / "editor.html"


def mount_editor(app: FastAPI) -> None:
    """Serve the editor page at ``/editor`` and its assets under ``/static``."""

    @app.get("/editor", include_in_schema=False)
    async def editor() -> FileResponse:
        # no-cache: the page is tiny and must match the (versioned) API it talks to.
        return FileResponse(
            EDITOR_PAGE, media_type="text/html", headers={"Cache-Control": "no-cache"}
        )

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")
