"""The gate hands a body on and keeps no reference to it while the app runs
(service.middleware.gate)."""

from __future__ import annotations

import asyncio
import gc
from typing import Any

from service.decoded import ESTIMATED_FROM
from service.middleware.gate import Gate
from service.settings import Settings


def test_the_gate_holds_no_body_while_its_app_runs() -> None:
    """Once the app has read a body, the gate no longer holds it: the app lets it go once
    decoded. The gate held every body it read (to price it for the decode budget) until
    its request's answer was sent: 8 BVH files of 7.6 MB solved at once peaked 40-50 MiB
    higher (2026-12-06, loopback, scripts/rss_bursts.py's burst)."""
    body = b'{"values": [' + b"1," * ESTIMATED_FROM + b"1]}"  # priced: the decode budget's
    scope: dict[str, Any] = {
        "type": "http", "method": "POST", "path": "/v1/solve/batch", "query_string": b"",
        "headers": [(b"content-type", b"application/json"),
                    (b"content-length", str(len(body)).encode())],
    }  # fmt: skip
    inbox = [{"type": "http.request", "body": body, "more_body": False}]
    del body
    holders: list[str] = []

    async def receive() -> dict[str, Any]:
        return inbox.pop(0) if inbox else {"type": "http.disconnect"}

    async def send(message: dict[str, Any]) -> None:
        pass

    async def app(scope: Any, receive: Any, send: Any) -> None:
        got = (await receive())["body"]
        assert len(got) > ESTIMATED_FROM
        for r in gc.get_referrers(got):
            if getattr(r, "cr_code", None) is Gate.__call__.__code__ or isinstance(r, tuple):
                holders.append(repr(r)[:80])

    gate = Gate(app, Settings())
    asyncio.run(gate(scope, receive, send))  # type: ignore[arg-type]
    assert holders == []
    assert gate.held == 0 and gate.decoded.held == 0  # its bytes and its budget given back
