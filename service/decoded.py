"""What a JSON body costs once decoded, and the worker's budget for it.

Decoded into Python objects, JSON text takes 2 to 45 times its bytes, by its shape
(tracemalloc, ``json.loads`` with the routes' strict hook, then the route's validation;
8.3 MB bodies): one long string 2.0x, a big BVH file 2.1x, 1,024 valid items 11.4x
(validated), a list of numbers 6.5-9.1x, distinct unknown keys 20.4x, empty lists 22.6x,
empty objects 26.9x, lists nested 200 deep 44.8x. Counted by bytes alone, six 8 MiB bodies
of empty objects (each a 413 or a 422) took a worker from 330 to 840 MiB, eight of lists
nested 200 deep to 1,103 MiB, over a 768 MiB pod limit.

:func:`estimate` prices a body from a count of its bytes (numpy, ~1.5 ms a MiB: no
decoding) at the most each kind of token was measured to cost; :class:`DecodeBudget` holds
a worker's decoded bodies under ``POSE_DECODE_MEMORY_BYTES`` (``service.middleware.gate``:
a body of ``ESTIMATED_FROM`` bytes or more reserves its estimate once read, until its
request ends; one that alone would exceed the budget is a 413, others wait for it in
arrival order no longer than their deadline leaves).
"""

from __future__ import annotations

import asyncio
import collections
import gc
import time
from typing import Any

import numpy as np

#: Bodies this long or longer are priced (``service.body.INLINE_BYTES``: smaller ones are
#: decoded on the event loop, one at a time, and cost at most ~3 MB decoded).
ESTIMATED_FROM = 64 * 1024

#: Bytes of Python objects per token, the most measured (CPython 3.11, 64-bit): a ``[``
#: a list (56 B, 32 B of slots when it holds anything); a ``{`` a dict (64 B; its pairs,
#: counted by ``:``, add their table); a ``,`` a value and its slot (a float 24 B, rounded
#: up, 8 B a slot); a ``:`` a member: its key's string when distinct (~56 B), the pair
#: the strict decoder's hook is handed (64 B), the dict's entry and the key's memo; a
#: ``"`` half of a string's header. Per byte of the body: the text decoded (once as a
#: whole, once as its strings' values) at the widest character it may hold (below).
COSTS = {ord("["): 88, ord("{"): 72, ord(","): 32, ord(":"): 168, ord('"'): 12}


def _width(a: np.ndarray[tuple[int], np.dtype[np.uint8]]) -> int:
    """Bytes per character of a ``str`` holding this UTF-8 text: 1 (ASCII, Latin-1), 2
    (a lead byte of U+0100..U+FFFF), 4 (one of a character beyond)."""
    top = int(a.max(initial=0))
    return 4 if top >= 0xF0 else 2 if top >= 0xC4 else 1


#: Routes that read a big body with orjson first (``service.middleware.fastpath``: the
#: columnar form), whose reader builds a document before its objects: ~13 bytes a byte of
#: the body (one long string: 13.1x; a list of numbers 20x in all, against 9x decoded by
#: ``json.loads``), and for a body it hands on, decodes it again after.
ORJSON_PATHS = frozenset({"/v1/solve/batch"})
ORJSON_BYTES = 13


#: Scope key: a priced body's count of each byte of :data:`COSTS` (the gate's, for the
#: columnar reader, ``service.middleware.fastpath``, not to count its commas again).
COUNTED = "pose.counted"


def estimate(body: bytes, orjson: bool = False, counted: dict[int, int] | None = None) -> int:
    """An upper bound of the bytes ``body`` takes decoded and validated (measured within
    +0 to +90 % for every shape above; see the module doc); ``orjson``: read by orjson
    first (:data:`ORJSON_PATHS`). ``counted``, when given, is filled with the count of
    each byte of :data:`COSTS`."""
    a = np.frombuffer(body, dtype=np.uint8)
    text = _width(a)
    # a string is its text's copy, but one with escapes is written out character by
    # character: begun narrow, copied wide at a surrogate pair's, grown by a quarter, and
    # copied once more to its length (9 bytes a byte, measured)
    escaped = np.count_nonzero(a == ord("\\")) and b"\\u" in body  # (a search: 1 GB/s)
    values = 9 if escaped else text
    widened = 1 if text > 1 else 0  # the text, decoded narrow until a wide character comes
    total = len(body) * (text + values + widened + (ORJSON_BYTES if orjson else 0))
    total += len(body) // 4
    counts = counted if counted is not None else {}
    for byte, cost in COSTS.items():
        counts[byte] = int(np.count_nonzero(a == byte))
        total += cost * counts[byte]
    return total


