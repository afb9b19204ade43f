"""Hardening headers on every answer: no MIME sniffing, no framing, no referrer, and a
Content Security Policy (HTML pages may load their own scripts and styles only)."""

from __future__ import annotations

from service.middleware.types import ASGIApp, Message, Receive, Scope, Send

#: JSON answers load nothing.
API_CSP = b"default-src 'none'; frame-ancestors 'none'; base-uri 'none'"
_BASE = [
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"no-referrer"),
    (b"cross-origin-opener-policy", b"same-origin"),
]


class SecurityHeaders:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def harden(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                names = {k.lower() for k, _ in headers}
                extra = [(k, v) for k, v in _BASE if k not in names]
                if b"content-security-policy" not in names:  # pages set their own
                    extra.append((b"content-security-policy", API_CSP))
                message["headers"] = headers + extra
            await send(message)

        await self.app(scope, receive, harden)
