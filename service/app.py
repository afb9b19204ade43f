"""Transport: the FastAPI application, assembled from its parts.

A request flows: middleware (``service.middleware``: the headers of every answer, CORS,
access log, metrics, the gate) -> a router (``service.routes``: body read
and validated by ``service.body`` and ``service.schemas``, cross-field checks in
``service.validation``) -> the data plane (``service.engine.Engine``) held by the model
repository (``service.repository``), which also holds readiness. ``service.errors``
maps every error to problem+json in one place.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import threading
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from starlette.routing import Mount

from service import middleware
from service.deps import ServiceState
from service.docs import document_problems, mount_docs
from service.editor import mount_editor
from service.errors import install_handlers
from service.limits import ComputeLimiter
from service.metrics import Metrics
from service.repository import ModelRepository
from service.routes import characters, complete, health, info, solve
from service.settings import Settings, get_settings


def _load(state: ServiceState, loop: asyncio.AbstractEventLoop) -> None:
    """Load the models, then freeze what is alive on the event loop's thread."""
    state.repository.load()
    with contextlib.suppress(RuntimeError):  # the loop closed: the process is exiting
        loop.call_soon_threadsafe(gc.freeze)


def create_app(settings: Settings | None = None, *, load_in_background: bool = True) -> FastAPI:
    """The app. Once the models are loaded, everything alive then (modules, sessions,
    schemas) is moved out of the garbage collector's reach (``gc.freeze``): collections
    then walk only what requests allocate (measured: the item-list batch ~1.7x faster,
    docs/speed.md, "HTTP")."""
    settings = settings or get_settings()
    state = ServiceState(settings, ModelRepository(settings), Metrics())

    @asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        if load_in_background:
            # A daemon thread, not awaited at shutdown: a stop while the models load (a
            # cold numba cache compiles for ~50 s) exits at once. The load was awaited, in
            # asyncio's executor, whose threads the interpreter also waits for: SIGTERM
            # then ran into the grace period and a SIGKILL (an ops audit).
            loop = asyncio.get_running_loop()
            threading.Thread(
                target=_load, args=(state, loop), name="marionette-load", daemon=True
            ).start()
            yield
        else:
            state.repository.load()
            gc.freeze()
            yield

    app = FastAPI(
        title="Marionette pose service",
        version="1.0.0",
        summary="Drag a few joints; get a natural full-body pose with exact bone lengths.",
        lifespan=lifespan,
        docs_url=None,  # mount_docs: self-hosted Swagger UI
        redoc_url=None,
        # /v1/solve/ is not /v1/solve: a 404 problem, not a bare 307 whose Location
        # repeats the client's Host header (an API audit, 2026-12-05)
        redirect_slashes=False,
        # metrics are Prometheus (service.metrics); FastAPI's OpenTelemetry hooks would
        # only look up unconfigured providers on every request (~10 µs)
        telemetry={"tracing": False, "metrics": False, "logs": False},
    )
    app.state.pose = state
    app.state.compute_limiter = ComputeLimiter(settings.compute_threads)
    install_handlers(app)
    routers = (solve.router, complete.router, info.router, health.router, characters.router)
    for router in routers:
        app.include_router(router)
    document_problems(app)
    mount_docs(app)
    mount_editor(app)
    # route templates for the metrics of requests refused before routing
    templates = [r for router in routers for r in router.routes]
    templates += [r for r in app.router.routes if getattr(r, "path", None)]
    # the paths a request may be answered at, for a 404's "without the slash" (a mount's
    # path is none: /static/ advised /static, itself a 404; an audit, 2026-12-06)
    app.state.route_paths = frozenset(
        getattr(r, "path", "") for r in templates if not isinstance(r, Mount)
    )
    middleware.install(app, settings, state.metrics, templates)
    return app
