"""Pure-ASGI middleware, one concern per module, installed by :func:`install`.

Outermost first: the headers of every answer (``headers``: request id, ``x-total-time``,
hardening), CORS preflights and last-resort answers included; the access log
(``context.AccessLog``: preflights included); CORS (``cors``); the last-resort answers
(``context.RequestContext``); Prometheus metrics (``metrics``); the gate (``gate``: API
key, content type, body limits and the per-worker admission bound), HEAD answered as GET
(``head``), and innermost the hot paths (``fastpath``: the pose form of ``/v1/solve``
and the columnar batch answered without the router). Every rejection is problem+json.
"""

from __future__ import annotations

from collections.abc import Sequence

from fastapi import FastAPI
from starlette.routing import BaseRoute

from service.metrics import Metrics
from service.middleware.context import AccessLog, RequestContext
from service.middleware.cors import ProblemCORS
from service.middleware.gate import Gate
from service.middleware.head import HeadAsGet
from service.middleware.headers import AnswerHeaders
from service.middleware.metrics import RequestMetrics
from service.settings import Settings

#: Headers a browser client may read.
EXPOSED = ["X-Request-ID", "X-Total-Time", "X-Compute-Time", "Retry-After"]


def install(
    app: FastAPI, settings: Settings, metrics: Metrics, routes: Sequence[BaseRoute]
) -> None:
    """Add the stack; ``add_middleware`` puts each new one outside the previous.
    ``routes``: every route (flattened), to label refused requests by template."""
    from service.middleware.fastpath import FastPath  # imports the routes' modules

    app.add_middleware(FastPath, app_routes=routes)
    app.add_middleware(HeadAsGet)  # the routes see GET; the layers outside, HEAD
    app.add_middleware(Gate, settings=settings, app_routes=routes)
    app.add_middleware(RequestMetrics, metrics=metrics, app_routes=routes)
    app.add_middleware(RequestContext)
    if settings.cors_origins:  # outside the gate and the 500s: their answers carry CORS too
        app.add_middleware(
            ProblemCORS,
            preflights=metrics.preflights,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "OPTIONS"],
            allow_headers=["Content-Type", "X-API-Key", "X-Request-ID", "Authorization"],
            expose_headers=EXPOSED,
        )
    app.add_middleware(AccessLog, access_log=settings.access_log)  # CORS preflights too
    app.add_middleware(AnswerHeaders)
