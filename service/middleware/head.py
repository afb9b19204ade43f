"""HEAD answered as GET (RFC 9110 9.3.2: a server that answers GET answers HEAD): the
routes see ``GET``; the HTTP layer (uvicorn, which reads its own copy of the scope) sends
the answer's status and headers without its body. The middleware outside still see
``HEAD``. A route without GET answers a HEAD as it answers a GET: 405."""

from __future__ import annotations

from service.middleware.types import ASGIApp, Receive, Scope, Send


class HeadAsGet:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] == "HEAD":
            scope = {**scope, "method": "GET"}
        await self.app(scope, receive, send)
