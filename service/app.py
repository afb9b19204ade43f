"""Transport: the FastAPI application, its routes and its middleware.

Routes translate JSON to validated problems and call the data plane (``Engine``);
``service.errors`` maps every domain error to problem+json in one place.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import logging
import time
import uuid
from collections.abc import AsyncIterator, Awaitable, Callable, MutableMapping
from contextlib import asynccontextmanager
from typing import Any

import numpy as np
import orjson
from fastapi import FastAPI, Response
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse, RedirectResponse
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, Counter, Histogram
from prometheus_client import generate_latest as prometheus_latest
from starlette.concurrency import run_in_threadpool

from core.manifest import ManifestError, SkeletonSpec, load_manifest
from core.skeleton import FRAME, JOINT_NAMES, PARENT_NAMES
from service.editor import mount_editor
from service.engine import Engine, SolveProblem, SolveResult
from service.errors import (
    NotReady,
    PayloadTooLarge,
    TooManyItems,
    Unauthorized,
    UnsupportedMediaType,
    install_handlers,
    internal_error,
    problem,
)
from service.schemas import (
    BatchRequest,
    BatchResponse,
    CompleteRequest,
    CompleteResponse,
    Health,
    ModelInfo,
    ModelsResponse,
    Problem,
    SkeletonResponse,
    SolveRequest,
    SolveResponse,
    TargetResult,
)
from service.settings import Settings, get_settings
from service.validation import parse_keypoints, parse_pose, parse_poses, parse_solve

log = logging.getLogger("service")
access_log = logging.getLogger("service.access")

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]


class Metrics:
    """Prometheus collectors of one app instance (own registry: apps don't collide)."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.requests = Counter(
            "pose_requests_total", "HTTP requests", ["route", "status"], registry=self.registry
        )
        self.latency = Histogram(
            "pose_request_seconds",
            "HTTP request latency",
            ["route"],
            buckets=(0.0005, 0.001, 0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0, 5.0),
            registry=self.registry,
        )
        self.solves = Counter(
            "pose_solves_total",
            "Solves by method and solver sequence",
            ["method", "solvers"],
            registry=self.registry,
        )
        self.batch = Histogram(
            "pose_batch_items",
            "Items per /v1/solve/batch request",
            buckets=(1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 4096),
            registry=self.registry,
        )


class State:
    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.engine: Engine | None = None
        self.skeleton: SkeletonSpec | None = None
        self.error: str | None = "loading models"
        self.metrics = Metrics()

    def ready_engine(self) -> Engine:
        if self.engine is None:
            raise NotReady(f"models not ready: {self.error}")
        return self.engine


def load_engine(state: State) -> None:
    """Load, verify and warm up the models; record why not when anything fails."""
    s = state.settings
    # the skeleton is served as soon as the manifest parses (before verification); a bad
    # manifest is reported with its reason by the Engine below
    with contextlib.suppress(ManifestError):
        state.skeleton = load_manifest(s.models_dir, verify=False).skeleton
    try:
        engine = Engine(
            s.models_dir,
            threads=s.ort_threads,
            composition_passes=s.composition_passes,
            composition=s.composition,
            composition_projections=s.composition_projections,
            fabrik_max_iterations=s.fabrik_max_iterations,
        )
        engine.warmup()
    except Exception as exc:  # any failure means "not ready", with the reason logged
        state.error = str(exc)
        log.error(
            json.dumps(
                {"event": "models_not_ready", "models_dir": str(s.models_dir), "reason": str(exc)}
            )
        )
        return
    state.engine = engine
    state.error = None
    log.info(
        json.dumps(
            {"event": "models_ready", "version": engine.version, "models_dir": str(s.models_dir)}
        )
    )


