"""The hot paths, answered without the router: ``POST /v1/solve`` in the pose form and
``POST /v1/solve/batch`` in the columnar form.

Innermost (inside the gate: the API key, content type, body limits and admission hold),
so the request id, access log, timing, metrics and hardening headers are as for any
request. What it answers, it answers exactly as the routes would (the same problem
assembly, engine call and answer; for the columnar form the same code). Anything else - the
character form, the item list, a body that is not plainly valid, a single solve while the
models are not ready - goes on to the app with the body replayed, so every error is the
routes' own. A columnar batch is read here ready or not (its errors are this form's
words either way), then answered 503 while the models load.

Why: FastAPI's routing, dependency injection and response classes cost ~0.3 ms per
request, twice the engine's own time of a solve (docs/limits.md, "The hot path").
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import orjson
from pydantic import ValidationError
from starlette.requests import Request
from starlette.routing import BaseRoute

from service import columnar
from service.body import DECODED, INLINE_BYTES, decode, in_worker
from service.bounded import look
from service.decoded import COUNTED
from service.deps import ServiceState
from service.errors import BodyError, BodyInvalid, PoseError, error_response, refused
from service.limits import Budget
from service.middleware.types import REASON, ASGIApp, Message, Receive, Scope, Send
from service.pose_json import plain
from service.problems import SolveProblem
from service.responses import compute_time, solve_payload
from service.routes.solve import solve_columns, solve_one
from service.schemas import SolveRequest
from service.validation import check_bones, poses, problem_of, solve_problem

SOLVE, BATCH = "/v1/solve", "/v1/solve/batch"
_POSE = ["pose"].__getitem__  # (a pose's place in check_bones' words)


def _keys(req: SolveRequest) -> int:
    """Object keys of a pose-form body as validated (to tell a repeated key: see below)."""
    n = len(JOINTS) + 2 * len(req.targets) + len(req.model_fields_set)
    n += sum("weight" in t.model_fields_set for t in req.targets)
    return n + (len(req.options.model_fields_set) if "options" in req.model_fields_set else 0)


JOINTS = SolveRequest.model_fields["pose"].annotation.model_fields  # type: ignore[union-attr]


def pose_form(body: bytes, data: Any = None) -> SolveRequest | None:
    """The body as a pose-form request when it is plainly valid, else None (the route
    then reads it and words the error); ``data``: the body already decoded by orjson, if
    it is. orjson keeps the last of a repeated key where
    the routes' strict decoder refuses the body; a repeated key shows
    as fewer keys parsed than colons in the body (a colon outside strings follows a key;
    one inside a string only makes the count differ, which sends the body to the route)."""
    try:  # (decoded apart: pydantic's JSON mode would hand each model's validator a copy)
        req = SolveRequest.model_validate(
            orjson.loads(body) if data is None else data, context=look()
        )
    except (orjson.JSONDecodeError, ValidationError):
        return None
    return req if body.count(b":") == _keys(req) else None


def plain_problem(body: bytes) -> tuple[SolveProblem, bool] | None:
    """A pose-form body's problem and whether it has pins, where the body is plainly valid
    (read without the models where ``service.pose_json`` takes it, else by the model,
    :func:`pose_form`); None for anything else, which the route reads and words."""
    try:
        data = orjson.loads(body)
    except orjson.JSONDecodeError:
        return None
    try:
        if (form := plain(data)) is not None:  # (most bodies: read without the models)
            if body.count(b":") != form.keys:  # a repeated key: see pose_form
                return None
            check_bones(form.pose, _POSE)
            p = problem_of(form.pose[0], form.targets, form.goals, form.weights, form.pins,
                           form.options)  # fmt: skip
            return p, bool(form.pins)
        if (req := pose_form(body, data)) is not None:  # (the body decoded once)
            return solve_problem(req, poses([req], ["pose"])[0]), bool(req.pins)
    except PoseError:
        pass  # the route words it
    return None


def tokens(body: bytes, counted: dict[int, int] | None = None) -> tuple[int, int, int]:
    """Colons, ``true``/``false`` words and double quotes in ``body``, in vectorised passes
    (a third of the time of ``bytes.count`` each: ~0.6 against ~2 ms for 1,024 poses); the
    colons and quotes from ``counted`` where the gate counted them
    (``service.decoded.COUNTED``). A word is counted wherever its letters stand, inside
    strings too: a count can only be too high, which sends the body to the precise checks."""
    a = np.frombuffer(body, dtype=np.uint8)
    known = counted or {}
    colons = known.get(ord(":"))
    if colons is None:
        colons = int(np.count_nonzero(a == ord(":")))
    quotes = known.get(ord('"'))
    if quotes is None:
        quotes = int(np.count_nonzero(a == ord('"')))
    ends = np.flatnonzero(a == ord("e"))  # both words end in "e"
    bools = 0
    for word in (b"true", b"false"):
        at = ends[ends >= len(word) - 1]
        hit = np.ones(at.shape, dtype=np.bool_)
        for back, char in enumerate(reversed(word[:-1]), start=1):
            hit &= a[at - back] == char
        bools += int(np.count_nonzero(hit))
    return colons, bools, quotes


#: A run of digits an integer past 64 bits has (orjson reads it as a float), and the lists
#: open at once past which the strict decoder refuses a body (Python's recursion: ~990).
_LONG_DIGITS = 20
_DEEP = 900


def _read_otherwise(body: bytes) -> bool:
    """Whether the strict decoder may read ``body`` other than orjson did: it holds an
    integer of 20 digits or more, or lists and objects nested near the strict decoder's
    depth (brackets inside strings counted too: either may hold for a body both read
    alike, which is then read twice)."""
    a = np.frombuffer(body, dtype=np.uint8)
    digit = np.concatenate(([False], (a >= ord("0")) & (a <= ord("9")), [False]))
    edges = np.flatnonzero(digit[1:] != digit[:-1])  # each run's start, then its end
    if int((edges[1::2] - edges[::2]).max(initial=0)) >= _LONG_DIGITS:
        return True
    step = (a == ord("[")).astype(np.int32) + (a == ord("{")) - (a == ord("]")) - (a == ord("}"))
    return int(np.cumsum(step).max(initial=0)) >= _DEEP


def _strings(value: Any, depth: int = 2) -> int:
    """Strings in ``value``: itself, or a list's (lists of lists too, to ``depth``), or an
    object's values."""
    if type(value) is str:
        return 1
    if depth and type(value) is list:
        return sum(_strings(v, depth - 1) for v in value)
    if depth and type(value) is dict:
        return sum(_strings(v, 0) for v in value.values())
    return 0


