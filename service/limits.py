"""Bounded work per request: a deadline, a watch on the client, and batches run in
priced chunks so that one request never holds the worker for long.

A batch is cut into chunks of at most ``CHUNK_PRICE`` units (a plain neural item costs
1 per neural pass, ``options.passes`` or the models' default; an item that runs FABRIK -
exact reach, pins, the fabrik method - costs ``FABRIK_PRICE``, a neural one that also
polishes ``FABRIK_PRICE - 1`` plus its passes; a turn search multiplies the passes by
its solves; the engine's retry of a soft answer left short, ``serving.retry_reach``, adds
the one more pass it may run). The engine's side of a price is one :class:`Pricing`. Chunks run
in worker threads under the app's compute limiter, in waves as wide as the compute tokens
free at the time (so one big batch uses every compute thread: 1.6-1.9x the engine's
poses/s on 2); between waves the request checks its deadline and its client, and stops
(504 or 499) instead of computing answers nobody will read.

The polish of a soft answer its retry still leaves short (``serving.retry_polish``) is not
priced: it runs for the few answers the networks leave over ``retry_reach`` (5 mm) short
(2-7 % of real edits: docs/service.md, `scripts/figures/polish_share.py`), each bounded by
the iteration cap (at most ~0.6 ms an item, 5 targets at tolerance 0, both stages at the
cap: 512 iterations; where the polish leaves a target short, exact reach's fallback runs
FABRIK twice more, from the caller's start and from the body moved across, each as
bounded), so a chunk of soft items that all polish runs at most some tens of ms longer.
Priced as exact reach's, it would cut a chunk of shipped 2-target soft items to under a
third (42 -> 12 items at 256 units a chunk) and halve a batch's poses/s on 2 threads
(18-22k -> 8-9k, measured in one process).
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import math
import time
import traceback
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol, TypeVar

import anyio
import anyio.to_thread
from fastapi import Request

from service.errors import ClientDisconnected, DeadlineExceeded, TooManyItems
from service.middleware.types import T0, Message
from service.problems import SolveProblem
from service.schemas import MAX_PASSES
from service.turns import NO_SEARCH, TurnSearch

if TYPE_CHECKING:
    from service.engine import Engine

#: Units per chunk: ~10 ms of a batch's 2-target soft items (170 at the shipped 2 passes
#: with the mirror image). Chunks of 256 units (42 such items) spent a third of their time
#: on the engine's per-call work: a columnar 1,024-edit batch over HTTP went 5.2-8.3k ->
#: 11.9-13.5k poses/s at 1,024 (11.1-11.3k at 512, 14.1-15.1k at 2,048), and lone edits
#: sent beside a stream of such batches kept their latency (p50 4.7-5.2 -> 4.5-4.6 ms, p99
#: 11.8-12.6 -> 12.3-12.8 ms: they run on the event loop, not in chunks); /tmp scripts,
#: two rounds each, interleaved. A chunk in process (/tmp script): 2-target soft items 13 ms,
#: 3-joint composed ones 30 ms, turn-searching 5-target ones 12 ms, exact 5 ms, FABRIK 2 ms.
CHUNK_PRICE = 1024
FABRIK_PRICE = 16
R = TypeVar("R")


class Priced(Protocol):
    """What an item's price reads: a problem's or a request's options."""

    @property
    def method(self) -> str: ...
    @property
    def reach(self) -> str: ...
    @property
    def passes(self) -> int | None: ...
    @property
    def turn_search(self) -> bool | None: ...
    @property
    def mirror(self) -> bool | None: ...


@dataclass(frozen=True)
class Pricing:
    """What an engine adds to an item's price: ``passes``, its default neural passes (for
    items that do not say); ``search``, its turn search; ``retry``, whether it gives a soft
    answer left short one more pass (``serving.retry_reach``, ``service.retry``);
    ``mirror``, whether its passes also solve the mirror image (for items that do not
    say; ``serving.solve_mirror``)."""

    passes: int = 1
    search: TurnSearch = NO_SEARCH
    retry: bool = False
    mirror: bool = False

    @staticmethod
    def of(engine: Engine) -> Pricing:
        return Pricing(
            engine.serving.passes,
            engine.turn_search,
            engine.serving.retry_reach > 0.0,
            engine.serving.solve_mirror,
        )


