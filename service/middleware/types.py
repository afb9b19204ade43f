"""ASGI types, the scope keys the middleware share, and their one shared step (:func:`observed`)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from service.errors import REASON, T0

__all__ = [
    "REASON", "REQUEST_ID", "T0", "ASGIApp", "Message", "Receive", "Scope", "Send", "observed",
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


async def observed(
    app: ASGIApp, scope: Scope, receive: Receive, send: Send, status: list[int]
) -> None:
    """Run ``app`` with ``send`` wrapped so that ``status[0]`` holds the answer's status once
    it starts (left as it was where none started)."""

    async def observe(message: Message) -> None:
        if message["type"] == "http.response.start":
            status[0] = int(message["status"])
        await send(message)

    await app(scope, receive, observe)
