"""CORS with problem+json rejections (Starlette answers a refused preflight in text), and
an access-log line for each preflight (answered here, before the access log's middleware
inside would see it)."""

from __future__ import annotations

import json
import time
from collections.abc import Sequence

from starlette.datastructures import Headers
from starlette.middleware.cors import CORSMiddleware
from starlette.responses import Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.errors import PROBLEM_BASE, PROBLEM_JSON
from service.middleware.context import log_request
from service.middleware.headers import request_id
from service.middleware.types import T0


class ProblemCORS(CORSMiddleware):
    def __init__(
        self,
        app: ASGIApp,
        allow_origins: Sequence[str],
        allow_methods: Sequence[str],
        allow_headers: Sequence[str],
        expose_headers: Sequence[str],
        access_log: bool = True,
    ) -> None:
        super().__init__(
            app,
            allow_origins=allow_origins,
            allow_methods=allow_methods,
            allow_headers=allow_headers,
            expose_headers=expose_headers,
        )
        self.access_log = access_log

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        headers = Headers(scope=scope) if scope["type"] == "http" else None
        if not (
            headers is not None
            and scope["method"] == "OPTIONS"
            and "origin" in headers
            and "access-control-request-method" in headers
        ):
            await super().__call__(scope, receive, send)
            return
        t0: float = scope.setdefault(T0, time.perf_counter())
        status = [500]

        async def tagged(message: Message) -> None:
            if message["type"] == "http.response.start":
                status[0] = int(message["status"])
            await send(message)

        await super().__call__(scope, receive, tagged)  # a preflight: answered here
        log_request(scope, request_id(scope), status[0], t0, self.access_log)

    def preflight_response(self, request_headers: Headers) -> Response:
        response = super().preflight_response(request_headers)
        if response.status_code < 400:
            return response
        detail = bytes(response.body).decode("utf-8", "replace")
        body = {
            "type": PROBLEM_BASE + "cors-rejected",
            "title": "CORS preflight rejected",
            "status": response.status_code,
            "detail": f"{detail} (allowed origins are configured with POSE_CORS_ORIGINS)",
        }
        keep = {
            k: v for k, v in response.headers.items() if k not in ("content-length", "content-type")
        }
        return Response(
            json.dumps(body), status_code=response.status_code, headers=keep,
            media_type=PROBLEM_JSON,
        )  # fmt: skip