def neural_price(
    slow: bool, passes: int, search: int = 1, retry: bool = False, views: int = 1
) -> int:
    """A neural item of ``passes`` passes: one unit per pass (times ``search``, its turn
    search's solves), one more for the engine's ``retry`` (soft items), all times its
    ``views`` (2 with the mirror image), plus the FABRIK polish's ``FABRIK_PRICE - 1``
    when it runs one (exact reach, pins)."""
    return (passes * search + int(retry)) * views + (FABRIK_PRICE - 1 if slow else 0)


def price_of(o: Priced, pinned: bool, pricing: Pricing, search: int = 1) -> int:
    """Relative cost of one pose item (measured: an exact-reach item ~10 ms, a neural pass
    well under 0.1 ms in a batch) with options ``o`` (``pinned``: it has pins) on an engine
    priced ``pricing``; ``search``: the solves per pass of its turn search
    (``TurnSearch.factor``, 1 without)."""
    if o.method == "fabrik":
        return FABRIK_PRICE
    p = pricing.passes if o.passes is None else o.passes
    soft = o.reach != "exact"
    views = 2 if (pricing.mirror if o.mirror is None else o.mirror) else 1
    return neural_price(not soft or pinned, p, search, pricing.retry and soft, views)


def searched_price(o: Priced, n_targets: int, pinned: bool, pricing: Pricing) -> int:
    """:func:`price_of` an item of ``n_targets`` targets with its turn search priced in
    (the solves ``pricing.search`` gives it, ``TurnSearch.factor``)."""
    factor = pricing.search.factor(o.method, n_targets, pinned, o.turn_search)
    return price_of(o, pinned, pricing, factor)


def price(p: SolveProblem, pricing: Pricing) -> int:
    """:func:`searched_price` of a validated problem."""
    return searched_price(p, p.n_targets, len(p.target_idx) > p.n_targets, pricing)


def chunks(problems: Sequence[SolveProblem], pricing: Pricing) -> list[slice]:
    """Consecutive slices of at most ``CHUNK_PRICE`` units (at least one item each)."""
    return chunks_of([price(p, pricing) for p in problems])


def chunks_of(prices: Sequence[int]) -> list[slice]:
    """:func:`chunks` of items priced ``prices`` (the array path's items have no objects)."""
    out: list[slice] = []
    start, total = 0, 0
    for i, cost in enumerate(prices):
        if i > start and total + cost > CHUNK_PRICE:
            out.append(slice(start, i))
            start, total = i, 0
        total += cost
    if start < len(prices):
        out.append(slice(start, len(prices)))
    return out


