"""HEAD answered as GET (RFC 9110 9.3.2: a server that answers GET answers HEAD): the
routes see ``GET``; the HTTP layer (uvicorn, which reads its own copy of the scope) sends
the answer's status and headers without its body. The middleware outside still see
``HEAD``, and what routing wrote into the scope (the route, for the request metrics'
template). A route without GET answers a HEAD as it answers a GET: 405."""

from __future__ import annotations

from service.middleware.types import ASGIApp, Receive, Scope, Send


class HeadAsGet:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if not (scope["type"] == "http" and scope["method"] == "HEAD"):
            await self.app(scope, receive, send)
            return
        inner = {**scope, "method": "GET"}
        try:
            await self.app(inner, receive, send)
        finally:  # what routing learnt (the route, a rejection's reason), for the metrics
            for key, value in inner.items():
                if key != "method":
                    scope[key] = value
