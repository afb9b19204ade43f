"""``POST /v1/solve`` and ``POST /v1/solve/batch``: to-canonical -> solve -> to-world is
the engine's; here: cross-field checks, the work budget, the answer."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

import anyio.to_thread
from fastapi import APIRouter, Request, Response

from service.body import BodyRoute
from service.deps import ReadyEngine, RequestBudget, State
from service.engine import SolveProblem
from service.errors import TooManyItems
from service.responses import json_response, solve_payload
from service.schemas import BatchRequest, BatchResponse, SolveRequest, SolveResponse
from service.validation import poses, solve_problem

router = APIRouter(route_class=BodyRoute, tags=["solve"])
INLINE_ITEMS = 32  # bigger batches are prepared and answered in a worker thread
R = TypeVar("R")


@router.post("/v1/solve", response_model=SolveResponse)
async def solve(req: SolveRequest, engine: ReadyEngine, budget: RequestBudget,
                state: State) -> Response:  # fmt: skip
    """Solve one pose edit: reach the targets, keep the pins, keep bone lengths."""
    p = solve_problem(req, poses([req], ["pose"])[0])
    if p.method == "neural" and p.reach == "soft" and not req.pins:
        t = time.perf_counter()  # ~0.3 ms: inline beats a thread hop
        (result,) = engine.solve([p])
        budget.compute += time.perf_counter() - t
    else:  # FABRIK iterations can take milliseconds: keep the event loop free
        (result,) = await budget.run(engine.solve, [p])
    state.metrics.solved(p.method, result.solvers)
    return json_response(solve_payload(p, result, engine.version), budget.compute)


@router.post("/v1/solve/batch", response_model=BatchResponse)
async def solve_batch(req: BatchRequest, engine: ReadyEngine, budget: RequestBudget,
                      state: State, request: Request) -> Response:  # fmt: skip
    """Many independent solves in one call, vectorised per solver sequence, run in
    priced chunks within the request deadline."""
    limit = state.settings.max_batch_items
    if len(req.items) > limit:
        raise TooManyItems(f"{len(req.items)} items exceed the limit of {limit} per batch")

    def prepare() -> list[SolveProblem]:
        arr = poses(req.items, [f"items[{i}].pose" for i in range(len(req.items))])
        return [solve_problem(item, arr[i], f"items[{i}]") for i, item in enumerate(req.items)]

    problems = await off_loop(request, prepare, len(req.items))
    results = await budget.run(engine.solve, problems)
    state.metrics.batch.observe(len(problems))
    for p, r in zip(problems, results, strict=True):
        state.metrics.solved(p.method, r.solvers)

    def answer() -> Response:
        pairs = zip(problems, results, strict=True)
        items = [solve_payload(p, r, engine.version) for p, r in pairs]
        return json_response({"items": items}, budget.compute)

    return await off_loop(request, answer, len(problems))


async def off_loop(request: Request, work: Callable[[], R], items: int) -> R:
    """Per-item Python work of a big batch in a worker thread (the loop stays free)."""
    if items <= INLINE_ITEMS:
        return work()
    limiter = request.app.state.compute_limiter
    return await anyio.to_thread.run_sync(work, limiter=limiter)