class Gate:
    """Pure-ASGI middleware: request id, timing header, body limit, content type, API key,
    metrics and one JSON access-log line per request."""

    def __init__(self, app: ASGIApp, state: State) -> None:
        self.app = app
        self.state = state

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0 = time.perf_counter()
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        request_id = headers.get("x-request-id") or uuid.uuid4().hex
        request_id = request_id[:128]
        path: str = scope["path"]
        method: str = scope["method"]
        status_box = [500]
        settings = self.state.settings

        async def send_wrapped(message: Message) -> None:
            if message["type"] == "http.response.start":
                status_box[0] = int(message["status"])
                extra = [
                    (b"x-request-id", request_id.encode("latin-1")),
                    (b"x-inference-time", f"{(time.perf_counter() - t0) * 1000:.3f}ms".encode()),
                ]
                message["headers"] = [*message.get("headers", []), *extra]
            await send(message)

        async def reject(resp: JSONResponse) -> None:
            await resp(scope, receive, send_wrapped)

        limit = settings.max_body_bytes
        try:
            secret = settings.api_key.get_secret_value() if settings.api_key else ""
            if path.startswith("/v1/") and secret and method != "OPTIONS":
                key = headers.get("x-api-key", "")
                auth = headers.get("authorization", "")
                if not key and auth.startswith("Bearer "):
                    key = auth.removeprefix("Bearer ")
                if not hmac.compare_digest(key.encode(), secret.encode()):
                    raise Unauthorized(
                        "send the API key in the X-API-Key header (or Authorization: Bearer)"
                    )
            has_body = headers.get("content-length", "0") != "0" or "transfer-encoding" in headers
            if method in ("POST", "PUT", "PATCH") and has_body:
                ctype = headers.get("content-type", "").split(";")[0].strip().lower()
                if ctype != "application/json":
                    raise UnsupportedMediaType(
                        f"content type must be application/json, got {ctype or 'none'!r}"
                    )
                length = headers.get("content-length")
                if length is not None and length.isdigit() and int(length) > limit:
                    raise PayloadTooLarge(f"body of {length} bytes exceeds the {limit}-byte limit")
        except (Unauthorized, UnsupportedMediaType, PayloadTooLarge) as exc:
            await reject(problem(exc.status, exc.title, exc.detail, type_=exc.type_))
            self._log(scope, request_id, status_box[0], t0)
            return

        if "content-length" not in headers and "transfer-encoding" in headers:
            # a chunked body: read it here, within the limit, then hand it on whole
            chunks: list[bytes] = []
            size = 0
            while True:
                message = await receive()
                if message["type"] != "http.request":
                    break
                chunks.append(message.get("body", b""))
                size += len(chunks[-1])
                if size > limit:
                    big = PayloadTooLarge(f"body exceeds the {limit}-byte limit")
                    await reject(problem(big.status, big.title, big.detail, type_=big.type_))
                    self._log(scope, request_id, status_box[0], t0)
                    return
                if not message.get("more_body", False):
                    break
            replay = [{"type": "http.request", "body": b"".join(chunks), "more_body": False}]

            async def receive_buffered() -> Message:
                return replay.pop() if replay else await receive()

            receive = receive_buffered

        started = [False]

        async def send_tracked(message: Message) -> None:
            started[0] = started[0] or message["type"] == "http.response.start"
            await send_wrapped(message)

        try:
            await self.app(scope, receive, send_tracked)
        except Exception:  # the app's own 500 handler would run outside this middleware
            response = internal_error(method, path)
            if not started[0]:
                await reject(response)
        self._log(scope, request_id, status_box[0], t0)

    def _log(self, scope: Scope, request_id: str, status: int, t0: float) -> None:
        seconds = time.perf_counter() - t0
        route = scope.get("route")
        route_path = getattr(route, "path", None) or "unmatched"
        m = self.state.metrics
        m.requests.labels(route_path, str(status)).inc()
        m.latency.labels(route_path).observe(seconds)
        if self.state.settings.access_log:
            access_log.info(
                json.dumps(
                    {
                        "event": "request",
                        "request_id": request_id,
                        "method": scope["method"],
                        "path": scope["path"],
                        "status": status,
                        "ms": round(seconds * 1000, 3),
                    }
                )
            )


def _pose_dict(pose: np.ndarray) -> dict[str, list[float]]:
    """A ``[21, 3]`` array as the API's joint-name -> [x, y, z] object."""
    return dict(zip(JOINT_NAMES, pose.tolist(), strict=True))


def _problem(req: SolveRequest, pose: np.ndarray, where: str = "") -> SolveProblem:
    o = req.options
    return parse_solve(
        pose,
        [(t.joint, t.position, t.weight) for t in req.targets],
        req.pins,
        method=o.method,
        preserve_bone_lengths=o.preserve_bone_lengths,
        reach=o.reach,
        tolerance=o.tolerance,
        where=where,
        floor=o.floor,
    )


