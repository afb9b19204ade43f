"""The headers every answer carries, whichever layer gives it (this layer is the outermost,
so CORS preflights and the last-resort 500 and 503 answers carry them too):

- ``X-Request-ID``: the client's (printable, at most 128 characters) or 32 random hex
  digits, made once per request (:func:`request_id`; the access log names it);
- ``X-Total-Time``: the whole request in ms, from arrival to the response's headers (the
  engine's own time is the route's ``X-Compute-Time``);
- hardening: no MIME sniffing, no framing, no referrer, and a Content Security Policy
  (HTML pages may load their own scripts and styles only).

It also notes the answer's status in the scope for the layers inside (the access log, the
metrics, the last-resort answers: ``types.observed``), as it sees every answer."""

from __future__ import annotations

import os
import time

from service.middleware.types import (
    REQUEST_ID,
    STATUS,
    T0,
    ASGIApp,
    Message,
    Receive,
    Scope,
    Send,
)

#: JSON answers load nothing.
API_CSP = b"default-src 'none'; frame-ancestors 'none'; base-uri 'none'"
#: The hardening headers of every answer (also the HTTP protocol's own: service.transport).
BASE_HEADERS = [
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"no-referrer"),
    (b"cross-origin-opener-policy", b"same-origin"),
]

#: The hardening headers an answer that sets none of them gets (in the order given).
_HARDENING = [*BASE_HEADERS, (b"content-security-policy", API_CSP)]
_STAMPED = frozenset(k for k, _ in _HARDENING)


def protocol_headers(t0: float) -> list[tuple[bytes, bytes]]:
    """The headers of an answer the HTTP protocol gives before any app runs (a head too
    large, bytes that are not HTTP: ``service.transport``), as this layer stamps every
    other: a fresh request id (the request's own headers may be what was refused), the
    time since its head began, the hardening headers and the API's CSP."""
    ms = f"{(time.perf_counter() - t0) * 1000:.3f}ms".encode()
    return [
        (b"x-request-id", os.urandom(16).hex().encode()),
        (b"x-total-time", ms),
        *BASE_HEADERS,
        (b"content-security-policy", API_CSP),
    ]


#: Request ids drawn from one ``os.urandom`` call.
IDS_AT_ONCE = 256
_random = bytearray()  # os.urandom's bytes not yet used, for IDS_AT_ONCE ids at a time


def _fresh_id() -> str:
    """32 random hex digits (16 bytes of ``os.urandom``, drawn for many ids at once: a
    system call a request was ~1-2 us of it)."""
    if not _random:
        _random.extend(os.urandom(16 * IDS_AT_ONCE))
    drawn = _random[-16:]
    del _random[-16:]
    if len(drawn) != 16:  # (another thread emptied it meanwhile: the event loop's alone now)
        drawn = bytearray(os.urandom(16))
    return drawn.hex()


os.register_at_fork(after_in_child=_random.clear)  # (a child draws its own)


def request_id(scope: Scope) -> str:
    """The request's id: the client's ``X-Request-ID`` (printable, at most 128 characters)
    or 32 random hex digits; made once per request and kept in its scope."""
    known: str | None = scope.get(REQUEST_ID)
    if known is None:
        given = next((v for k, v in scope["headers"] if k.lower() == b"x-request-id"), b"")
        text = given.decode("latin-1")
        known = "".join(c for c in text[:128] if c.isprintable()) or _fresh_id()
        scope[REQUEST_ID] = known
    return known


class AnswerHeaders:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        t0: float = scope.setdefault(T0, time.perf_counter())
        tag = (b"x-request-id", request_id(scope).encode("latin-1", "replace"))
        status = [0]  # the answer's, for the layers inside (types.observed: no wrapper of theirs)
        scope[STATUS] = status

        async def stamped(message: Message) -> None:
            if message["type"] == "http.response.start":
                status[0] = int(message["status"])
                headers = list(message.get("headers", []))
                names = {k.lower() for k, _ in headers}
                ms = f"{(time.perf_counter() - t0) * 1000:.3f}ms".encode()
                extra = [tag, (b"x-total-time", ms)]
                if names.isdisjoint(_STAMPED):  # (most answers: every one of them added)
                    extra += _HARDENING
                else:
                    extra += [(k, v) for k, v in BASE_HEADERS if k not in names]
                    if b"content-security-policy" not in names:  # pages set their own
                        extra.append((b"content-security-policy", API_CSP))
                message["headers"] = headers + extra
            await send(message)

        await self.app(scope, receive, stamped)