class ComputeLimiter:
    """The app's compute tokens (``POSE_COMPUTE_THREADS``), handed to the OLDEST waiting
    request first (by arrival time), not to the one that asked first.

    A request asks again at each stage (its body, its items, each wave, its answer). With
    first-come tokens, requests that arrive together advance together, a stage each in
    turn, and under overload all of them pass the deadline: 42 columnar 1,024-edit batches
    sent at once (2 s deadline) were 42 504s. Oldest-first lets the first arrivals finish
    while the later ones wait (and end at their deadline, :meth:`Budget.token`).

    Event-loop only (no thread calls it). The methods a request uses are
    ``anyio.CapacityLimiter``'s, ``age`` added: a request's arrival time (lower: older)."""

    def __init__(self, total_tokens: int) -> None:
        self.total_tokens = total_tokens
        self._holders: set[object] = set()
        self._waiting: list[tuple[float, int, object, anyio.Event]] = []  # a heap
        self._order = itertools.count()

    @property
    def borrowed_tokens(self) -> int:
        return len(self._holders)

    def acquire_on_behalf_of_nowait(self, borrower: object) -> None:
        """A token now, if one is free and no request waits for one (``anyio.WouldBlock``
        otherwise)."""
        if self._waiting or len(self._holders) >= self.total_tokens:
            raise anyio.WouldBlock
        self._holders.add(borrower)

    async def acquire_on_behalf_of(self, borrower: object, age: float = -math.inf) -> None:
        """A token for ``borrower``, once every older waiter has had one."""
        try:
            self.acquire_on_behalf_of_nowait(borrower)
            return
        except anyio.WouldBlock:
            pass
        entry = (age, next(self._order), borrower, anyio.Event())
        heapq.heappush(self._waiting, entry)
        try:
            await entry[3].wait()
        except BaseException:  # cancelled (its deadline): give up its place, or its token
            if borrower in self._holders:
                self.release_on_behalf_of(borrower)
            else:
                self._waiting.remove(entry)
                heapq.heapify(self._waiting)
            raise

    def release_on_behalf_of(self, borrower: object) -> None:
        """Give ``borrower``'s token back: straight to the oldest waiter, if any."""
        self._holders.remove(borrower)
        if self._waiting:
            _, _, next_borrower, ready = heapq.heappop(self._waiting)
            self._holders.add(next_borrower)
            ready.set()


#: The ASGI scope's key for :attr:`Budget.waited`.
WAITED = "marionette.token_wait"


class _Timing:
    """:meth:`Budget.timing`'s block."""

    __slots__ = ("budget", "t", "waited")

    def __init__(self, budget: Budget) -> None:
        self.budget = budget

    def __enter__(self) -> None:
        self.t, self.waited = time.perf_counter(), self.budget.waited

    def __exit__(self, kind: object, *exc: object) -> None:
        if kind is None:  # (a block that raised adds nothing, as before)
            b = self.budget
            b.compute += time.perf_counter() - self.t - (b.waited - self.waited)