def _payload(p: SolveProblem, r: SolveResult, version: str) -> dict[str, Any]:
    """The body of a SolveResponse as plain JSON types (the schema documents it; building
    dicts and encoding them once with orjson is ~40x cheaper than pydantic models and
    jsonable_encoder: 4 ms instead of 200 ms for 1024 poses)."""
    k = p.n_targets
    names = [JOINT_NAMES[int(j)] for j in p.target_idx]
    return {
        "pose": _pose_dict(r.pose),
        "targets": [
            {"joint": n, "error": e, "reached": e <= p.tolerance}
            for n, e in zip(names[:k], r.errors.tolist(), strict=True)
        ],
        "pins": [
            {"joint": n, "error": e, "reached": e <= p.tolerance}
            for n, e in zip(names[k:], r.pin_errors.tolist(), strict=True)
        ],
        "max_bone_length_error": r.max_bone_error,
        "solvers": r.solvers,
        "model": version,
        "method": "fabrik" if p.method == "fabrik" else "neural",
        "iterations": r.iterations,
    }


def _json(body: Any) -> Response:
    return Response(orjson.dumps(body), media_type="application/json")


_PROBLEM_STATUS = {
    400: "Body is not decodable JSON (e.g. not UTF-8).",
    401: "Missing or wrong API key (only when POSE_API_KEY is set).",
    413: "Body or batch larger than the configured limit.",
    415: "Body is not application/json.",
    422: "Invalid request: the detail says which field and why.",
    503: "Models not loaded yet, or broken (see /v2/health/ready).",
}


def _document_problems(app: FastAPI) -> None:
    """Make the schema say what the app does: errors are problem+json (RFC 9457)."""

    def openapi() -> dict[str, Any]:
        if app.openapi_schema:
            return app.openapi_schema
        from fastapi.openapi.utils import get_openapi

        schema = get_openapi(
            title=app.title, version=app.version, summary=app.summary, routes=app.routes
        )
        components = schema.setdefault("components", {}).setdefault("schemas", {})
        components["Problem"] = Problem.model_json_schema(
            ref_template="#/components/schemas/{model}"
        )
        for name in ("HTTPValidationError", "ValidationError"):
            components.pop(name, None)
        ref = {"$ref": "#/components/schemas/Problem"}
        for path, ops in schema["paths"].items():
            for method, op in ops.items():
                if not path.startswith("/v1/"):
                    continue
                codes = [400, 401, 413, 415, 422, 503] if method == "post" else [401, 503]
                for code in codes:
                    op["responses"][str(code)] = {
                        "description": _PROBLEM_STATUS[code],
                        "content": {"application/problem+json": {"schema": ref}},
                    }
        app.openapi_schema = schema
        return schema

    app.openapi = openapi  # type: ignore[method-assign]


