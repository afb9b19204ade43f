"""Prometheus request metrics, labelled by route template (``/v1/solve``), also for
requests refused before routing (matched here against the app's routes), plus a
rejection counter by reason (the problem type). A request under a mount (``/static``,
``/docs/assets``) is labelled with the mount's path, served or not: the mount sets no
route in the scope, and its prefix, moved into the scope's ``root_path``, had the rest
matched against the app's own routes (``/static/editor`` counted as a 404 of ``/editor``,
``/static/`` of ``/``; an audit, 2026-12-06)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Sequence
from typing import Any

from starlette.routing import BaseRoute, Match

from service.metrics import Metrics
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


class RequestMetrics:
    def __init__(self, app: ASGIApp, metrics: Metrics, app_routes: Sequence[BaseRoute]) -> None:
        self.app = app
        self.metrics = metrics
        self.routes = app_routes
        self.children: dict[tuple[str, int], tuple[Any, Any]] = {}  # bounded: routes x statuses
        self.in_flight = metrics.in_flight

    def route_of(self, scope: Scope, root_path: str = "") -> str:
        """The label of a request whose scope is now ``scope`` and whose ``root_path`` was
        ``root_path`` when it arrived (a mount moves its prefix into it)."""
        route: Any = scope.get("route")
        if route is not None and getattr(route, "path", None):
            return str(route.path)
        if scope.get("root_path", "") != root_path:  # under a mount: match the whole path
            scope = {**scope, "root_path": root_path}
        # refused before routing, or under a mount: find the template (or the mount) anyway
        for candidate in self.routes:
            match, _ = candidate.matches(scope)
            if match is Match.FULL and getattr(candidate, "path", None):
                return str(candidate.path)  # type: ignore[attr-defined]
        return "unmatched"

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0: float = scope.setdefault(T0, time.perf_counter())
        root_path: str = scope.get("root_path", "")
        cancelled = False
        self.in_flight.inc()
        try:
            await observed(self.app, scope, receive, send)
        except asyncio.CancelledError:  # shutdown: RequestContext answers a 503
            cancelled = True
            scope[REASON] = "shutting-down"
            raise
        finally:
            self.in_flight.dec()
            status = status_of(scope, 500)  # (the answer as this layer saw it)
            if cancelled and status == 500:
                status = 503
            route = self.route_of(scope, root_path)
            m = self.metrics
            key = (route, status)
            children = self.children.get(key)
            if children is None:  # labels() looks up and locks: once per (route, status)
                children = (m.requests.labels(route, str(status)), m.latency.labels(route))
                self.children[key] = children
            children[0].inc()
            children[1].observe(time.perf_counter() - t0)
            if status >= 400:
                m.rejections.labels(route, str(scope.get(REASON, status))).inc()
