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
uvicorn's plain text (:func:`service.errors.raw_answer`).

Each answer also leaves in one write where it is small: uvicorn writes the status line and
headers, then the body, each at once, so a small answer cost two ``send`` system calls
and two TCP segments, and its client woke up twice to read it (:class:`Coalescing`).
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import Any, ClassVar

import orjson
from prometheus_client import Counter
from uvicorn.protocols.http.auto import AutoHTTPProtocol

from service.errors import T0, HeadTooLarge, MalformedHTTP, PoseError, raw_answer
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


class Coalescing:
    """A transport that holds a small write until the next one, or until the end of the
    event loop's step if none comes, and then sends both as one: a response's headers
    leave with its body, in one ``send`` and one TCP segment. The write that completes a
    pair goes at once (holding it to the end of the step would put the app's work after
    its answer, metrics and logs, before the client's read). In order with every other
    write; ``close`` sends what is held first, ``abort`` drops it (as the transport drops
    its buffer). Everything else is the transport's own."""

    def __init__(self, transport: asyncio.Transport) -> None:
        self._transport = transport
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
            asyncio.get_running_loop().call_soon(self._flush)
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


def _head_too_large() -> HeadTooLarge:
    return HeadTooLarge(
        f"the request line and headers exceed {MAX_HEAD_BYTES} bytes "
        "(the server reads no more of them)"
    )


class PacedHTTPProtocol(AutoHTTPProtocol):  # type: ignore[misc, valid-type]
    """uvicorn's HTTP protocol with a bound on the answers waiting for their clients, its
    small writes coalesced (:class:`Coalescing`)."""

    #: this worker's connections whose answer waits, in the order they began to wait (a
    #: dict: insertion order, and removal by key)
    waiting: ClassVar[dict[PacedHTTPProtocol, None]] = {}

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._budget = get_settings().max_unsent_bytes
        self._head = -1  # bytes of a request's head read so far (-1: not inside one)
        self._refused = False  # answered below the app: what comes is dropped
        self._refusal: bytes | None = None  # that answer, while one before it is still due
        self._began = False  # a head began in the read being parsed
        self._too_long = False  # a whole head over the bound: the parse stopped on it
        self._t0 = time.perf_counter()  # when the last head began (a refusal's total time)
        self._fields = 0  # bytes of the head's header lines so far, as sent

    def data_received(self, data: bytes) -> None:
        if self._refused:  # read and dropped until the close (see refuse)
            return
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
        if size > MAX_HEAD_BYTES:
            self._too_long = True
            raise ValueError("request head too long")
        super().on_headers_complete()
        if not self.pipeline or self.pipeline[0][0] is not self.cycle:  # started, not queued
            # its arrival, for its deadline and times: the task starts only once the loop
            # is through what it was doing (lone soft edits solved on it, 64 clients of 30
            # ms ones: seconds), which stamping it there (the middleware's) left uncounted
            self.scope[T0] = time.perf_counter()

    def send_400_response(self, msg: str) -> None:
        """The parser's refusal (uvicorn's plain text) as a problem."""
        if self._too_long:
            self.refuse(_head_too_large())
            return
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

        self._refusal = raw_answer(exc, protocol_headers(self._t0))
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
        super().connection_made(Coalescing(transport))

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
        super().connection_lost(exc)
