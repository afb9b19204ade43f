"""The HTTP protocol the service runs under uvicorn: uvicorn's own (httptools where it is
installed, else h11), with a bound on the answers a worker holds for clients that do not
take them.

uvicorn hands a whole answer to the connection at once; what the client's socket does not
take waits in the process, for as long as the client keeps the connection open. An answer
of a few megabytes (a BVH file) that is never read therefore held most of itself in memory
for good: twelve clients that sent a 7.6 MB ``/v1/bvh/solve`` and read nothing took the
server from 283 to 408 MB (a ``/tmp`` script on loopback), and some sixty would take a pod
past its memory limit. Here the answers waiting in a worker (its connections whose
write buffer went over the high-water mark, uvicorn's flow control) hold at most
``max_unsent_bytes`` (``POSE_MAX_UNSENT_BYTES``) between them: when an answer backs up
past it, the connections that have waited longest are closed and their answers dropped,
oldest first, with a ``slow-reader`` warning in the log each and
``pose_slow_readers_total``. A client that reads, however slowly, loses its answer only
while the worker holds more than that for clients that do not. (A floor on each client's
pace was tried first: the client's own socket buffer, megabytes on loopback, hides its
reading from the server for seconds at a time, so steady readers were cut off.)

A request's line and headers are bounded too (:data:`MAX_HEAD_BYTES`): uvicorn's httptools
parser keeps whatever a client sends before the blank line that ends them, so four
connections each sending an unfinished 50 MB header took a worker from 340 to 620 MB (an
audit's script on loopback); past the bound the connection gets a 431 problem+json and is
closed. The parser's own refusals (bytes that are not HTTP) are problem+json too, not
uvicorn's plain text (:func:`service.errors.raw_answer`); each of these refusals, 400 or
431, is counted and logged as the closes below are (``malformed-http``,
``head-too-large``), with its status and the request id the client got.

A connection's time and number are bounded too, as ops expect of a server facing clients
it does not know (a slowloris: an audit held a head unfinished for 60 s and more, 1,000
unfinished 60 KB heads took a worker from 355 to 419 MiB for good, and 19,980 fresh
connections that never sent a byte were all open 30 s on). A fresh connection that sends
nothing is closed after ``idle_timeout_seconds`` (uvicorn's keep-alive timeout between
requests, the same setting); a request's line and headers must be whole within
``head_timeout_seconds`` of their first byte, else a 408 problem+json (``head-timeout``) and
the close; the rest of a body the app answered without reading (a 415, a 429 ...) must come
within ``deadline_seconds`` of that answer, else the connection is closed (the body the app
reads has the gate's own bound: ``service.middleware.gate``). One sweep a worker looks for
connections past their time (:data:`SWEEP_SECONDS`), as the gate's one watch looks for
bodies, instead of a timer per connection. Past ``max_connections`` open on the worker, a
new connection is answered 503 (``too-many-connections``, ``Retry-After: 1``) and closed
before anything of it is read (uvicorn's ``limit_concurrency`` would answer its plain text
only once a head is whole, so the connection and its unfinished head stay). Each is counted
in ``pose_connections_closed_total`` by reason and logged (``connection_closed``, at most a
line a second per reason, with the count since the last: a flood of connections is not a
flood of log lines).

Each answer also leaves in one write where it is small: uvicorn writes the status line and
headers, then the body, each at once, so a small answer cost two ``send`` system calls
and two TCP segments, and its client woke up twice to read it (:class:`Coalescing`).
"""

from __future__ import annotations

import asyncio
import logging
import sys
import time
from typing import Any, ClassVar, Literal, get_args

import orjson
from prometheus_client import Counter
from uvicorn.protocols.http.auto import AutoHTTPProtocol

from service.errors import (
    T0,
    HeadTimeout,
    HeadTooLarge,
    MalformedHTTP,
    PoseError,
    TooManyConnections,
    raw_answer,
)
from service.settings import get_settings

log = logging.getLogger("service.transport")


#: A write smaller than this may wait for the next (a response's headers for its body); a
#: larger one goes at once with what waits (no copy of a big body, and uvicorn's flow
#: control sees it).
COALESCE_BYTES = 64 * 1024
#: Bytes of a request's line and headers a client may send (h11, the fallback parser,
#: bounds them itself: uvicorn's ``h11_max_incomplete_event_size``, 16 KiB by default).
MAX_HEAD_BYTES = 64 * 1024
#: How long a refused connection's further bytes are read and dropped before it closes.
LINGER_SECONDS = 1.0
#: How often a worker looks for connections past their time (idle, head, unread body).
SWEEP_SECONDS = 0.25
#: A ``connection_closed`` log line per reason at most this often (with the count since).
LOG_EVERY_SECONDS = 1.0
#: At ``max_connections``, a connection with no request under way that has waited this long
#: (for its first byte, the rest of its head, its next request) is closed to make room.
EVICT_AFTER_SECONDS = 1.0


