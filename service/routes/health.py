"""Open Inference Protocol health (``/v2/health/live``, ``/v2/health/ready``) and
Prometheus ``/metrics``. None of them reads a body or touches the engine."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response
from fastapi.responses import RedirectResponse
from prometheus_client.exposition import CONTENT_TYPE_PLAIN_0_0_4

from service.deps import State
from service.errors import refused
from service.routes import ROUTE_PROBLEMS
from service.schemas import Health

router = APIRouter(tags=["health"], responses=ROUTE_PROBLEMS)


# load balancers probe with HEAD: answered as GET (service.middleware.head)
@router.get("/v2/health/live", response_model=Health)
async def live() -> Health:
    """The process is up (Open Inference Protocol liveness)."""
    return Health(status="live")


@router.get(
    "/v2/health/ready",
    response_model=Health,
    responses={503: {"model": Health, "description": "Models not loaded or broken."}},
)
async def ready(request: Request, response: Response, state: State) -> Health:
    """200 once every model is loaded, verified and a warm-up solve passed; else 503
    with the reason (file names, never server paths): while they load with
    ``Retry-After``, once they failed (the service does not retry) without."""
    repo = state.repository
    if not repo.ready:
        response.status_code = 503
        why = repo.not_ready()
        # its problem type, as /v1's refusal for the same reason (pose_rejections_total,
        # the access log): it was reason="503" here, "not-ready" there (an ops audit)
        refused(request.scope, why)
        if why.retry_after is not None:
            response.headers["Retry-After"] = str(why.retry_after)
        return Health(status="not ready", detail=why.detail if repo.failed else repo.reason)
    return Health(status="ready")


@router.get("/metrics", response_class=Response)
async def metrics(state: State) -> Response:
    """Prometheus metrics (with several worker processes, the sum of all of them)."""
    # the text format 0.0.4 generate_latest writes and openapi.yaml declares (it was
    # CONTENT_TYPE_LATEST, version=1.0.0 since prometheus_client 0.22: an API audit)
    return Response(state.metrics.exposition(), media_type=CONTENT_TYPE_PLAIN_0_0_4)


@router.get("/", include_in_schema=False)
@router.get("/editor/", include_in_schema=False)  # (no slash redirects otherwise: service.app)
async def root() -> RedirectResponse:
    return RedirectResponse("/editor")  # a path: the Location never repeats the Host header