#: Seconds full collections are deferred at most while big bodies follow each other
#: without a pause; then one may run (and they are deferred again once it has).
MAX_DEFERRED = 30.0
_NEVER = 1 << 30  # a third threshold no count of collections reaches


class FullCollections:
    """The garbage collector's full collections, deferred while a worker holds big bodies
    decoded (:class:`DecodeBudget`). Once the models are loaded, the process's objects are
    frozen (``service.app``), so a full collection walks what requests allocated: a body of
    64 KiB or more decoded holds up to millions of containers, and the collections its
    decoding set off took the GIL for 45-100 ms each (a 6.5 MiB item list, a real
    uvicorn: the event loop waited as long). Decoded JSON holds no reference cycles; the
    young generations are still collected as ever (each walks a few thousand objects); a
    full collection runs when no big body is held (walking little: they are freed), or
    once every ``MAX_DEFERRED`` seconds of them. Process-wide; event-loop threads only."""

    def __init__(self) -> None:
        self.holders = 0
        self.saved: tuple[int, int, int] | None = None  # the thresholds while deferred
        self.since = 0.0  # when deferred (time.monotonic)
        gc.callbacks.append(self._collected)

    def hold(self) -> None:
        self.holders += 1
        if self.holders == 1:
            self._defer()
        elif self.saved is not None and time.monotonic() - self.since > MAX_DEFERRED:
            self._allow()  # one may run now (deferred again once it has: _collected)

    def release(self) -> None:
        self.holders -= 1
        if self.holders == 0:
            self._allow()

    def _defer(self) -> None:
        if self.saved is None:
            self.saved = gc.get_threshold()
            gc.set_threshold(self.saved[0], self.saved[1], _NEVER)
        self.since = time.monotonic()

    def _allow(self) -> None:
        if self.saved is not None:
            gc.set_threshold(*self.saved)
            self.saved = None

    def _collected(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "stop" and info["generation"] == 2 and self.holders > 0:
            self._defer()


FULL_COLLECTIONS = FullCollections()


class DecodeBudget:
    """Bytes of decoded bodies a worker holds at once; reservations are granted in
    arrival order (one that does not fit holds back those after it, so a big body is not
    starved by small ones). Event-loop only."""

    def __init__(self, total: int) -> None:
        self.total = total
        self.held = 0
        self._waiting: collections.deque[tuple[int, asyncio.Future[bool]]] = collections.deque()

    def _grant(self) -> None:
        while self._waiting:
            size, ready = self._waiting[0]
            if ready.done():  # (given up: its deadline, or its request cancelled)
                self._waiting.popleft()
                continue
            if self.held + size > self.total:
                return
            self._waiting.popleft()
            self._add(size)
            ready.set_result(True)

    def _expire(self, ready: asyncio.Future[bool]) -> None:
        if not ready.done():
            ready.set_result(False)
            self._grant()  # those behind it may fit now

    async def reserve(self, size: int, until: float) -> bool:
        """Reserve ``size`` bytes (at most ``total``), waiting no later than ``until``
        (``time.perf_counter``); False if they did not come by then. (The future is
        awaited as it is: a request cancelled while it waits - the shutdown grace ran
        out - ends at once and is answered; through ``asyncio.wait_for`` it took loop
        turns the shutdown did not wait for, and its client got no answer.)"""
        if not self._waiting and self.held + size <= self.total:
            self._add(size)
            return True
        loop = asyncio.get_running_loop()
        ready: asyncio.Future[bool] = loop.create_future()
        self._waiting.append((size, ready))
        timer = loop.call_later(max(0.0, until - time.perf_counter()), self._expire, ready)
        try:
            return await ready
        except asyncio.CancelledError:
            if ready.done() and not ready.cancelled() and ready.result():
                self.release(size)  # granted as it was cancelled
            else:
                self._grant()
            raise
        finally:
            timer.cancel()

    def _add(self, size: int) -> None:
        if self.held == 0 and size > 0:
            FULL_COLLECTIONS.hold()
        self.held += size

    def release(self, size: int) -> None:
        self.held -= size
        if self.held == 0 and size > 0:
            FULL_COLLECTIONS.release()
        self._grant()