class Coalescing:
    """A transport that holds a small write until the next one, or until the end of the
    event loop's step if none comes, and then sends both as one: a response's headers
    leave with its body, in one ``send`` and one TCP segment. The write that completes a
    pair goes at once (holding it to the end of the step would put the app's work after
    its answer, metrics and logs, before the client's read). In order with every other
    write; ``close`` sends what is held first, ``abort`` drops it (as the transport drops
    its buffer). Everything else is the transport's own."""

    def __init__(self, transport: asyncio.Transport, loop: asyncio.AbstractEventLoop) -> None:
        self._transport = transport
        self._loop = loop
        self._held: bytes | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self._transport, name)

    def write(self, data: bytes | bytearray | memoryview) -> None:
        held, self._held = self._held, None
        if held is not None:  # the pair is complete
            if len(data) < COALESCE_BYTES:
                data = held + data
            else:
                self._transport.write(held)
            self._transport.write(data)
        elif len(data) < COALESCE_BYTES:
            self._held = bytes(data)
            self._loop.call_soon(self._flush)
        else:
            self._transport.write(data)

    def writelines(self, parts: Any) -> None:
        self.write(b"".join(parts))

    def write_eof(self) -> None:
        self._flush()
        self._transport.write_eof()

    def _flush(self) -> None:
        held, self._held = self._held, None
        if held is not None and not self._transport.is_closing():
            self._transport.write(held)

    def get_write_buffer_size(self) -> int:
        return int(self._transport.get_write_buffer_size()) + len(self._held or b"")

    def close(self) -> None:
        self._flush()
        self._transport.close()

    def abort(self) -> None:
        self._held = None
        self._transport.abort()


#: Connections closed on a client that did not take its answer (``pose_slow_readers_total``;
#: the protocol has no app to count in, so the count is the process's, which every app's
#: registry shows: ``service.metrics``).
SLOW_READERS = Counter(
    "pose_slow_readers",
    "Connections closed on a client that did not take its answer",
    registry=None,
)


#: Connections closed for their pace, refused for their number, or closed on a refusal of
#: the HTTP parser's (bytes that are not HTTP, a head too large), by reason
#: (``pose_connections_closed_total``; the process's, as :data:`SLOW_READERS`).
CONNECTIONS_CLOSED = Counter(
    "pose_connections_closed",
    "Connections closed for their pace, refused for their number, or closed on a request "
    "the HTTP parser refused (malformed-http, head-too-large), by reason",
    ["reason"],
    registry=None,
)

#: Every reason a connection is closed for (:func:`closed`).
CloseReason = Literal[
    "head-timeout", "idle-timeout", "body-timeout", "too-many-connections", "evicted",
    "malformed-http", "head-too-large",
]  # fmt: skip
CLOSE_REASONS: tuple[str, ...] = get_args(CloseReason)
for _reason in CLOSE_REASONS:  # each series at 0 from the start, a worker's too (it imports
    # this afresh, into its own multiprocess file): each appeared at its reason's first
    # close, and a dashboard or an alert by name found nothing until then (a new-user audit)
    CONNECTIONS_CLOSED.labels(_reason)
_logged: dict[str, tuple[float, int]] = {}  # reason -> (its last line's time, events since)


def closed(reason: CloseReason, level: int, **fields: Any) -> None:
    """Count a connection closed for ``reason`` and log it: a line per reason and
    :data:`LOG_EVERY_SECONDS` at most, ``events`` saying how many since the last."""
    CONNECTIONS_CLOSED.labels(reason).inc()
    now = time.monotonic()
    last, events = _logged.get(reason, (-LOG_EVERY_SECONDS, 0))
    if now - last < LOG_EVERY_SECONDS:
        _logged[reason] = (last, events + 1)
        return
    _logged[reason] = (now, 0)
    line = {"event": "connection_closed", "reason": reason, **fields, "events": events + 1}
    log.log(level, orjson.dumps(line).decode())


def _head_too_large() -> HeadTooLarge:
    return HeadTooLarge(
        f"the request line and headers exceed {MAX_HEAD_BYTES} bytes "
        "(the server reads no more of them)"
    )


