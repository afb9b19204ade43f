"""The gate: what a request must satisfy before the app reads it.

- ``/v1/*``: the API key when one is set (``X-API-Key`` or ``Authorization: Bearer``,
  scheme in any case, compared in constant time);
- a body must be ``application/json``, uncompressed (a ``Content-Encoding`` other than
  ``identity`` is a 415, not a body read as if it were plain), unless no route takes the
  request (its path, with its method): the app's 404 or 405 says so first (a mistyped
  ``/v1/bvh/slove`` sent with curl's default form content type was a 415, the client told
  to fix a header before learning the path was wrong; an audit, 2026-12-06); and within
  ``max_body_bytes`` (declared length checked up front, a chunked body counted while it is
  read);
- admission, per worker: at most ``max_concurrency`` ``/v1`` POSTs in flight and at most
  ``max_inflight_bytes`` of bodies held at once, any route's (a chunked body reserves the
  whole body limit); past either, 429 with ``Retry-After`` before the body is read;
- the body is read here, whole, within the request's deadline (``deadline_seconds`` from
  its arrival): a body that has not arrived by then is a 408 and the connection is closed.
  Before, a stalled upload held its admission slot for as long as the client kept the
  connection open: 64 of them, sent by one client with no bandwidth to speak of, turned
  every other request away with 429s.
"""

from __future__ import annotations

import asyncio
import hmac
import time
from collections.abc import Sequence

from starlette.routing import BaseRoute, Match

from core.text import clip
from service.decoded import COUNTED, ESTIMATED_FROM, ORJSON_PATHS, DecodeBudget, estimate
from service.errors import (
    ClientDisconnected,
    DeadlineExceeded,
    MalformedBody,
    PayloadTooLarge,
    PoseError,
    RequestTimeout,
    TooManyRequests,
    Unauthorized,
    UnsupportedMediaType,
    error_response,
    refused,
)
from service.middleware.types import (
    REASON,
    T0,
    ASGIApp,
    Message,
    Receive,
    Scope,
    Send,
    header_map,
)
from service.settings import Settings

WATCH_SECONDS = 0.1  # how often the gate looks for body reads past their deadline

#: Routes that take a BVH file's text, which a client may send as an excerpt.
BVH_PATHS = frozenset({"/v1/bvh/solve", "/v1/bvh/inspect"})
#: The route that edits many frames of a BVH file (its excerpt holds the frames edited).
CLIP_PATH = "/v1/bvh/solve/batch"


def too_large(path: str, limit: int, size: int | None = None) -> PayloadTooLarge:
    """The 413 of a body over ``max_body_bytes``, saying what the client can do: it gave
    the sizes alone (a new-user audit). Only the frame asked for is read from a BVH file's
    frames (docs/bvh.md), so its header and that frame's line answer as the whole
    file does: the editor sends a big file so (docs/editor.md)."""
    of = f" of {size} bytes" if size is not None else ""
    said = f"body{of} exceeds the {limit}-byte limit (the server's POSE_MAX_BODY_BYTES)"
    if path in BVH_PATHS:
        back = " (the answer's frame line goes back in its place)" if "solve" in path else ""
        return PayloadTooLarge(
            f"{said}. Send a big file as an excerpt: its text through the 'Frame Time:' line "
            f"with 'Frames: 1', then the line of the frame wanted alone, as frame 0{back}"
        )
    if path == CLIP_PATH:
        return PayloadTooLarge(
            f"{said}. Send a big file as an excerpt: its text through the 'Frame Time:' line "
            "with 'Frames:' the count of frames edited, then their lines alone, each edit's "
            "frame numbered by its line from 0 (the answer's lines go back in their places); "
            "or the edits in several requests"
        )
    batch = " (a batch's items in several requests)" if path == "/v1/solve/batch" else ""
    return PayloadTooLarge(f"{said}: send a smaller body{batch}")


def _api_key(headers: dict[str, str]) -> str:
    key = headers.get("x-api-key", "")
    scheme, _, credentials = headers.get("authorization", "").strip().partition(" ")
    if not key and scheme.lower() == "bearer":
        key = credentials.strip()
    return key


