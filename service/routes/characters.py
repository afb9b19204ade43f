"""``POST /v1/character/solve`` (an alias of the character form of ``POST /v1/solve``: a
skeleton of the client's own, local rotations in and out), ``POST /v1/bvh/solve`` (a BVH
file in, the same file with one frame edited out) and ``POST /v1/bvh/inspect`` (read-only:
the file's joints, joint map, units, axes, one frame). The work is ``service.characters``;
:func:`answer_character` is the one path of every character solve (``/v1/solve``, its batch
items, the alias); conventions: docs/characters.md."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from fastapi import APIRouter, Response

from core.bvh import BVH
from service.body import BodyRoute
from service.character_bvh import bvh_answer, bvh_inspect, character_from_bvh, read_request_bvh
from service.characters import (
    BVHInspectRequest,
    BVHInspectResponse,
    BVHSolveRequest,
    BVHSolveResponse,
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
from service.limits import Budget
from service.problems import SolveProblem
from service.responses import json_response

router = APIRouter(route_class=BodyRoute, tags=["characters"])
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
        return bvh, character_from_bvh(bvh, req)

    bvh, ch = await step(budget, "reading the file", read)

    def work() -> dict[str, object]:
        edit = solve_character(engine, ch, req)
        state.metrics.solved(edit.problem.method, edit.result.solvers)
        return bvh_answer(bvh, ch, req, edit)

    return json_response(await step(budget, "the solve", work), budget.compute)


@router.post("/v1/bvh/inspect", response_model=BVHInspectResponse)
async def bvh_inspect_route(req: BVHInspectRequest, budget: RequestBudget) -> Response:
    """Read a BVH file without solving: its joints and channels, the joint map (where each
    canonical joint sits), units, up axis, frame count and time, and the world positions of
    one frame (``frame``, default 0), in the file's units and axes."""

    def work() -> dict[str, object]:
        bvh = read_request_bvh(req.bvh, req.frame)
        return bvh_inspect(bvh, character_from_bvh(bvh, req), req.frame, req.root_position)

    return json_response(await step(budget, "reading the file", work), budget.compute)
