"""Domain errors and their one mapping to HTTP problem details (RFC 9457).

The data plane raises these; ``install_handlers`` turns them (and FastAPI's own request
validation errors, and anything unexpected) into ``application/problem+json``.
"""

from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

PROBLEM_JSON = "application/problem+json"
log = logging.getLogger("service")


class PoseError(Exception):
    """Base of every error a client can cause; carries the HTTP status and a title."""

    status = 422
    title = "Unprocessable pose request"
    type_ = "invalid-request"

    def __init__(self, detail: str, **extra: Any) -> None:
        super().__init__(detail)
        self.detail = detail
        self.extra = extra


class InvalidRequest(PoseError):
    """Unknown joint, duplicate target, NaN, wrong vector length, degenerate pose…"""


class TooManyItems(PoseError):
    status = 413
    title = "Too many items"
    type_ = "too-many-items"


class PayloadTooLarge(PoseError):
    status = 413
    title = "Request body too large"
    type_ = "payload-too-large"


class UnsupportedMediaType(PoseError):
    status = 415
    title = "Unsupported media type"
    type_ = "unsupported-media-type"


class Unauthorized(PoseError):
    status = 401
    title = "Missing or wrong API key"
    type_ = "unauthorized"


class NotReady(PoseError):
    status = 503
    title = "Models not ready"
    type_ = "not-ready"


def problem(
    status: int,
    title: str,
    detail: str,
    *,
    type_: str = "about:blank",
    headers: dict[str, str] | None = None,
    **extra: Any,
) -> JSONResponse:
    body: dict[str, Any] = {
        "type": type_ if type_ == "about:blank" else f"https://marionette.dev/problems/{type_}",
        "title": title,
        "status": status,
        "detail": detail,
    }
    body.update(extra)
    if status == 401:
        headers = {**(headers or {}), "WWW-Authenticate": "ApiKey"}
    return JSONResponse(body, status_code=status, media_type=PROBLEM_JSON, headers=headers)


def _location(loc: tuple[Any, ...] | list[Any]) -> str:
    parts = [str(p) for p in loc if p != "body"]
    return ".".join(parts) or "body"


def install_handlers(app: FastAPI) -> None:
    @app.exception_handler(PoseError)
    async def _pose_error(_: Request, exc: PoseError) -> JSONResponse:
        return problem(exc.status, exc.title, exc.detail, type_=exc.type_, **exc.extra)

    @app.exception_handler(RequestValidationError)
    async def _validation(_: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [
            {"location": _location(e.get("loc", ())), "message": str(e.get("msg", ""))}
            for e in exc.errors()
        ]
        detail = "; ".join(f"{e['location']}: {e['message']}" for e in errors[:10])
        return problem(
            422, "Invalid request body", detail, type_="invalid-request", errors=errors[:50]
        )

    @app.exception_handler(StarletteHTTPException)
    async def _http(_: Request, exc: StarletteHTTPException) -> JSONResponse:
        return problem(
            exc.status_code, str(exc.detail), str(exc.detail), headers=dict(exc.headers or {})
        )

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        return internal_error(request.method, request.url.path)


def internal_error(method: str, path: str) -> JSONResponse:
    """Log the exception being handled and answer a 500 problem (no internals leak)."""
    log.exception("unhandled error on %s %s", method, path)
    return problem(500, "Internal error", "an unexpected error occurred; see the server log")
