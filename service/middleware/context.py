"""One JSON access-log line per request (its id: ``headers.request_id``), written by
:class:`AccessLog` outside CORS (a preflight is answered there, by the CORS layer), and the
last-resort answers (:class:`RequestContext`, inside CORS so that they carry its headers):
a 500 problem for anything unhandled and, when the server cancels a request at the end of
its shutdown grace period, a 503 problem."""

from __future__ import annotations

import asyncio
import logging
import time

import orjson

from service.errors import LIMIT, ShuttingDown, error_response, internal_error
from service.middleware.headers import request_id
from service.middleware.types import (
    REASON,
    T0,
    ASGIApp,
    Receive,
    Scope,
    Send,
    observed,
    status_of,
)

access_log = logging.getLogger("service.access")
#: A failed request's ``outcome`` when no layer noted why (the problem type: REASON)
_OUTCOME = {499: "client_disconnected", 503: "unavailable", 504: "deadline_exceeded"}


class AccessLog:
    """The access-log line of every request, whichever layer below answered it."""

    def __init__(self, app: ASGIApp, access_log: bool = True) -> None:
        self.app = app
        self.access_log = access_log

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0: float = scope.setdefault(T0, time.perf_counter())
        try:
            await observed(self.app, scope, receive, send)
        finally:
            log_request(scope, request_id(scope), status_of(scope, 500), t0, self.access_log)


class RequestContext:
    """The last-resort answers: a 500 problem, or a 503 once the shutdown grace ran out."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        try:
            await observed(self.app, scope, receive, send)
        except asyncio.CancelledError:  # the shutdown grace period ran out
            scope[REASON] = "shutting-down"
            if not status_of(scope, 0):  # (0: no answer started)
                busy = ShuttingDown("the server is shutting down; retry on another instance")
                await error_response(busy)(scope, receive, send)
            return  # answered: the cancellation ends here
        except Exception:  # the app's own 500 handler would run outside the middleware
            if not status_of(scope, 0):
                await internal_error(scope["method"], scope["path"])(scope, receive, send)


def log_request(scope: Scope, request_id: str, status: int, t0: float, enabled: bool) -> None:
    """The access-log line of a request answered (``enabled``: the setting)."""
    if not enabled or not access_log.isEnabledFor(logging.INFO):
        return  # not even built when nobody reads it
    client = scope.get("client")
    line = {
        "event": "request",
        "request_id": request_id,
        "client": f"{client[0]}:{client[1]}" if client else None,
        "method": scope["method"],
        "path": scope["path"][:200],
        "status": status,
        "ms": round((time.perf_counter() - t0) * 1000, 3),
    }
    # why a request failed: 499, 503 and 504 by their names of old (dashboards read them),
    # any other refusal by the problem type its answer carried (a 413 ``payload-too-large``
    # or ``too-many-items``, a 429 ``too-many-requests``), with the setting whose limit
    # refused it (a 413 or 429 said neither: only 499, 503 and 504 had an outcome, an ops
    # audit)
    if status in _OUTCOME:
        line["outcome"] = _OUTCOME[status]
    elif status >= 400 and REASON in scope:
        line["outcome"] = str(scope[REASON])
    if status >= 400 and LIMIT in scope:
        line["limit"] = scope[LIMIT]
    access_log.info(orjson.dumps(line).decode())
