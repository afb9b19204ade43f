"""ASGI types, the scope keys the middleware share, and their one shared step (:func:`observed`)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from service.errors import REASON, T0

__all__ = [
    "REASON", "REQUEST_ID", "STATUS", "T0", "ASGIApp", "Message", "Receive", "Scope", "Send",
    "observed", "status_of",
]  # fmt: skip

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

REQUEST_ID = "pose.request_id"


def header_map(scope: Scope) -> dict[str, str]:
    """The request's headers by lower-case name; a name sent on several lines has its values
    joined with ", ", as one list (RFC 9110 5.3: ``Transfer-Encoding: gzip`` then
    ``Transfer-Encoding: chunked`` is ``gzip, chunked``, not the last line alone)."""
    out: dict[str, str] = {}
    for k, v in scope["headers"]:
        name, value = k.decode("latin-1").lower(), v.decode("latin-1")
        out[name] = f"{out[name]}, {value}" if name in out else value
    return out


#: The scope's record of the answer's status (a list of one int, 0 until an answer
#: starts), kept by the outermost layer that observes it (:func:`observed`).
STATUS = "pose.status"


async def observed(app: ASGIApp, scope: Scope, receive: Receive, send: Send) -> None:
    """Run ``app``; :func:`status_of` then says the status of the answer it started. The
    outermost layer that calls this wraps ``send`` to note the status in the scope; the
    layers inside it, whose answers all pass through it, hand ``send`` on as it is and
    read the same note (a wrapper per layer cost every message an extra frame)."""
    if STATUS in scope:
        await app(scope, receive, send)
        return
    status = [0]
    scope[STATUS] = status

    async def observe(message: Message) -> None:
        if message["type"] == "http.response.start":
            status[0] = int(message["status"])
        await send(message)

    await app(scope, receive, observe)


def status_of(scope: Scope, default: int) -> int:
    """The status of the answer started by now (:func:`observed`), else ``default``."""
    status: list[int] | None = scope.get(STATUS)
    return status[0] if status and status[0] else default
