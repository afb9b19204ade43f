"""``POST /v1/solve`` and ``POST /v1/solve/batch``: to-canonical -> solve -> to-world is
the engine's; here: cross-field checks, the work budget, the answer. A request (or batch
item) is in the pose form (the 21 canonical joints) or the character form (a skeleton of
the client's own), answered by ``service.routes.characters.answer_character``'s path."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any, ClassVar, TypeVar

import numpy as np
from fastapi import APIRouter, Request, Response
from pydantic import (
    Discriminator,
    RootModel,
    Tag,
    ValidationInfo,
    ValidatorFunctionWrapHandler,
    model_validator,
)

from service import columnar
from service.body import BodyRoute
from service.characters import (
    BatchRequest,
    BatchResponse,
    CharacterSolveRequest,
    CharacterSolveResponse,
    SolveBody,
    field_error,
)
from service.deps import ReadyEngine, RequestBudget, ServiceState, State
from service.engine import Engine
from service.errors import InvalidRequest, every_item, too_many_items
from service.limits import Budget, Pricing, edit_price, price_of, refuse_price
from service.problems import SolveProblem, SolveResult
from service.responses import json_response, raw_response, solve_payload, starts_warnings
from service.routes import ROUTE_PROBLEMS
from service.routes.characters import answer_character, read_character, solve_read
from service.schemas import ColumnarBatch, ColumnarResponse, SolveRequest, SolveResponse
from service.validation import degenerate, poses, solve_problem, start_poses, validate_as

router = APIRouter(route_class=BodyRoute, tags=["solve"], responses=ROUTE_PROBLEMS)
INLINE_ITEMS = 32  # bigger batches are prepared and answered in a worker thread
R = TypeVar("R")


def _batch_form(data: Any) -> str:
    """The form a batch body is read as: columnar by its ``poses`` (``columnar.is_columnar``)
    or, without ``items``, by the columnar form's other keys, so that a columnar body
    missing its ``poses`` is told that (it was read as the item list: "items: Field
    required; pins: Extra inputs are not permitted"; an API audit, 2026-12-08)."""
    if columnar.is_columnar(data) or isinstance(data, ColumnarBatch):
        return "columns"
    own = isinstance(data, dict) and "items" not in data and bool({"targets", "pins"} & set(data))
    return "columns" if own else "items"


class BatchBody(
    RootModel[
        Annotated[
            Annotated[BatchRequest, Tag("items")] | Annotated[ColumnarBatch, Tag("columns")],
            Discriminator(_batch_form),
        ]
    ]
):
    """A batch in one of two forms: the **item list** (`items`, each in the pose or the
    character form, answered item by item) or the **columnar form** (`poses`, `targets`,
    `pins`, `options`: arrays in, arrays out; docs/limits.md)."""

    #: What a body that is no JSON object is told to send (``service.body.parse``).
    BODY_FORMS: ClassVar[str] = (
        'a JSON object, {"items": [...]} or the columnar form {"poses": [...], "targets": {...}},'
    )

    @model_validator(mode="wrap")
    @classmethod
    def _form(cls, data: Any, handler: ValidatorFunctionWrapHandler, info: ValidationInfo) -> Any:
        settings = (info.context or {}).get("settings")
        if isinstance(data, dict) and "items" in data:
            both = [key for key in columnar.TOP if key in data]
            if both:  # (was "poses: Extra inputs are not permitted")
                raise field_error(cls.__name__, (both[0],), BOTH_FORMS, data)
        items = data.get("items") if isinstance(data, dict) else None
        if settings is not None and isinstance(items, list):  # counted before validated
            too_many(len(items), settings.max_batch_items)
        return validate_as(
            data,
            handler,
            lambda d: ColumnarBatch if _batch_form(d) == "columns" else BatchRequest,
            info.context,
        )


#: A batch body with ``items`` and a columnar key (at most 200 characters: a message's).
BOTH_FORMS = (
    "a batch takes one form, not both: the item list (`items`) or the columnar form "
    "(`poses`, `targets`, `pins`, `options`); each item of a list carries its own options"
)


def too_many(n: int, limit: int) -> None:
    """413 for a batch of ``n`` items beyond ``limit``."""
    if n > limit:
        raise too_many_items("items", n, limit)


@router.post("/v1/solve", response_model=SolveResponse | CharacterSolveResponse)
async def solve(body: SolveBody, engine: ReadyEngine, budget: RequestBudget,
                state: State) -> Response:  # fmt: skip
    """Solve one pose edit: reach the targets, keep the pins, keep bone lengths. The pose
    form answers the 21 joints; the character form the local rotations of every joint of
    the client's skeleton and its root position (docs/characters.md)."""
    req = body.root
    if isinstance(req, CharacterSolveRequest):
        return json_response(await answer_character(req, engine, budget, state), budget.compute)
    p = solve_problem(req, poses([req], ["pose"])[0])
    result = await solve_one(p, bool(req.pins), engine, budget)
    state.metrics.solved(p.method, result.solvers)
    return json_response(solve_payload(p, result, engine.version), budget.compute)


async def solve_one(p: SolveProblem, pinned: bool, engine: Engine, budget: Budget) -> SolveResult:
    """One pose problem (``pinned``: it has pins), its engine time added to the budget's:
    a cheap one inline (:func:`inline`, one solver: 0.1-2 ms), anything else in a worker
    thread on a compute token within the deadline (FABRIK iterations, pins, exact reach, a
    turn search, extra passes or composed solvers can take milliseconds: the loop stays
    free). Whether an edit searches its turn, and how many solvers it needs, is known once
    its targets are looked at (``serving.turn_gate``): ``Engine.solve_lone`` looks, and
    solves it unless it searches (then solved in a worker from the items it was looked at
    as, ``Engine.solve_searching``) or needs more than one solver or the general path (then
    ``Engine.solve`` in a worker). Composed solvers ran on the loop too, once: a lone
    15-target soft edit held it 8-26 ms, liveness p50 23-53 ms under three clients of it
    (an API audit, 2026-12-08).

    The turn search ran inline too, once (in a worker it shares the GIL with the loop: a
    lone 5-target edit took 6.2 against 5.0 ms over HTTP), but a flood of them starved
    the loop: 64 clients of an 18-target searching edit with 4 passes, a 2 s deadline,
    every answer a 200, the last after 4.75 s, requests unread by the server for up to
    10 s (an audit; uvloop). The inline solve also checks the deadline first
    (``Budget.due``: a clock read, no await), as the worker path does before each wave."""
    if inline(p, pinned, engine):
        budget.due("the solve")
        with budget.timing():
            lone = engine.solve_lone(p)
        if isinstance(lone, SolveResult):
            return lone
        if lone is not None:  # it searches its turn: from the items it was looked at as
            searches = lone
            (result,) = await budget.run(
                lambda ps: [engine.solve_searching(ps[0], searches)], [p], Pricing.of(engine)
            )
            return result
    (result,) = await budget.run(engine.solve, [p], Pricing.of(engine))
    return result


def inline(p: SolveProblem, pinned: bool, engine: Engine) -> bool:
    """Whether a lone edit may be solved on the event loop: neural, soft reach, no pins and
    no more passes than the models serve (its cost then a few network runs,
    ``service.lean``), unless it searches its turn or needs more than one solver
    (``Engine.solve_lone`` tells)."""
    return (
        p.method == "neural" and p.reach == "soft" and not pinned
        and engine.passes_of(p) <= engine.serving.passes
    )  # fmt: skip


@router.post("/v1/solve/batch", response_model=BatchResponse | ColumnarResponse)
async def solve_batch(body: BatchBody, engine: ReadyEngine, budget: RequestBudget,
                      state: State, request: Request) -> Response:  # fmt: skip
    """Many independent solves in one call, in one of two forms. The **item list**: each
    item in either solve form, answered in order; pose items are vectorised per solver
    sequence and run in priced chunks within the request deadline; character items are
    solved one by one, as singles are, between deadline checks, and priced by their
    joints. The **columnar form**: arrays in (`poses`, `targets`, `pins`), arrays out,
    the same answers as the item list, bit for bit, for throughput."""
    if isinstance(body.root, ColumnarBatch):
        data = body.root.model_dump()
        cols = columnar.parse(data, state.settings.max_batch_items, suspect=False)
        return await solve_columns(cols, engine, budget, state, request)
    req = body.root
    limit = state.settings.max_batch_items
    too_many(len(req.items), limit)
    forms = [item.root for item in req.items]
    chars = {i: f for i, f in enumerate(forms) if isinstance(f, CharacterSolveRequest)}
    if chars:
        check_price(forms, limit, Pricing.of(engine))
    where = [i for i, f in enumerate(forms) if i not in chars]
    items = [f for f in forms if isinstance(f, SolveRequest)]  # the pose form, in order

    def prepare() -> tuple[list[SolveProblem], dict[int, InvalidRequest], int]:
        """The pose items' problems, each bad item's error (its index: a degenerate pose's
        alone) and how many degenerate ones are past those listed (``degenerate``)."""
        arr = start_poses(items)
        bad, found = degenerate(arr, lambda k: f"items[{where[k]}].pose")
        told = {where[k]: exc for k, exc in zip(bad, found, strict=False)}
        skip = set(bad)
        out = []
        for k, (i, item) in enumerate(zip(where, items, strict=True)):
            if k in skip:
                continue
            try:
                out.append(solve_problem(item, arr[k], f"items[{i}]"))
            except InvalidRequest as exc:  # every item's told, not the first one's alone
                told[i] = exc
        return out, told, len(bad) - len(found)

    problems, told, unlisted = await off_loop(budget, prepare, len(items), "preparing the items")
    total = len(forms)  # (a 504's counts: the pose items solve first, then the characters)
    prepared = {}
    for i, f in chars.items():  # every one read (each priced): a bad one stops none
        try:
            prepared[i] = await read_character(budget, f, f"items[{i}]", done=0, total=total)
        except InvalidRequest as exc:
            told[i] = exc
    if told:  # one 422 of every bad item's errors, pose and character, in item order
        raise every_item([told[i] for i in sorted(told)], len(told) + unlisted)
    # a mixed batch's pose items run first (a 504 then counts them), its characters after
    noun = f"pose items (then {len(chars)} character items)" if chars else "items"
    results = await budget.run(engine.solve, problems, Pricing.of(engine), noun)
    state.metrics.batch.observe(len(forms))
    for p, r in zip(problems, results, strict=True):
        state.metrics.solved(p.method, r.solvers)
    solved = {}
    for k, i in enumerate(chars):  # (each item's 504 counts what was done before it)
        at, done = f"items[{i}]", len(problems) + k
        solved[i] = await solve_read(
            budget, engine, state, chars[i], prepared[i], at, done=done, total=total
        )

    def answer() -> Response:
        starts = np.stack([p.pose for p in problems]) if problems else np.zeros((0, 21, 3))
        floors = np.array([p.floor for p in problems], dtype=np.float64)
        said = iter(starts_warnings(starts, floors))
        pairs = iter(zip(problems, results, strict=True))
        out = [solved[i] if i in solved
               else solve_payload(*next(pairs), engine.version, next(said))
               for i in range(len(forms))]  # fmt: skip
        return json_response({"items": out}, budget.compute)

    return await answer_off_loop(budget, answer, len(forms))


def check_price(forms: list[SolveRequest | CharacterSolveRequest], max_items: int,
                pricing: Pricing) -> None:  # fmt: skip
    """Refuse (413) a batch of more than one item that costs more than ``max_items`` of
    the costliest pose items: a character item costs by its joints
    (``service.limits.character_price``), a pose item as ``service.limits.price``
    (``pricing``: the engine's)."""
    prices = [
        edit_price(len(f.character.joints), f.options, bool(f.pins))
        if isinstance(f, CharacterSolveRequest)
        else price_of(f.options, bool(f.pins), pricing)
        for f in forms
    ]
    joints = [len(f.character.joints) if isinstance(f, CharacterSolveRequest) else 21
              for f in forms]  # fmt: skip
    refuse_price(prices, joints, max_items, pricing)


async def off_loop(budget: Budget, work: Callable[[], R], items: int, stage: str) -> R:
    """Per-item Python work of a big batch in a worker thread (the loop stays free), on a
    compute token taken within the deadline (``stage`` names it in a 504)."""
    if items <= INLINE_ITEMS:
        return work()
    return await budget.in_thread(work, stage, done=0, total=items)  # (a 504's counts)


async def answer_off_loop(budget: Budget, work: Callable[[], R], items: int) -> R:
    """The answer of a batch whose ``items`` are all solved: in a worker thread for a big
    batch as :func:`off_loop`, but without waiting for a compute token, so past the
    deadline too: a 504 now would throw the done work away (``Budget.answer_in_thread``)."""
    if items <= INLINE_ITEMS:
        return work()
    return await budget.answer_in_thread(work, items)


async def solve_columns(cols: columnar.Columns, engine: Engine, budget: Budget,
                        state: ServiceState, request: Request) -> Response:  # fmt: skip
    """A validated columnar batch: solved in priced parts within the budget, answered
    from the arrays (``service.columnar``)."""
    parts = await budget.run_parts(
        lambda part: columnar.solve(engine, cols, part),
        cols.parts(Pricing.of(engine)),
    )
    whole = columnar.merge(parts)
    state.metrics.batch.observe(cols.size)
    state.metrics.solved_paths(cols.options.method, whole.ans.paths, whole.ans.path_of)
    body = await answer_off_loop(
        budget, lambda: columnar.answer(cols, whole, engine.version), cols.size
    )
    return raw_response(body, budget.compute)
