"""The service's files (the editor's page ``/editor`` and ``/static``, the docs'
``/docs/assets``): Starlette's ``FileResponse`` and ``StaticFiles`` with every refusal a
problem (``service.errors``).

Starlette answers a ``Range`` it cannot serve in plain text (a 416 with an empty body, a
400 "Range header: start must be less than end"); here those are a 416
``range-not-satisfiable`` with ``Content-Range: bytes */<size>`` and a 400
``malformed-range``, raised to the app's one problem mapping (an adversarial audit,
2026-12-06).

A ``Range`` in a unit other than bytes (``items=0-1``) is ignored and the whole file served,
as RFC 9110 (section 14.2) requires of an origin server; Starlette answered it with a 400.

A file's path with a trailing slash (``/static/editor.js/``) is a 404 naming the file, as
a route's is (docs/limits.md); Starlette served the file there, where the relative URLs
it holds resolve under ``editor.js/``. A mount's own path (``/static/``) is a plain 404.
"""

from __future__ import annotations

import os
import stat

import anyio
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.responses import FileResponse, MalformedRangeHeader, Response
from starlette.responses import RangeNotSatisfiable as _Unsatisfiable
from starlette.staticfiles import NotModifiedResponse, StaticFiles
from starlette.types import Scope

from core.text import clip, quoted
from service.errors import MalformedRange, RangeNotSatisfiable

#: Starlette's reasons for a malformed ``Range``, in the service's words.
_WHY = {
    "Malformed range header.": "not a unit and ranges (bytes=0-99)",
    "Range header: range must be requested": "it names no range",
    "Range header: start must be less than end": "a range ends before it starts",
}


class File(FileResponse):
    """A file whose ``Range`` refusals are raised as problems, not answered in text."""

    @classmethod
    def _parse_range_header(cls, http_range: str, file_size: int) -> list[tuple[int, int]]:
        unit, equals, _ = http_range.partition("=")
        if equals and unit.strip().lower() != "bytes":
            return []  # a unit not understood: the whole file (RFC 9110, section 14.2)
        try:
            return super()._parse_range_header(http_range, file_size)
        except MalformedRangeHeader as exc:
            why = _WHY.get(exc.content, exc.content)
            raise MalformedRange(f"Range {quoted(http_range)}: {why}") from None
        except _Unsatisfiable as exc:
            detail = f"Range {quoted(http_range)} starts past the file's {exc.max_size} bytes"
            raise RangeNotSatisfiable(detail, exc.max_size) from None


class Files(StaticFiles):
    """``StaticFiles`` whose every error is a problem, and whose files are served at their
    paths alone (see the module doc)."""

    async def get_response(self, path: str, scope: Scope) -> Response:
        asked: str = scope["path"]
        if not (asked.endswith("/") and scope["method"] in ("GET", "HEAD")):
            return await super().get_response(path, scope)
        try:  # a directory's URL (html is off: none is served), or a file's with a slash
            _, found = await anyio.to_thread.run_sync(self.lookup_path, path)
        except (OSError, ValueError):  # a name too long, a NUL: no file
            found = None
        if found is not None and stat.S_ISREG(found.st_mode) and not asked.endswith("//"):
            detail = f"no file {clip(asked)}: the file is {clip(asked[:-1])}, without the slash"
            raise HTTPException(404, detail)
        raise HTTPException(404)

    def file_response(
        self, full_path: str | os.PathLike[str], stat_result: os.stat_result, scope: Scope,
        status_code: int = 200,
    ) -> Response:  # fmt: skip
        response = File(full_path, status_code=status_code, stat_result=stat_result)
        if self.is_not_modified(response.headers, Headers(scope=scope)):
            return NotModifiedResponse(response.headers)
        return response