class Budget:
    """One request's deadline and its client; ``compute`` accumulates engine seconds."""

    def __init__(self, request: Request, deadline_seconds: float) -> None:
        self.request = request
        self.t0: float = request.scope.get(T0, time.perf_counter())
        self.deadline_seconds = deadline_seconds
        self.compute = 0.0
        self._watch: asyncio.Future[Message] | None = None
        #: what a 504's counts count (a clip's route says "edits")
        self.noun = "items"

    @property
    def waited(self) -> float:
        """Seconds the request waited for compute tokens (:meth:`token`), by every budget
        of it (its body's reading has one of its own): kept in its ASGI scope."""
        return float(self.request.scope.get(WAITED, 0.0))

    def _waited(self, seconds: float) -> None:
        self.request.scope[WAITED] = self.waited + seconds

    def timing(self) -> _Timing:
        """Add the block's time to ``compute``, less what it waited for compute tokens:
        ``X-Compute-Time`` is the engine's own work (an API audit, 2026-12-06: a small
        ``/v1/complete`` behind two batches said 14.6 ms, its wait, against 1.2 ms alone).
        (A class, not a generator's context manager: a third of its cost, and a lone edit
        on the event loop pays it.)"""
        return _Timing(self)

    @property
    def left(self) -> float:
        return self.t0 + self.deadline_seconds - time.perf_counter()

    @property
    def _over(self) -> str:
        """The start of every 504 of this budget's deadline."""
        return f"the request needed more than the {self.deadline_seconds:g} s deadline"

    @property
    def _own_work(self) -> bool:
        """Whether the request's own compute took half its deadline or more: the same
        request would need as long again, so a 504 says no ``Retry-After``."""
        return self.compute >= self.deadline_seconds / 2

    def late(self, stage: str, **counts: int) -> DeadlineExceeded:
        """The 504 of a request whose deadline passed before ``stage`` began (``counts``:
        a batch's ``done`` and ``total``, in the detail and as members, as an overrun's).
        ``Retry-After`` as :meth:`overrun` gives it: not where the request's own compute
        took half its deadline or more (a batch of 600 character items, each solved in
        its own stage, was told to retry after 1 s at every try, without its counts: a
        user's audit, 2026-12-06)."""
        own = self._own_work
        said = [
            f"before {stage}",
            f"{counts['done']} of {counts['total']} {self.noun} done" if counts else "",
            f"{self.compute:.2f} s of its own compute" if own else "",
        ]
        advice = "send a smaller request" if own else "retry, or send a smaller request"
        exc = DeadlineExceeded(
            f"{self._over} ({'; '.join(w for w in said if w)}); {advice}", **counts
        )
        if own:
            exc.retry_after = None
        return exc

    def due(self, stage: str) -> None:
        """Raise :meth:`late` when the deadline has passed: one clock read and a float
        comparison, for work run on the event loop without a compute token (the lone soft
        edit, ``service.routes.solve.solve_one``), which :meth:`token` never sees."""
        if time.perf_counter() >= self.t0 + self.deadline_seconds:
            raise self.late(stage)

    async def client_gone(self, done: int = 0, total: int = 0) -> None:
        """Raise (499, never sent) when the client has gone away.

        The request's body is read by now, so its next ASGI message says the client left
        (or the answer was sent): the first look starts a task awaiting it, lets it run
        once (a message already there is taken at once), and every look reads that task.
        Starlette's ``Request.is_disconnected`` asks anew each time, in a cancelled anyio
        scope whose cancel message formats the task: ~0.3 ms a look, a wave of a batch
        each (1.1 ms of a columnar 1,024-edit batch's 35 ms, in the event loop)."""
        if self._watch is None:
            self._watch = asyncio.ensure_future(self.request.receive())
            self._watch.add_done_callback(_retrieved)
            await asyncio.sleep(0)
        if not self._watch.done():
            return
        w = self._watch
        failed = w.cancelled() or w.exception() is not None  # (the connection broke: gone)
        if not failed and w.result().get("type") != "http.disconnect":
            # (a message of another kind: dropped, as Starlette drops it; look again)
            self._watch = None
            return
        raise ClientDisconnected(f"client went away after {done} of {total} items")

    async def check(self, done: int = 0, total: int = 0, noun: str = "items") -> None:
        """Raise when the work should stop: client gone, deadline passed (the 504 says
        ``done`` of ``total`` ``noun`` were done)."""
        await self.client_gone(done, total)
        if self.left <= 0:
            raise self.overrun(done, total, noun)

    def overrun(self, done: int, total: int, noun: str) -> DeadlineExceeded:
        """The 504 of work the deadline stopped: ``done`` and ``total`` as members too (a
        client sizing its batches need not parse the detail); ``Retry-After`` unless the
        request's own compute took half its deadline or more (the same request would need
        as long again, however idle the server: an API audit, 2026-12-06, saw a batch that
        needs ~4.5 s told to retry after 1 s at every try). Where the time went to waiting
        (compute threads, a busy event loop, the body), a retry may fit."""
        own = self._own_work
        why = (
            f"{self.compute:.2f} s of its own compute" if own
            else f"{self.compute:.2f} s of it compute, the rest waiting: the server is busy"
        )  # fmt: skip
        exc = DeadlineExceeded(
            f"{self._over} ({done} of {total} {noun} done; {why}); send smaller batches",
            done=done, total=total,
        )  # fmt: skip
        if own:
            exc.retry_after = None
        return exc

    async def token(
        self, limiter: ComputeLimiter, borrower: object, stage: str, **counts: int
    ) -> None:
        """Take one of ``limiter``'s compute tokens for ``borrower``, waiting no longer than
        the deadline leaves: past it, a 504 that names ``stage`` (and a batch's ``done``
        and ``total`` items, ``counts``, as an overrun's). A request queued behind
        busy compute threads thus ends at its deadline, not once its turn comes (64
        1,024-item batches at once: the last 504 came after 25 s before this bound)."""
        t, left = time.perf_counter(), self.left
        if left > 0:
            with anyio.move_on_after(left):
                try:
                    await limiter.acquire_on_behalf_of(borrower, self.t0)
                finally:
                    self._waited(time.perf_counter() - t)
                return
        if left <= 0 or self._own_work:  # (its own work's: late)
            raise self.late(stage, **counts)
        raise DeadlineExceeded(
            f"{self._over} (before {stage}, after {time.perf_counter() - t:.2f} s waiting for a "
            "compute thread): the server is busy; retry later, or send a smaller request",
            **counts,
        )

    async def in_thread(self, work: Callable[[], R], stage: str, **counts: int) -> R:
        """``work()`` in a worker thread on one of the app's compute tokens, taken within
        the deadline (:meth:`token`; ``counts``: a batch's, for its 504)."""
        limiter: ComputeLimiter | None = getattr(self.request.app.state, "compute_limiter", None)
        if limiter is None:
            return await anyio.to_thread.run_sync(work)
        borrower = object()
        await self.token(limiter, borrower, stage, **counts)
        try:
            return await anyio.to_thread.run_sync(work)
        except BaseException as exc:
            # The error's traceback and anyio's future that carried it form a cycle, which
            # kept the frames of ``work`` - a body decoded, to the last list - until the
            # cyclic collector ran (rarely: what lives past the start is frozen, and what
            # a request leaves is in the oldest generation by then): eight 8.3 MB columnar
            # bodies of 14,000 rows, each a 413, took a worker from 330 to 701 MiB, one
            # at a time within the decode budget. Their locals go now; lines stay for logs.
            traceback.clear_frames(exc.__traceback__)
            raise
        finally:
            limiter.release_on_behalf_of(borrower)

    async def answer_in_thread(self, work: Callable[[], R], total: int) -> R:
        """``work()``, the answer of a request whose ``total`` items are all done, in a
        worker thread WITHOUT a compute token and whatever the deadline leaves (only a
        client gone away stops it, 499).

        It took a token within the deadline, as every stage does (:meth:`in_thread`): under
        overload none came in time and a batch whose every item was solved was answered
        504 "before writing the answer", its work thrown away (16 columnar 1,024-edit
        batches at once, 2 s deadline: 1 of the 16 in one round, a /tmp script). The
        deadline bounds work not yet begun; this work is bounded without it: an answer of
        at most ``POSE_MAX_BATCH_ITEMS`` items already computed (1,024: ~2 ms columnar,
        15-70 ms as an item list, measured in process on this shared 2-core host), once per
        request, for at most ``POSE_MAX_CONCURRENCY`` requests admitted at once. Waiting for
        a token past the deadline instead would make a done answer wait for other requests'
        stages, holding its results meanwhile; without one the answer leaves and its memory
        is freed at once (its Python shares the GIL with the compute threads' as the event
        loop's does: onnxruntime and the compiled kernels run without it)."""
        await self.client_gone(total, total)
        return await anyio.to_thread.run_sync(work)

    async def run(self, fn: Callable[[Sequence[SolveProblem]], list[R]],
                  problems: Sequence[SolveProblem], pricing: Pricing,
                  noun: str = "items") -> list[R]:  # fmt: skip
        """``fn`` over ``problems`` chunk by chunk, off the event loop, within budget
        (``pricing``: the engine's, :meth:`Pricing.of`; ``noun``: what a 504 counts)."""
        parts = await self.run_parts(
            lambda part: fn(problems[part]), chunks(problems, pricing), noun
        )
        return [r for part in parts for r in part]

    async def run_parts(
        self, fn: Callable[[slice], R], parts: Sequence[slice], noun: str = "items"
    ) -> list[R]:
        """``fn`` over consecutive ``parts`` of a batch of ``parts[-1].stop`` items (the
        array path): like :meth:`run`, each part in a worker thread within budget.

        Parts run in waves of up to ``compute_threads`` parts, each wave on the compute
        tokens free when it starts (:func:`_wave`), so a lone big batch uses every compute
        thread; the budget is checked before each wave. An
        item's answer does not depend on its part or on what runs beside it (the engine
        computes every item alone), so the answers are the same whatever the width."""
        limiter = getattr(self.request.app.state, "compute_limiter", None)
        width = max(1, int(limiter.total_tokens)) if limiter is not None else 1
        total = parts[-1].stop if parts else 0
        out: list[R] = []
        for w in range(0, len(parts), width):
            wave = parts[w : w + width]
            await self.check(wave[0].start, total, noun)
            with self.timing():
                out.extend(await _wave(fn, wave, limiter, self, total))
        return out


