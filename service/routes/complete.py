"""``POST /v1/complete``: a whole pose from key points."""

from __future__ import annotations

from fastapi import APIRouter, Response

from service.body import BodyRoute
from service.deps import ReadyEngine, RequestBudget
from service.responses import complete_payload, json_response
from service.routes import ROUTE_PROBLEMS
from service.schemas import CompleteRequest, CompleteResponse
from service.validation import keypoints

router = APIRouter(route_class=BodyRoute, tags=["complete"], responses=ROUTE_PROBLEMS)


@router.post("/v1/complete", response_model=CompleteResponse)
async def complete(req: CompleteRequest, engine: ReadyEngine, budget: RequestBudget) -> Response:
    """A whole pose from key points alone (at least the six base points)."""
    points = keypoints(req)
    await budget.check()
    with budget.timing():
        result = await budget.in_thread(
            lambda: engine.complete(points, req.bone_lengths, floor=req.floor), "the completion"
        )
    return json_response(complete_payload(list(points), result, engine.version), budget.compute)