class Gate:
    def __init__(
        self, app: ASGIApp, settings: Settings, app_routes: Sequence[BaseRoute] | None = None
    ) -> None:
        self.app = app
        self.settings = settings
        #: the app's routes, for a body's 415 to wait for a route's 404 or 405 (None: every
        #: request is taken to have a route)
        self.routes = app_routes
        self.active = 0  # admitted /v1 POSTs in flight
        self.held = 0  # body bytes reserved by them
        #: tasks reading a body -> when their deadline passes (perf_counter seconds)
        self._reading: dict[asyncio.Task[object], float] = {}
        self._late: set[asyncio.Task[object]] = set()  # cancelled for being late
        self._watch: asyncio.Task[None] | None = None
        self.decoded = DecodeBudget(settings.decode_memory_bytes)

    async def _watch_reads(self) -> None:
        """Cancel every body read past its deadline, every ``WATCH_SECONDS``, while any
        runs. One watch for all reads: a timeout per request (asyncio's, or anyio's cancel
        scope) added 9-14 µs to every request's time in the gate, the watch and the whole
        body's buffering ~4 µs (a /tmp loop over the gate alone, three rounds)."""
        try:
            while self._reading:
                await asyncio.sleep(WATCH_SECONDS)
                now = time.perf_counter()
                for task, until in list(self._reading.items()):
                    if now > until and task not in self._late:
                        self._late.add(task)
                        task.cancel()
        finally:
            self._watch = None

    def _check(self, scope: Scope, headers: dict[str, str]) -> int:
        """Raise the first rule the request breaks; return the body bytes to reserve."""
        s = self.settings
        path: str = scope["path"]
        method: str = scope["method"]
        secret = s.api_key.get_secret_value() if s.api_key else ""
        guarded = path.startswith("/v1/") and secret and method != "OPTIONS"
        if guarded and not hmac.compare_digest(_api_key(headers).encode(), secret.encode()):
            raise Unauthorized(
                "send the API key in the X-API-Key header (or Authorization: Bearer <key>)"
            )
        length = headers.get("content-length")
        chunked = length is None and "transfer-encoding" in headers
        if length in (None, "0") and not chunked:
            return 0
        if method in ("POST", "PUT", "PATCH"):
            try:
                self._check_type(headers)
            except UnsupportedMediaType:
                if self._routed(scope):
                    raise  # (else the app answers its 404 or 405, the body unread)
        if length is not None and not length.isdigit():
            raise MalformedBody(f"Content-Length is not a number: {length[:40]!r}")
        size = s.max_body_bytes if chunked else int(length or 0)
        if size > s.max_body_bytes:
            raise too_large(path, s.max_body_bytes, size)
        if path.startswith("/v1/") and self.active >= s.max_concurrency:
            raise TooManyRequests(
                f"{self.active} requests in flight on this worker (limit {s.max_concurrency})",
                limit="POSE_MAX_CONCURRENCY",
            )
        # every body read here is held until its request ends, whatever its route: one sent
        # to a route that takes none (a GET's, a POST to /v2/health/live) was read whole
        # outside this bound (30 such bodies of 8 MiB at once: 687 -> 899 MiB, a /tmp script)
        # (settings refuse a budget below the body limit, so an idle worker admits any body
        # the limit does and a 429 here is worth its retry: some are held; "0 body bytes in
        # flight (limit 4096)", answered to every retry, was an ops audit's)
        if self.held + size > s.max_inflight_bytes:
            counted = " (a chunked body counts as the whole body limit)" if chunked else ""
            raise TooManyRequests(
                f"{self.held} body bytes in flight on this worker; this request's "
                f"{size}{counted} would pass the limit ({s.max_inflight_bytes})",
                limit="POSE_MAX_INFLIGHT_BYTES",
            )
        return size

    def _routed(self, scope: Scope) -> bool:
        """Whether a route of the app takes the request, its path with its method (only
        asked of a body refused for its type: a route's matching costs microseconds)."""
        if self.routes is None:
            return True
        return any(route.matches(scope)[0] is Match.FULL for route in self.routes)

    @staticmethod
    def _check_type(headers: dict[str, str]) -> None:
        """Raise a 415 for a body that is not uncompressed JSON."""
        if (
            headers.get("content-type") == "application/json"
            and "content-encoding" not in headers
            and "transfer-encoding" not in headers
        ):
            return  # (the usual body: nothing more to look at)
        ctype, *params = headers.get("content-type", "").lower().split(";")
        ctype = ctype.strip()
        if ctype != "application/json":
            raise UnsupportedMediaType(
                f"content type must be application/json, got {ctype[:60] or 'none'!r}"
            )
        charset = next((p.split("=", 1)[1].strip(' "') for p in params if "charset=" in p), None)
        if charset not in (None, "utf-8", "utf8"):  # JSON is UTF-8 (RFC 8259 section 8.1)
            raise UnsupportedMediaType(
                f"charset {clip(charset, 40)!r} is not accepted: JSON is sent as UTF-8 "
                "(charset=utf-8, or none)"
            )
        coding = headers.get("content-encoding", "identity").strip().lower()
        if any(t.strip() not in ("", "identity") for t in coding.split(",")):  # (a list too)
            raise UnsupportedMediaType(
                f"content encoding {clip(coding, 40)!r} is not accepted: send the body "
                "uncompressed (no Content-Encoding, or identity)"
            )
        codings = [t.strip() for t in headers.get("transfer-encoding", "").lower().split(",")]
        if any(t not in ("", "chunked", "identity") for t in codings):
            raise UnsupportedMediaType(
                f"transfer coding {clip(headers['transfer-encoding'], 40)!r} is not accepted: "
                "send the body uncompressed (chunked, or with a Content-Length)"
            )

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = header_map(scope)
        try:
            reserved = self._check(scope, headers)
        except PoseError as exc:
            refused(scope, exc)
            answer = error_response(exc)
            if isinstance(exc, PayloadTooLarge):  # its body is not worth taking: no keep-alive
                answer.headers["connection"] = "close"
            await answer(scope, receive, send)
            return
        admitted = scope["path"].startswith("/v1/") and reserved > 0
        if admitted:
            self.active += 1
        self.held += reserved
        decoded = 0  # bytes of the decode budget this request holds
        try:
            length = headers.get("content-length")
            if (length is not None and length != "0") or (
                length is None and "transfer-encoding" in headers
            ):
                buffered = await self._buffer(scope, receive, send, length)
                if buffered is None:
                    return
                receive, body = buffered
                del buffered
                if len(body) >= ESTIMATED_FROM:
                    try:
                        decoded = await self._reserve_decoded(scope, body)
                    except PoseError as exc:
                        refused(scope, exc)
                        await error_response(exc)(scope, receive, send)
                        return
                # not held here while the app runs: the app reads it from ``receive`` and
                # lets it go once decoded; held, every body outlived its request's answer
                # (8 BVH files of 7.6 MB solved at once: +40-50 MiB at peak)
                del body
            await self.app(scope, receive, send)
        finally:
            if admitted:
                self.active -= 1
            self.held -= reserved
            if decoded > 0:
                self.decoded.release(decoded)

    async def _reserve_decoded(self, scope: Scope, body: bytes) -> int:
        """Reserve what ``body`` takes decoded (``service.decoded``) for the request's
        life, waiting no longer than its deadline leaves; the bytes reserved. Raises 413
        for a body that needs more than the whole budget, 504 when it is not free in time."""
        counted: dict[int, int] = {}
        scope[COUNTED] = counted
        need = estimate(body, orjson=scope["path"] in ORJSON_PATHS, counted=counted)
        budget = self.decoded.total
        mib = 1024 * 1024
        if need > budget:
            raise PayloadTooLarge(
                f"this body would take about {need // mib} MiB of memory decoded (its "
                f"{len(body)} bytes hold that many values, objects and arrays), more than "
                f"a worker decodes at once ({budget // mib} MiB): send fewer values, or "
                "split the request",
                limit="POSE_DECODE_MEMORY_BYTES",
            )
        t0 = scope.get(T0, time.perf_counter())
        waited = time.perf_counter()
        if await self.decoded.reserve(need, t0 + self.settings.deadline_seconds):
            return need
        raise DeadlineExceeded(
            f"the request needed more than the {self.settings.deadline_seconds:g} s deadline "
            f"(before decoding the body, after {time.perf_counter() - waited:.2f} s waiting "
            f"for {need // mib} MiB of memory to decode it in): the server is busy; retry "
            "later, or send a smaller request"
        )

    async def _buffer(
        self, scope: Scope, receive: Receive, send: Send, length: str | None
    ) -> tuple[Receive, bytes] | None:
        """Read the body within the size limit and the deadline and hand it on whole,
        with the body (None: refused, answered here)."""
        limit = self.settings.max_body_bytes
        deadline = self.settings.deadline_seconds
        chunks: list[bytes] = []
        size = 0
        late = gone = False
        task = asyncio.current_task()
        assert task is not None
        self._reading[task] = scope.get(T0, time.perf_counter()) + deadline
        if self._watch is None:
            self._watch = asyncio.get_running_loop().create_task(self._watch_reads())
        try:
            while size <= limit:
                message = await receive()
                if message["type"] != "http.request":  # the client closed mid-body
                    gone = True
                    break
                chunks.append(message.get("body", b""))
                size += len(chunks[-1])
                if not message.get("more_body", False):
                    break
        except asyncio.CancelledError:
            if task not in self._late:
                raise
            task.uncancel()  # cancelled by the watch below: answered here
            late = True
        finally:
            del self._reading[task]
            self._late.discard(task)
        if size > limit:
            big = too_large(scope["path"], limit)
            refused(scope, big)
            answer = error_response(big)
            answer.headers["connection"] = "close"  # the rest of the body is not read
            await answer(scope, receive, send)
            return None
        of = f" of {length}" if length is not None else ""
        if gone:  # an unfinished body is never handed on (logged 499, nothing sent)
            left = ClientDisconnected(f"client went away after {size}{of} bytes of the body")
            scope[REASON] = left.type_
            await error_response(left)(scope, receive, send)
            return None
        if late:
            timeout = RequestTimeout(
                f"the request body did not arrive within the {deadline:g} s deadline "
                f"({size}{of} bytes received): send the body without pauses, or a smaller one"
            )
            scope[REASON] = timeout.type_
            answer = error_response(timeout)
            answer.headers["connection"] = "close"
            await answer(scope, receive, send)
            return None
        body = chunks[0] if len(chunks) == 1 else b"".join(chunks)
        replay: list[Message] = [{"type": "http.request", "body": body, "more_body": False}]

        async def receive_buffered() -> Message:
            return replay.pop() if replay else await receive()

        return receive_buffered, body
