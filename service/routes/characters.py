"""``POST /v1/character/solve`` (an alias of the character form of ``POST /v1/solve``: a
skeleton of the client's own, local rotations in and out), ``POST /v1/bvh/solve`` (a BVH
file in, the same file with one frame edited out), ``POST /v1/bvh/solve/batch`` (many
frames of one file edited in one call) and ``POST /v1/bvh/inspect`` (read-only:
the file's joints, joint map, units, axes, one frame). The work is ``service.characters``;
:func:`answer_character` is the one path of every character solve (``/v1/solve``, its batch
items, the alias); conventions: docs/characters.md."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from fastapi import APIRouter, Response

from core.bvh import BVH
from service.body import BodyRoute
from service.bvh_models import (
    BVHBatchRequest,
    BVHBatchResponse,
    BVHInspectRequest,
    BVHInspectResponse,
    BVHSolveRequest,
    BVHSolveResponse,
)
from service.character_bvh import (
    FrameAnswer,
    bvh_answer,
    bvh_inspect,
    character_from_bvh,
    clip_answer,
    clip_edits,
    clip_frames,
    frame_answer,
    read_request_bvh,
)
from service.characters import (
    Character,
    CharacterAliasRequest,
    CharacterSolveRequest,
    CharacterSolveResponse,
    character_answer,
    character_from_request,
    character_problem,
    solve_character,
    solve_prepared,
)
from service.deps import ReadyEngine, RequestBudget, ServiceState, State
from service.engine import Engine
from service.errors import TooManyItems, every_item
from service.limits import Budget, Pricing, edit_price, refuse_price
from service.problems import SolveProblem
from service.responses import json_response
from service.routes import ROUTE_PROBLEMS

router = APIRouter(route_class=BodyRoute, tags=["characters"], responses=ROUTE_PROBLEMS)
R = TypeVar("R")


async def step(budget: Budget, stage: str, work: Callable[[], R], **counts: int) -> R:
    """One stage of the work, as the solve routes run theirs: first the client (499), then
    ``work`` in a worker thread on a compute token taken within the deadline (504 naming
    ``stage``, :meth:`Budget.token`; ``counts``: a batch's ``done`` and ``total`` items)."""
    await budget.client_gone(**counts)
    with budget.timing():
        return await budget.in_thread(work, stage, **counts)


Prepared = tuple[Character, SolveProblem]


async def read_character(
    budget: Budget, req: CharacterSolveRequest, where: str = "", **counts: int
) -> Prepared:
    """Stage one of a character solve: the skeleton, its joint map and the canonical problem
    (every 422 of the request found here, before any solving); errors name ``where``
    (``counts``: a batch's, for its 504)."""

    def read() -> Prepared:
        ch = character_from_request(req, where)
        return ch, character_problem(ch, req, where)

    return await step(budget, f"reading {where or 'the skeleton'}", read, **counts)


async def solve_read(
    budget: Budget,
    engine: Engine,
    state: ServiceState,
    req: CharacterSolveRequest,
    prepared: Prepared,
    where: str = "",
    **counts: int,
) -> dict[str, object]:
    """Stage two: solve alone, retarget, answer (the same for a single request and a batch
    item, so both give the same bits); a 504 names ``where`` (a batch's item) and
    ``counts`` (the batch's ``done`` and ``total`` items)."""
    ch, p = prepared

    def work() -> dict[str, object]:
        edit = solve_prepared(engine, ch, p)
        state.metrics.solved(edit.problem.method, edit.result.solvers)
        return character_answer(ch, edit, req.rotations)

    return await step(budget, f"solving {where}" if where else "the solve", work, **counts)


async def answer_character(
    req: CharacterSolveRequest, engine: Engine, budget: Budget, state: ServiceState
) -> dict[str, object]:
    """A character solve's answer: rotations of every joint, root position, positions."""
    return await solve_read(budget, engine, state, req, await read_character(budget, req))


@router.post("/v1/character/solve", response_model=CharacterSolveResponse)
async def character_solve(
    req: CharacterAliasRequest, engine: ReadyEngine, budget: RequestBudget, state: State
) -> Response:
    """Alias of the character form of `POST /v1/solve` (same body, same answer; the
    skeleton may also be sent under its earlier name `skeleton`): a character given in its
    own skeleton, local rotations of every joint out."""
    return json_response(await answer_character(req, engine, budget, state), budget.compute)


@router.post("/v1/bvh/solve", response_model=BVHSolveResponse)
async def bvh_solve(
    req: BVHSolveRequest, engine: ReadyEngine, budget: RequestBudget, state: State
) -> Response:
    """Edit one frame of a BVH file: targets in the file's units and axes, the same file
    back with that frame changed (hierarchy, offsets, channel orders, the other frames and
    the frame time untouched)."""

    def read() -> tuple[BVH, Character]:
        bvh = read_request_bvh(req.bvh, req.frame)
        return bvh, character_from_bvh(bvh, req, req.frame)

    bvh, ch = await step(budget, "reading the file", read)

    def work() -> dict[str, object]:
        edit = solve_character(engine, ch, req)
        state.metrics.solved(edit.problem.method, edit.result.solvers)
        return bvh_answer(bvh, ch, req, edit)

    return json_response(await step(budget, "the solve", work), budget.compute)


@router.post("/v1/bvh/solve/batch", response_model=BVHBatchResponse)
async def bvh_solve_batch(
    req: BVHBatchRequest, engine: ReadyEngine, budget: RequestBudget, state: State
) -> Response:
    """Edit many frames of one BVH file in one call (a clip cleaned: a foot held through a
    contact, a hand kept on a prop): each edit names its frame, targets, pins and options,
    and is solved exactly as `POST /v1/bvh/solve` solves that frame alone; the file comes
    back once, with every edited frame's changed values rewritten, and each edit's report
    in request order. Priced by the file's joints per edit (413 past the batch's limit)."""
    budget.noun = "edits"  # (a 504 counts the edits done)
    frames = [e.frame for e in req.edits]
    bvh = await step(budget, "reading the file", lambda: read_request_bvh(req.bvh, frames))
    prices = [edit_price(len(bvh.joints), e.options, bool(e.pins)) for e in req.edits]
    framed = clip_frames(bvh, req)  # (edits refused for their frames: they cost nothing)
    try:
        refuse_price(prices, len(bvh.joints), state.settings.max_batch_items,
                     Pricing.of(engine), "edits")  # fmt: skip
    except TooManyItems:  # (told those first)
        if framed:
            raise every_item(list(framed.values())) from None
        raise
    total = len(req.edits)
    edits = await step(
        budget, "reading the edits", lambda: clip_edits(bvh, req, framed), done=0, total=total
    )
    done: list[FrameAnswer] = []
    for k, ((ch, p), e) in enumerate(zip(edits, req.edits, strict=True)):

        def work(ch: Character = ch, p: SolveProblem = p, frame: int = e.frame) -> FrameAnswer:
            edit = solve_prepared(engine, ch, p)
            state.metrics.solved(edit.problem.method, edit.result.solvers)
            return frame_answer(bvh, ch, frame, req.root_position, edit)

        done.append(await step(budget, f"solving edits[{k}]", work, done=k, total=total))
    state.metrics.batch.observe(total)
    answer = await budget.answer_in_thread(lambda: clip_answer(bvh, done), total)
    return json_response(answer, budget.compute)


@router.post("/v1/bvh/inspect", response_model=BVHInspectResponse)
async def bvh_inspect_route(req: BVHInspectRequest, budget: RequestBudget) -> Response:
    """Read a BVH file without solving: its joints and channels, the joint map (where each
    canonical joint sits), units, up axis, frame count and time, and the world positions of
    one frame (``frame``, default 0), in the file's units and axes."""

    def work() -> dict[str, object]:
        bvh = read_request_bvh(req.bvh, req.frame)
        ch = character_from_bvh(bvh, req, req.frame)
        return bvh_inspect(bvh, ch, req.frame, req.root_position)

    return json_response(await step(budget, "reading the file", work), budget.compute)