def _retrieved(watch: asyncio.Future[Message]) -> None:
    """A client watch that failed after its request's last look: its error read (asyncio
    would log it as never retrieved)."""
    if not watch.cancelled():
        watch.exception()


#: Threads for a wave's parts beyond its first (which runs in the request's own worker
#: thread); each runs only on a compute token the request holds (see :func:`_wave`).
_PARTS = ThreadPoolExecutor(thread_name_prefix="marionette-part")


async def _wave(fn: Callable[[slice], R], wave: Sequence[slice],
                limiter: ComputeLimiter | None,
                budget: Budget | None = None, total: int = 0) -> list[R]:  # fmt: skip
    """``fn`` over the parts of ``wave``, at once on as many compute tokens as are free;
    the answers in order, the first error (in part order) raised once every part ended.

    The request first waits for one token, as any compute does (no longer than its
    deadline leaves, :meth:`Budget.token`), then takes more only if
    they are free at that moment (it never waits while holding one, so requests cannot
    deadlock), and keeps them until its wave ends. The parts run from ONE awaited worker
    thread call: a request cancelled meanwhile (the shutdown grace ran out) ends as it
    does awaiting one thread, once the running parts end."""
    if limiter is None:
        return [await anyio.to_thread.run_sync(fn, part) for part in wave]
    stage = f"items {wave[0].start}-{wave[-1].stop - 1}"
    counts = {"done": wave[0].start, "total": total}  # (a 504 waiting for a token says them)
    if len(wave) == 1 and budget is not None:
        return [await budget.in_thread(lambda: fn(wave[0]), stage, **counts)]
    held: list[object] = []
    try:
        for _ in wave:
            borrower = object()
            if held:
                try:
                    limiter.acquire_on_behalf_of_nowait(borrower)
                except anyio.WouldBlock:
                    break
            elif budget is not None:
                await budget.token(limiter, borrower, stage, **counts)
            else:  # no deadline (tests of the wave alone)
                await limiter.acquire_on_behalf_of(borrower)
            held.append(borrower)
        width = len(held)
        return await anyio.to_thread.run_sync(fan_out, fn, wave, width)
    finally:
        for borrower in held:
            limiter.release_on_behalf_of(borrower)