def create_app(settings: Settings | None = None, *, load_in_background: bool = True) -> FastAPI:
    settings = settings or get_settings()
    state = State(settings)

    @asynccontextmanager
    async def lifespan(_: FastAPI) -> AsyncIterator[None]:
        if load_in_background:
            task = asyncio.create_task(asyncio.to_thread(load_engine, state))
            yield
            await task
        else:
            load_engine(state)
            yield

    app = FastAPI(
        title="Marionette pose service",
        version="1.0.0",
        summary="Drag a few joints; get a natural full-body pose with exact bone lengths.",
        lifespan=lifespan,
    )
    app.state.pose = state
    install_handlers(app)

    @app.post("/v1/solve", response_model=SolveResponse, tags=["solve"])
    async def solve(req: SolveRequest) -> Response:
        """Solve one pose edit: reach the targets, keep the pins, keep bone lengths."""
        engine = state.ready_engine()
        p = _problem(req, parse_pose(req.pose.model_dump()))
        if p.method == "neural" and p.reach == "soft":  # ~0.3 ms: inline beats a thread hop
            (result,) = engine.solve([p])
        else:  # FABRIK iterations can take milliseconds: keep the event loop free
            (result,) = await run_in_threadpool(engine.solve, [p])
        state.metrics.solves.labels(p.method, "|".join(result.solvers)).inc()
        return _json(_payload(p, result, engine.version))

    @app.post("/v1/solve/batch", response_model=BatchResponse, tags=["solve"])
    async def solve_batch(req: BatchRequest) -> Response:
        """Many independent solves in one call, vectorised per solver sequence."""
        engine = state.ready_engine()
        limit = settings.max_batch_items
        if len(req.items) > limit:
            raise TooManyItems(f"{len(req.items)} items exceed the limit of {limit} per batch")
        poses = parse_poses(
            [[getattr(item.pose, j) for j in JOINT_NAMES] for item in req.items],
            [f"items[{i}].pose" for i in range(len(req.items))],
        )
        problems = [_problem(item, poses[i], f"items[{i}]") for i, item in enumerate(req.items)]
        results = await run_in_threadpool(engine.solve, problems)
        state.metrics.batch.observe(len(problems))
        items = [_payload(p, r, engine.version) for p, r in zip(problems, results, strict=True)]
        return await run_in_threadpool(_json, {"items": items})

    @app.post("/v1/complete", response_model=CompleteResponse, tags=["complete"])
    async def complete(req: CompleteRequest) -> CompleteResponse:
        """A whole pose from key points alone (at least the six base points)."""
        engine = state.ready_engine()
        points = parse_keypoints([(kp.joint, kp.position) for kp in req.keypoints])
        result = engine.complete(points, req.bone_lengths, floor=req.floor)
        return CompleteResponse(
            pose=_pose_dict(result.pose),
            keypoints=[
                TargetResult(joint=j, error=float(e), reached=bool(ok))
                for j, e, ok in zip(points, result.errors, result.reached, strict=True)
            ],
            levels=result.levels,
            model=engine.version,
        )

    @app.get("/v1/skeleton", response_model=SkeletonResponse, tags=["info"])
    async def skeleton() -> SkeletonResponse:
        """Joint names, parents, reference bone lengths (m) and frame conventions
        (available as soon as the manifest parses, before the models are ready)."""
        spec = state.engine.manifest.skeleton if state.engine else state.skeleton
        if spec is None:
            state.ready_engine()  # raises NotReady with the reason
        assert spec is not None
        return SkeletonResponse(
            joints=list(JOINT_NAMES),
            parents=dict(PARENT_NAMES),
            reference_bone_lengths=dict(spec.reference_bone_lengths),
            frame=dict(FRAME),
        )

    @app.get("/v1/models", response_model=ModelsResponse, tags=["info"])
    async def models() -> ModelsResponse:
        """The loaded models: version, licence, solver sets, completion levels, metrics."""
        engine = state.ready_engine()
        m = engine.manifest
        return ModelsResponse(
            version=m.version,
            licence=m.licence,
            model_card="https://github.com/marionette/marionette/blob/main/models/README.md",
            solver_sets=sorted(m.solvers()),
            completion_levels=[list(e.joints) for e in m.completion_levels()],
            models=[
                ModelInfo(
                    name=e.name,
                    kind=e.kind,
                    key=e.key,
                    joints=list(e.joints),
                    parameters=e.parameters,
                    bytes=e.bytes,
                    metrics=dict(e.metrics),
                )
                for e in m.models
            ],
        )

    @app.get("/v2/health/live", response_model=Health, tags=["health"])
    async def live() -> Health:
        """The process is up (Open Inference Protocol liveness)."""
        return Health(status="live")

    @app.get(
        "/v2/health/ready",
        response_model=Health,
        tags=["health"],
        responses={503: {"model": Health, "description": "Models not loaded or broken."}},
    )
    async def ready(response: Response) -> Health:
        """200 once every model is loaded, verified and a warm-up solve passed; else 503."""
        if state.engine is None:
            response.status_code = 503
            return Health(status="not ready", detail=state.error)
        return Health(status="ready")

    @app.get("/metrics", tags=["health"], response_class=Response)
    async def metrics() -> Response:
        """Prometheus metrics."""
        return Response(prometheus_latest(state.metrics.registry), media_type=CONTENT_TYPE_LATEST)

    @app.get("/", include_in_schema=False)
    async def root() -> RedirectResponse:
        return RedirectResponse("/editor")

    _document_problems(app)
    mount_editor(app)
    app.add_middleware(Gate, state=state)
    if settings.cors_origins:  # outermost: even the Gate's rejections carry CORS headers
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST", "OPTIONS"],
            allow_headers=["Content-Type", "X-API-Key", "X-Request-ID", "Authorization"],
            expose_headers=["X-Request-ID", "X-Inference-Time"],
        )
    return app
