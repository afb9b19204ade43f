"""The gate: what a request must satisfy before the app reads it.

- ``/v1/*``: the API key when one is set (``X-API-Key`` or ``Authorization: Bearer``,
  scheme in any case, compared in constant time);
- a body must be ``application/json`` and within ``max_body_bytes`` (declared length
  checked up front, a chunked body counted while it is read);
- admission, per worker: at most ``max_concurrency`` ``/v1`` POSTs in flight and at most
  ``max_inflight_bytes`` of their bodies held at once (a chunked body reserves the whole
  body limit); past either, 429 with ``Retry-After`` before the body is read.
"""

from __future__ import annotations

import hmac

from service.errors import (
    MalformedBody,
    PayloadTooLarge,
    PoseError,
    TooManyRequests,
    Unauthorized,
    UnsupportedMediaType,
    error_response,
)
from service.middleware.types import REASON, ASGIApp, Message, Receive, Scope, Send, header_map
from service.settings import Settings


def _api_key(headers: dict[str, str]) -> str:
    key = headers.get("x-api-key", "")
    scheme, _, credentials = headers.get("authorization", "").strip().partition(" ")
    if not key and scheme.lower() == "bearer":
        key = credentials.strip()
    return key


class Gate:
    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        self.settings = settings
        self.active = 0  # admitted /v1 POSTs in flight
        self.held = 0  # body bytes reserved by them

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
        if method not in ("POST", "PUT", "PATCH") or (length in (None, "0") and not chunked):
            return 0
        ctype = headers.get("content-type", "").split(";")[0].strip().lower()
        if ctype != "application/json":
            raise UnsupportedMediaType(
                f"content type must be application/json, got {ctype[:60] or 'none'!r}"
            )
        if length is not None and not length.isdigit():
            raise MalformedBody(f"Content-Length is not a number: {length[:40]!r}")
        size = s.max_body_bytes if chunked else int(length or 0)
        if size > s.max_body_bytes:
            raise PayloadTooLarge(f"body of {size} bytes exceeds the {s.max_body_bytes}-byte limit")
        if path.startswith("/v1/"):
            if self.active >= s.max_concurrency:
                raise TooManyRequests(
                    f"{self.active} requests in flight on this worker (limit {s.max_concurrency})"
                )
            if self.held + size > s.max_inflight_bytes:
                raise TooManyRequests(
                    f"{self.held} body bytes in flight on this worker "
                    f"(limit {s.max_inflight_bytes})"
                )
            return size
        return 0

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = header_map(scope)
        try:
            reserved = self._check(scope, headers)
        except PoseError as exc:
            scope[REASON] = exc.type_
            await error_response(exc)(scope, receive, send)
            return
        admitted = scope["path"].startswith("/v1/") and reserved > 0
        if admitted:
            self.active += 1
            self.held += reserved
        try:
            if "content-length" not in headers and "transfer-encoding" in headers:
                buffered = await self._buffer(scope, receive, send)
                if buffered is None:
                    return
                receive = buffered
            await self.app(scope, receive, send)
        finally:
            if admitted:
                self.active -= 1
                self.held -= reserved

    async def _buffer(self, scope: Scope, receive: Receive, send: Send) -> Receive | None:
        """Read a chunked body within the limit and hand it on whole (None: refused)."""
        limit = self.settings.max_body_bytes
        chunks: list[bytes] = []
        size = 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                break
            chunks.append(message.get("body", b""))
            size += len(chunks[-1])
            if size > limit:
                big = PayloadTooLarge(f"body exceeds the {limit}-byte limit")
                scope[REASON] = big.type_
                await error_response(big)(scope, receive, send)
                return None
            if not message.get("more_body", False):
                break
        replay: list[Message] = [
            {"type": "http.request", "body": b"".join(chunks), "more_body": False}
        ]

        async def receive_buffered() -> Message:
            return replay.pop() if replay else await receive()

        return receive_buffered