def fan_out(fn: Callable[[slice], R], wave: Sequence[slice], width: int) -> list[R]:
    """The parts of ``wave``, ``width`` at a time: the first of each group in this
    thread, the others in :data:`_PARTS`."""
    out: list[R] = []
    for g in range(0, len(wave), width):
        group = wave[g : g + width]
        others = [_PARTS.submit(fn, part) for part in group[1:]]
        try:
            first = fn(group[0])
        finally:
            wait(others)
        out.append(first)
        out.extend(f.result() for f in others)
    return out


#: A character item of a batch (its own solve, joint map, retargeting and answer, in
#: Python) in the units above, which are ~6.3 us of a pose item's work (1,024 of the
#: costliest, 25 units each, took 156 ms, 1,024 plain 2-target ones, 6 units each, 45 ms:
#: in process on one compute thread, `python scripts/figures/character_price.py --rounds
#: 5`, 2026-12-07): CHARACTER_PRICE, plus CHARACTER_SLOW_PRICE when its solve runs FABRIK
#: (exact reach, pins, the fabrik method), plus 3 units per 5 joints. Measured so: a
#: 22-joint skeleton 1.76 ms soft, 2.57 ms exact with two pins (294 / 434 units: 1.84 /
#: 2.71 ms); 522 joints 3.10 / 4.25 ms (594 / 734); 1,022 joints 5.47 / 5.41 ms (894 /
#: 1,034). It was 400, 400 more slow and 8 per 5 joints, priced before the character path
#: was compiled (2.8 / 5.3 ms for 22 joints, 13.1 / 13.3 for 1,022): twice its work and
#: more since, so a batch of them was refused at half the size it could take. Before that
#: it was 16 units plus 1 per 8 joints, doubled (38 for the 22-joint exact item): the 413
#: admitted 600 such items, 3.2 s of work, which no deadline of 2 s could finish (a user's
#: audit).
CHARACTER_PRICE, CHARACTER_SLOW_PRICE = 280, 140
#: ... and CHARACTER_JOINT_UNITS units for every CHARACTER_PER_JOINTS of its joints
CHARACTER_JOINT_UNITS, CHARACTER_PER_JOINTS = 3, 5


