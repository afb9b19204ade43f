"""ASGI types, the scope keys the middleware share, and their one shared step (:func:`observed`)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from service.errors import REASON

__all__ = [
    "REASON", "REQUEST_ID", "T0", "ASGIApp", "Message", "Receive", "Scope", "Send", "observed",
]  # fmt: skip

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

T0 = "pose.t0"  # perf_counter() when the request arrived
REQUEST_ID = "pose.request_id"


def header_map(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}


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