class PacedHTTPProtocol(AutoHTTPProtocol):  # type: ignore[misc, valid-type]
    """uvicorn's HTTP protocol with a bound on the answers waiting for their clients, on
    a connection's time and on the connections open, its small writes coalesced
    (:class:`Coalescing`)."""

    #: this worker's connections whose answer waits, in the order they began to wait (a
    #: dict: insertion order, and removal by key)
    waiting: ClassVar[dict[PacedHTTPProtocol, None]] = {}
    #: this worker's connections with no request under way, that must send something by a
    #: time: -> (by when, what, since when), in the order they began to wait
    due: ClassVar[dict[PacedHTTPProtocol, tuple[float, str, float]]] = {}
    #: the sweep looking for them, and its loop (while any is due)
    sweep: ClassVar[tuple[asyncio.TimerHandle, asyncio.AbstractEventLoop] | None] = None
    #: this worker's connections open (counted against ``max_connections``)
    open: ClassVar[int] = 0

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        s = get_settings()
        self._budget = s.max_unsent_bytes
        self._max_connections = s.max_connections
        self._idle, self._head_time = s.idle_timeout_seconds, s.head_timeout_seconds
        self._body_time = s.deadline_seconds
        self.timeout_keep_alive = s.idle_timeout_seconds  # (uvicorn's, between requests)
        self._counted = False  # counted in ``open``
        self._waits: str | None = None  # what it must send by a time (``due``), if any
        self._in_body = False  # the parser is inside a request's body
        self._head = -1  # bytes of a request's head read so far (-1: not inside one)
        self._refused = False  # answered below the app: what comes is dropped
        self._refusal: bytes | None = None  # that answer, while one before it is still due
        self._began = False  # a head began in the read being parsed
        self._too_long = False  # a whole head over the bound: the parse stopped on it
        self._t0 = time.perf_counter()  # when the last head began (a refusal's total time)
        self._fields = 0  # bytes of the head's header lines so far, as sent
        self._why = ""  # the parser's words for a refusal of its (for the log)

    def data_received(self, data: bytes) -> None:
        if self._refused:  # read and dropped until the close (see refuse)
            return
        if self._waits == "idle":
            self._disarm()
        self._began = False
        super().data_received(data)
        # a read that ended inside a head begun before it was all head; one whose head began
        # in it may have held a request before that head (pipelined), so it is not counted
        # here: an unfinished head is bounded at MAX_HEAD_BYTES and one read, a whole one at
        # MAX_HEAD_BYTES (on_headers_complete)
        if self._head >= 0 and not self._began and not self._refused:
            self._head += len(data)
            if self._head > MAX_HEAD_BYTES:
                self.refuse(_head_too_large())
        if self._head >= 0 and self._waits is None and not self._refused:  # not whole yet
            self._arm(self._t0 + self._head_time, "head")

    def on_message_begin(self) -> None:  # httptools: a request's head begins
        super().on_message_begin()
        self._head, self._began, self._t0 = 0, True, time.perf_counter()
        self._fields = 0

    def on_header(self, name: bytes, value: bytes) -> None:
        # counted as sent: uvicorn keeps the value without its trailing blanks (a head
        # padded with 100 kB of spaces went through as small)
        self._fields += len(name) + len(value) + 4
        super().on_header(name, value)

    def on_headers_complete(self) -> None:
        # a whole head that came in one read (never counted above): its size from what the
        # parser gave (line and header lines as sent, their separators); past the bound the parse is
        # stopped here (httptools turns the raise into its error, uvicorn's data_received
        # calls send_400_response) before any request exists
        size = 16 + len(getattr(self, "url", b"")) + self._fields
        self._head = -1
        if self._waits == "head":
            self._disarm()
        if size > MAX_HEAD_BYTES:
            self._too_long = True
            raise ValueError("request head too long")
        super().on_headers_complete()
        if not self.pipeline or self.pipeline[0][0] is not self.cycle:  # started, not queued
            # its arrival, for its deadline and times: the task starts only once the loop
            # is through what it was doing (lone soft edits solved on it, one after
            # another), which stamping it there (the middleware's) left uncounted
            self.scope[T0] = time.perf_counter()
        self._in_body = True  # (until on_message_complete, at once for a bodiless request)

    def on_message_complete(self) -> None:
        self._in_body = False
        if self._waits == "body":
            self._disarm()
        super().on_message_complete()

    def send_400_response(self, msg: str) -> None:
        """The parser's refusal (uvicorn's plain text) as a problem; the parser's own words
        (uvicorn calls this inside its ``except``) go to the log line (:meth:`refuse`)."""
        if self._too_long:
            self.refuse(_head_too_large())
            return
        self._why = str(sys.exc_info()[1] or "")[:200]
        self.refuse(MalformedHTTP(f"{msg.rstrip('.')}: the bytes sent are not an HTTP/1.1 request"))

    def refuse(self, exc: PoseError) -> None:
        """Answer ``exc`` before any app runs and close the connection, after the answers
        still due on it (pipelined requests before this one): our side at once, theirs
        after ``LINGER_SECONDS`` of reading and dropping what they still send (a close with
        their bytes unread would reset the connection, and the client could lose the
        answer before reading it)."""
        self._head = -1
        if self._refused or self.transport.is_closing():
            return
        self._refused = True
        self._disarm()
        cycle = getattr(self, "cycle", None)
        if (
            cycle is not None and cycle.more_body and not cycle.response_started
            and not any(c is cycle for c, _ in getattr(self, "pipeline", ()))
        ):  # fmt: skip
            # the bad bytes are the running request's body (a chunk size that is no
            # number): that request is the one refused, not an answer due before the
            # refusal; its app reads a disconnect (it waited for the rest of the body, and
            # the client got a 408 at the deadline instead of this 400: an API audit)
            cycle.disconnected = True
            cycle.message_event.set()
        from service.middleware.headers import protocol_headers  # (its package imports this)

        headers = protocol_headers(self._t0)
        if isinstance(exc, MalformedHTTP | HeadTooLarge):  # (others: logged where decided)
            # counted and logged as the other closes (a line a second at most): uvicorn's
            # own "Invalid HTTP request received." (service.logs drops it) said neither the
            # status, nor the client, nor the id the client got, and a client looping
            # garbage for 3 s wrote 7,482 of them (an ops audit)
            malformed = isinstance(exc, MalformedHTTP)
            reason: CloseReason = "malformed-http" if malformed else "head-too-large"
            closed(reason, logging.WARNING, status=exc.status, client=self._client(),
                   request_id=dict(headers)[b"x-request-id"].decode(),
                   why=self._why or exc.detail[:200])  # fmt: skip
        self._refusal = raw_answer(exc, headers)
        if not self._answers_due():
            self._send_refusal()

    def _answers_due(self) -> bool:
        cycle = getattr(self, "cycle", None)
        return bool(getattr(self, "pipeline", None)) or (
            cycle is not None and not cycle.response_complete and not cycle.disconnected
        )

    def on_response_complete(self) -> None:
        super().on_response_complete()  # (starts the next pipelined request, if any)
        if self._refusal is not None and not self._answers_due():
            self._send_refusal()
        elif (
            self._waits is None
            and self.cycle.response_complete
            and not (self._refused or self.pipeline or self.transport.is_closing())
        ):
            now = time.perf_counter()
            if self._in_body:
                # answered before its body was read (415, 429 ...): uvicorn reads on and
                # drops the rest, for as long as it trickles in (every byte put off its
                # keep-alive timeout)
                self._arm(now + self._body_time, "body")
            elif self._head < 0:  # kept alive, idle (uvicorn's timer closes it too)
                self._arm(now + self._idle, "idle")

    def _send_refusal(self) -> None:
        answer, self._refusal = self._refusal, None
        if answer is None or self.transport.is_closing():
            return
        self.transport.write(answer)
        if self.transport.can_write_eof():
            self.transport.write_eof()
            asyncio.get_running_loop().call_later(LINGER_SECONDS, self.transport.close)
        else:
            self.transport.close()

    def connection_made(self, transport: asyncio.Transport) -> None:
        super().connection_made(Coalescing(transport, self.loop))
        cls = PacedHTTPProtocol
        if cls.open >= self._max_connections and not self._make_room():
            # refused before anything of it is read
            closed("too-many-connections", logging.WARNING, client=self._client(),
                   open=cls.open, max_connections=self._max_connections)  # fmt: skip
            self.refuse(TooManyConnections(
                f"{cls.open} connections open on this worker (limit {self._max_connections})"
                "; retry later"
            ))  # fmt: skip
            return
        cls.open += 1
        self._counted = True
        self._arm(time.perf_counter() + self._idle, "idle")

    def _make_room(self) -> bool:
        """Close the connection that has waited longest with no request under way, if it
        has waited :data:`EVICT_AFTER_SECONDS` (idle, or its head unfinished: a client in no
        hurry), to let this one in (as nginx drains idle connections when it runs out);
        False if there is none such (every connection has a request under way, or began to
        wait just now: this one is refused)."""
        cls = PacedHTTPProtocol
        now = time.perf_counter()
        victim = None
        for conn, (_, _, since) in cls.due.items():  # the longest waiting first
            if now - since < EVICT_AFTER_SECONDS:
                break
            if not conn._answers_due():  # (a head begun behind a request still answered)
                victim = conn
                break
        if victim is None:
            return False
        conn, (_, waits, since) = victim, cls.due[victim]
        closed("evicted", logging.INFO, client=conn._client(), waited_for=waits,
               seconds=round(now - since, 3))  # fmt: skip
        conn._disarm()
        conn._counted = False  # (on its way out)
        cls.open -= 1
        conn.transport.close()  # no answer: it has no request under way
        return True

    def _client(self) -> str | None:
        client = getattr(self, "client", None)
        return f"{client[0]}:{client[1]}" if client else None

    def _arm(self, when: float, waits: str) -> None:
        """The connection must have sent what it ``waits`` for by ``when`` (perf_counter)."""
        cls = PacedHTTPProtocol
        cls.due.pop(self, None)  # (to the end: the order is when each began to wait)
        cls.due[self] = (when, waits, time.perf_counter())
        self._waits = waits
        if cls.sweep is None or cls.sweep[1] is not self.loop:
            cls.sweep = (self.loop.call_later(SWEEP_SECONDS, cls.sweep_due), self.loop)

    def _disarm(self) -> None:
        PacedHTTPProtocol.due.pop(self, None)
        self._waits = None

    @classmethod
    def sweep_due(cls) -> None:
        """Close the connections past their time; look again while any is due."""
        loop = cls.sweep[1] if cls.sweep is not None else asyncio.get_running_loop()
        cls.sweep = None
        now = time.perf_counter()
        for conn, (when, waits, _) in list(cls.due.items()):
            if now >= when:
                conn._disarm()
                conn.timed_out(waits)
        if cls.due:
            cls.sweep = (loop.call_later(SWEEP_SECONDS, cls.sweep_due), loop)

    def timed_out(self, waits: str) -> None:
        """The connection did not send what it ``waits`` for in time: a head (answered 408
        after the answers due before it, then closed), its first byte or next request, or
        the rest of a body answered already (closed: nothing to answer)."""
        if self.transport.is_closing():
            return
        if waits == "head":
            closed("head-timeout", logging.WARNING, client=self._client(),
                   head_timeout_seconds=self._head_time)  # fmt: skip
            self.refuse(HeadTimeout(
                f"the request line and headers did not arrive within {self._head_time:g} s "
                "of their first byte: send a request's head without pauses"
            ))  # fmt: skip
            return
        if waits == "idle":
            if getattr(self, "cycle", None) is None:  # (after a request: a keep-alive's end)
                closed("idle-timeout", logging.INFO, client=self._client(),
                       idle_timeout_seconds=self._idle)  # fmt: skip
        else:
            closed("body-timeout", logging.WARNING, client=self._client(),
                   seconds=self._body_time)  # fmt: skip
        self.transport.close()

    def pause_writing(self) -> None:
        super().pause_writing()
        cls = PacedHTTPProtocol
        cls.waiting.setdefault(self, None)
        held = {p: p.transport.get_write_buffer_size() for p in cls.waiting}
        total = sum(held.values())
        for oldest in list(cls.waiting):
            if total <= self._budget:
                break
            total -= held[oldest]
            oldest.drop(held[oldest], total)

    def drop(self, unsent: int, left: int) -> None:
        """Close this connection and drop the ``unsent`` bytes of its answer (``left``:
        what the others still hold)."""
        PacedHTTPProtocol.waiting.pop(self, None)
        SLOW_READERS.inc()
        client = getattr(self, "client", None)
        line = {
            "event": "slow-reader", "client": f"{client[0]}:{client[1]}" if client else None,
            "unsent": unsent, "others_unsent": left, "max_unsent_bytes": self._budget,
        }  # fmt: skip
        log.warning(orjson.dumps(line).decode())
        self.transport.abort()  # connection_lost follows; the app's sends become no-ops

    def resume_writing(self) -> None:
        super().resume_writing()  # under the low-water mark: it takes its answer
        PacedHTTPProtocol.waiting.pop(self, None)

    def connection_lost(self, exc: Exception | None) -> None:
        PacedHTTPProtocol.waiting.pop(self, None)
        self._disarm()
        if self._counted:
            self._counted = False
            PacedHTTPProtocol.open -= 1
        super().connection_lost(exc)
