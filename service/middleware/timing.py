"""``X-Total-Time``: the whole request in ms, from arrival to the response's headers
(the engine's own time is the route's ``X-Compute-Time``)."""

from __future__ import annotations

import time

from service.middleware.types import T0, ASGIApp, Message, Receive, Scope, Send


class Timing:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0: float = scope.setdefault(T0, time.perf_counter())

        async def timed(message: Message) -> None:
            if message["type"] == "http.response.start":
                ms = f"{(time.perf_counter() - t0) * 1000:.3f}ms".encode()
                message["headers"] = [*message.get("headers", []), (b"x-total-time", ms)]
            await send(message)

        await self.app(scope, receive, timed)