def _named(data: dict[str, Any]) -> int:
    """The strings a columnar body holds where its form has them (joint names, pins, the
    options' words): with its keys, every string of a body whose quotes number twice
    theirs (a string among the numbers would make numpy build a text array of every row
    as wide as it: a 653 kB body took a worker to 1.3 GiB, a bigger one was a 500; an
    audit, 2026-12-06)."""
    targets = data.get("targets")
    joints, positions = (targets.get("joints"), targets.get("positions")) if isinstance(
        targets, dict) else (None, None)  # fmt: skip
    packed = (type(data.get("poses")) is str) + (type(positions) is str)  # (base64 columns)
    return (_strings(joints) + _strings(data.get("pins")) + _strings(data.get("options"), 1)
            + packed)  # fmt: skip


#: Values a valid columnar item holds at most (its pose's 63 numbers, 21 targets'
#: positions 63 and weights 21, rows of 21 joint names and pins), so commas in a valid body.
ITEM_VALUES = 192


def plausible(body: bytes, max_items: int, commas: int | None = None) -> bool:
    """Whether ``body`` may be a valid columnar batch, for orjson to read it: orjson holds
    the GIL for a whole body (6.5 MiB of numbers kept the event loop waiting 0.11-0.15 s,
    a real uvicorn), so one of ``INLINE_BYTES`` or more holding more values than
    ``max_items`` valid items could, or an item list (``"items"``), is read by the strict
    decoder, in steps (``service.stepped``), as the routes read bodies. ``commas``: the
    body's, where the gate counted them (``service.decoded.COUNTED``)."""
    if len(body) < INLINE_BYTES:
        return True
    if commas is None:
        commas = int(np.count_nonzero(np.frombuffer(body, dtype=np.uint8) == ord(",")))
    return commas <= ITEM_VALUES * max_items + 64 and b'"items"' not in body


def _columnar_keys(data: Any) -> int:
    """Keys of a columnar body where it has objects (top level, ``targets``, ``options``);
    -1 when it is not the columnar form."""
    if not columnar.is_columnar(data):
        return -1
    n = len(data)
    for key in ("targets", "options"):
        if isinstance(data.get(key), dict):
            n += len(data[key])
    return n


