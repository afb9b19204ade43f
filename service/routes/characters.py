"""``POST /v1/character/solve`` (a skeleton of the client's own, local rotations in and
out), ``POST /v1/bvh/solve`` (a BVH file in, the same file with one frame edited out) and
``POST /v1/bvh/inspect`` (read-only: the file's joints, joint map, units, axes, one frame).
The work is ``service.characters``; conventions: docs/characters.md."""

from __future__ import annotations

from fastapi import APIRouter, Response
from starlette.concurrency import run_in_threadpool

from service.body import BodyRoute
from service.characters import (
    BVHInspectRequest,
    BVHInspectResponse,
    BVHSolveRequest,
    BVHSolveResponse,
    CharacterSolveRequest,
    CharacterSolveResponse,
    bvh_answer,
    bvh_inspect,
    character_answer,
    character_from_bvh,
    character_from_request,
    read_request_bvh,
    solve_character,
)
from service.deps import ReadyEngine, State
from service.engine import Engine
from service.responses import json_response

router = APIRouter(route_class=BodyRoute, tags=["characters"])


@router.post("/v1/character/solve", response_model=CharacterSolveResponse)
async def character_solve(
    req: CharacterSolveRequest, engine: ReadyEngine, state: State
) -> Response:
    """Solve a character given in its own skeleton: local rotations of every joint out."""

    def work(engine: Engine) -> dict[str, object]:
        ch = character_from_request(req)
        edit = solve_character(engine, ch, req)
        state.metrics.solved(edit.problem.method, edit.result.solvers)
        return character_answer(ch, edit, req.rotations)

    return json_response(await run_in_threadpool(work, engine))


@router.post("/v1/bvh/solve", response_model=BVHSolveResponse)
async def bvh_solve(req: BVHSolveRequest, engine: ReadyEngine, state: State) -> Response:
    """Edit one frame of a BVH file: targets in the file's units and axes, the same file
    back with that frame changed (hierarchy, offsets, channel orders, the other frames and
    the frame time untouched)."""

    def work(engine: Engine) -> dict[str, object]:
        bvh = read_request_bvh(req.bvh)
        ch = character_from_bvh(bvh, req)
        edit = solve_character(engine, ch, req)
        state.metrics.solved(edit.problem.method, edit.result.solvers)
        return bvh_answer(bvh, ch, req, edit)

    return json_response(await run_in_threadpool(work, engine))


@router.post("/v1/bvh/inspect", response_model=BVHInspectResponse)
async def bvh_inspect_route(req: BVHInspectRequest) -> Response:
    """Read a BVH file without solving: its joints and channels, the joint map (where each
    canonical joint sits), units, up axis, frame count and time, and the world positions of
    one frame (``frame``, default 0), in the file's units and axes."""

    def work() -> dict[str, object]:
        bvh = read_request_bvh(req.bvh)
        return bvh_inspect(bvh, character_from_bvh(bvh, req), req.frame)

    return json_response(await run_in_threadpool(work))