def character_price(joints: int, slow: bool) -> int:
    per_joints = -(-joints * CHARACTER_JOINT_UNITS // CHARACTER_PER_JOINTS)
    return CHARACTER_PRICE + (CHARACTER_SLOW_PRICE if slow else 0) + per_joints


def edit_price(joints: int, o: Priced, pinned: bool) -> int:
    """:func:`character_price` of one character edit of ``joints`` joints asking ``o``
    (slow where its solve runs FABRIK: exact reach, pins, the fabrik method)."""
    return character_price(joints, o.method == "fabrik" or o.reach == "exact" or pinned)


def refuse_price(prices: Sequence[int], joints: int | Sequence[int], max_items: int,
                 pricing: Pricing, field: str = "items") -> None:  # fmt: skip
    """Refuse (413) a batch of more than one item (``field``: ``items``, a clip's
    ``edits``) whose ``prices`` add up past :func:`batch_price_limit` (``joints``: each
    item's character's joints, or the clip's), naming the costliest."""
    total, cap = sum(prices), batch_price_limit(max_items, pricing)
    if total <= cap or len(prices) <= 1:
        return
    i = max(range(len(prices)), key=prices.__getitem__)
    many = joints if isinstance(joints, int) else joints[i]
    noun = "an edit" if field == "edits" else "a character item"
    raise TooManyItems(
        f"{field}: the batch costs {total} work units, beyond the limit of {cap} (what "
        f"{max_items} of the costliest pose items cost, {max_item_price(pricing)} units "
        f"each); {noun} costs {CHARACTER_PRICE} + {CHARACTER_JOINT_UNITS} per "
        f"{CHARACTER_PER_JOINTS} joints, {CHARACTER_SLOW_PRICE} more for exact reach, pins or "
        f"FABRIK ({field}[{i}], {many} joints: {prices[i]}; {_fit(cap // prices[i])}); send "
        "smaller batches"
    )


def _fit(n: int) -> str:
    """How many of the costliest item fit a batch's price limit, said (one alone always)."""
    return f"{n} such fit a batch" if n > 1 else "one such is taken alone, never in a batch"


def max_item_price(pricing: Pricing) -> int:
    """The costliest pose item: neural with the FABRIK polish (pins) at the most passes a
    request may ask for or the models' default, whichever is more, and the retry, with
    its mirror image (``options.mirror``); dearer than a FABRIK item. (A pose item's turn
    search is priced in its chunks, not here: a batch of pose items is bounded by its
    item count alone.)"""
    passes = max(MAX_PASSES, pricing.passes)
    return max(FABRIK_PRICE, neural_price(True, passes, retry=pricing.retry, views=2))


def batch_price_limit(max_items: int, pricing: Pricing) -> int:
    """The most one batch of more than one item may cost: ``max_items`` of the costliest
    pose items (a batch of pose items is bounded by its item count alone; character items
    also by their joints; one item alone is never refused for its price, as a single
    request of it is not)."""
    return max_items * max_item_price(pricing)