def read_columns(body: bytes, limit: int, scope: Scope) -> columnar.Columns | None:
    """A columnar batch read and validated (``limit``: items at most), or None: the body
    is not the columnar form (decoded by the strict decoder, it is left in ``scope`` for
    the route, ``service.body.DECODED``)."""
    strict, plain = False, False
    data: Any = None
    counted = scope.get(COUNTED, {})  # (the gate's counts of a big body's bytes)
    if plausible(body, limit, counted.get(ord(","))):
        try:
            data = orjson.loads(body)
            if not columnar.is_columnar(data):
                return None  # the item list: the route reads it
            colons, bools, quotes = tokens(body, counted)
            strict = _columnar_keys(data) == colons  # see pose_form
            # booleans only where options hold one, strings only where the form has them:
            # else every number's type is checked
            options = data.get("options")
            legit = isinstance(options, dict) and type(options.get("preserve_bone_lengths")) is bool
            plain = strict and bools == int(legit) and quotes == 2 * (colons + _named(data))
        except orjson.JSONDecodeError:  # NaN, or malformed: the strict decoder says
            pass
    if strict:
        try:
            return columnar.parse(data, limit, suspect=not plain)
        except BodyInvalid:
            # refused: where the routes' strict decoder may read the body otherwise, it is
            # read again so, and its problem is theirs (orjson takes an integer past 64 bits
            # for a float, and reads lists nested past the strict decoder's depth: an audit
            # found a 422 misquoting the one, and a 422 where the routes answer 400 for the
            # other); else the refusal stands (read again, a 63 kB body's cost 0.4 -> 1.5 ms)
            if not _read_otherwise(body):
                raise
            strict = False
    if not strict:
        data = None  # (orjson's objects freed before the body is decoded again)
        try:
            data = decode(body)
        except PoseError as exc:
            raise BodyError(exc) from None
    if not columnar.is_columnar(data):
        scope[DECODED] = data  # the route validates it, not decoded twice
        return None
    return columnar.parse(data, limit, suspect=True)


class FastPath:
    def __init__(self, app: ASGIApp, app_routes: Sequence[BaseRoute]) -> None:
        self.app = app
        self.routes = {
            getattr(r, "path", ""): r
            for r in app_routes
            if getattr(r, "path", "") in (SOLVE, BATCH)
        }

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        path = scope.get("path")
        if scope["type"] != "http" or scope["method"] != "POST" or path not in self.routes:
            await self.app(scope, receive, send)
            return
        messages: list[Message] = []
        chunks: list[bytes] = []
        while True:
            message = await receive()
            messages.append(message)
            if message["type"] != "http.request":
                break
            chunks.append(message.get("body", b""))
            if not message.get("more_body", False):
                break
        state: ServiceState = scope["app"].state.pose
        body = b"".join(chunks)
        scope["route"] = self.routes[path]  # the metrics' label
        done = False
        if messages[-1]["type"] == "http.request":
            if path == SOLVE and state.repository.ready:
                done = await self._solve(scope, receive, send, state, body)
            elif path != SOLVE:  # read whether or not the models are ready: the same words
                done = await self._columns(scope, receive, send, state, body)  # (then a 503)
        if done:
            return
        replay = list(reversed(messages))

        async def replayed() -> Message:
            return replay.pop() if replay else await receive()

        await self.app(scope, replayed, send)

    async def _solve(self, scope: Scope, receive: Receive, send: Send, state: ServiceState,
                     body: bytes) -> bool:  # fmt: skip
        if len(body) >= INLINE_BYTES or (read := plain_problem(body)) is None:
            return False
        p, pinned = read
        engine = state.repository.ready_engine()
        budget = Budget(Request(scope, receive), state.settings.deadline_seconds)
        try:
            result = await solve_one(p, pinned, engine, budget)  # the route's own
        except PoseError as exc:
            await _problem(scope, receive, send, exc)
            return True
        try:  # (counted once the answer is handed on: off the client's wait)
            answer = orjson.dumps(solve_payload(p, result, engine.version))
            await _json(send, answer, budget.compute)
        finally:
            state.metrics.solved(p.method, result.solvers)
        return True

    async def _columns(self, scope: Scope, receive: Receive, send: Send, state: ServiceState,
                       body: bytes) -> bool:  # fmt: skip
        limit = state.settings.max_batch_items
        request = Request(scope, receive)
        budget = Budget(request, state.settings.deadline_seconds)
        try:

            def read() -> columnar.Columns | None:
                return read_columns(body, limit, scope)

            small = len(body) < INLINE_BYTES
            cols = read() if small else await budget.in_thread(in_worker(read), "reading the body")
            if cols is None:
                return False
            engine = state.repository.ready_engine()
            response = await solve_columns(cols, engine, budget, state, request)
        except BodyError as exc:
            await _problem(scope, receive, send, exc.error)
            return True
        except BodyInvalid as exc:
            scope[REASON] = "invalid-request"
            await exc.answer()(scope, receive, send)
            return True
        except PoseError as exc:
            await _problem(scope, receive, send, exc)
            return True
        await response(scope, receive, send)
        return True


async def _problem(scope: Scope, receive: Receive, send: Send, exc: PoseError) -> None:
    refused(scope, exc)
    await error_response(exc)(scope, receive, send)


async def _json(send: Send, body: bytes, compute_seconds: float) -> None:
    await send(
        {
            "type": "http.response.start",
            "status": 200,
            "headers": [
                (b"content-length", str(len(body)).encode()),
                (b"content-type", b"application/json"),
                (b"x-compute-time", compute_time(compute_seconds).encode()),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})
