"""Refusals leave a trace an operator can follow: the HTTP parser's (bytes that are not
HTTP, a head too large: answered below the app, ``service.transport``) a rate-limited
``connection_closed`` line with the status, the client, the request id it got and why, and
a count in ``pose_connections_closed_total``; every access-log line its client's address,
a 413's or a 429's the problem type and the limit that refused it. An ops audit found
uvicorn's "Invalid HTTP request received." alone (no status, no client, no id; 7,482
lines in 3 s from one client looping garbage) and 413s and 429s without a word of why."""

from __future__ import annotations

import json
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.service.server import Server, serve, solve_item

pytestmark = pytest.mark.slow

ENV = {
    "POSE_MAX_BODY_BYTES": "65536",
    "POSE_MAX_INFLIGHT_BYTES": "65536",
    "POSE_MAX_BATCH_ITEMS": "2",
}


@pytest.fixture(scope="module")
def server(models_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    with serve(models_dir, tmp_path_factory.mktemp("refusals"), **ENV) as s:
        yield s


def _sent(port: int, data: bytes) -> tuple[str, dict[str, str], str]:
    """``data`` sent on a fresh connection: the answer's status line, headers (lower-case
    names) and the connection's local address as the server sees it."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        host, port_here = sock.getsockname()[:2]
        here = f"{host}:{port_here}"
        sock.sendall(data)
        answer = b""
        while b"\r\n\r\n" not in answer:
            chunk = sock.recv(1 << 16)
            if not chunk:
                break
            answer += chunk
    head = answer.split(b"\r\n\r\n", 1)[0].decode("latin-1").split("\r\n")
    fields = dict(line.split(": ", 1) for line in head[1:])
    return head[0], {k.lower(): v for k, v in fields.items()}, here


def _lines(server: Server, event: str) -> list[dict[str, Any]]:
    return [e for e in server.log_lines() if e.get("event") == event]


def _metric(server: Server, series: str) -> float:
    text = server.request("GET", "/metrics")[2].decode()
    (line,) = [x for x in text.splitlines() if x.startswith(series + " ")]
    return float(line.split()[1])


GARBAGE = b"GARBAGE\r\n\r\n"
CL_TE = (b"POST /v1/solve HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
         b"Content-Length: 5\r\nTransfer-Encoding: chunked\r\n\r\n0\r\n\r\n")  # fmt: skip
NEGATIVE_CL = (b"POST /v1/solve HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
               b"Content-Length: -1\r\n\r\n")  # fmt: skip
BIG_HEAD = b"GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + b"a" * 70000 + b"\r\n\r\n"
MALFORMED = 'pose_connections_closed_total{reason="malformed-http"}'
TOO_LARGE = 'pose_connections_closed_total{reason="head-too-large"}'


def test_parser_refusals_are_logged_and_counted(server: Server) -> None:
    before = _metric(server, MALFORMED), _metric(server, TOO_LARGE)
    status, fields, client = _sent(server.port, GARBAGE)
    assert status.startswith("HTTP/1.1 400 "), status
    time.sleep(1.1)  # (a line a second per reason at most: the next is a line of its own)
    big_status, big_fields, big_client = _sent(server.port, BIG_HEAD)
    assert big_status.startswith("HTTP/1.1 431 "), big_status
    for data in (CL_TE, NEGATIVE_CL):
        assert _sent(server.port, data)[0].startswith("HTTP/1.1 400 ")
    time.sleep(0.2)
    assert _metric(server, MALFORMED) == before[0] + 3
    assert _metric(server, TOO_LARGE) == before[1] + 1
    lines = {(e["reason"], e["request_id"]): e for e in _lines(server, "connection_closed")}
    garbage = lines[("malformed-http", fields["x-request-id"])]
    assert garbage["level"] == "warning" and garbage["status"] == 400, garbage
    assert garbage["client"] == client and garbage["why"] == "Invalid method encountered"
    big = lines[("head-too-large", big_fields["x-request-id"])]
    assert big["status"] == 431 and big["client"] == big_client, big
    assert "65536 bytes" in big["why"], big
    messages = [e.get("message") for e in server.log_lines()]
    assert "Invalid HTTP request received." not in messages  # (uvicorn's: said none of it)


def test_a_flood_of_garbage_is_a_line_a_second(server: Server) -> None:
    """The audit's client looping garbage for 3 s wrote 7,482 warning lines; now a line a
    second at most, ``events`` counting the refusals it stands for, every one counted."""
    time.sleep(1.1)
    before, had = _metric(server, MALFORMED), len(_lines(server, "connection_closed"))
    t0, n = time.monotonic(), 0
    while time.monotonic() - t0 < 2.5:
        assert _sent(server.port, GARBAGE)[0].startswith("HTTP/1.1 400 ")
        n += 1
    took = time.monotonic() - t0
    time.sleep(0.2)
    assert n > 50, n
    assert _metric(server, MALFORMED) == before + n
    new = [e for e in _lines(server, "connection_closed")[had:] if e["reason"] == "malformed-http"]
    assert 1 <= len(new) <= took + 1, new
    assert new[-1]["events"] > 1 and sum(e["events"] for e in new) <= n, new


def _request(port: int, path: str, body: bytes) -> tuple[str, dict[str, str], str]:
    head = (f"POST {path} HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
            f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n").encode()  # fmt: skip
    return _sent(port, head + body)


def test_access_log_names_the_client_and_the_limit(server: Server) -> None:
    one = json.dumps({"items": [solve_item(1)]}).encode()
    three = json.dumps({"items": [solve_item(i) for i in range(3)]}).encode()
    big = json.dumps({"items": [solve_item(1)], "pad": "x" * 70000}).encode()
    answers = {
        "ok": _request(server.port, "/v1/solve/batch", one),
        "items": _request(server.port, "/v1/solve/batch", three),
        "bytes": _request(server.port, "/v1/solve/batch", big),
        "invalid": _request(server.port, "/v1/solve", b'{"targets": 1}'),
    }
    # a chunked body under way reserves the whole body limit (65536, the in-flight budget):
    # the next body is a 429 for POSE_MAX_INFLIGHT_BYTES
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as held:
        held.sendall(b"POST /v1/solve HTTP/1.1\r\nHost: x\r\nContent-Type: application/json"
                     b"\r\nTransfer-Encoding: chunked\r\n\r\n1\r\n{\r\n")  # fmt: skip
        time.sleep(0.3)
        answers["busy"] = _request(server.port, "/v1/solve/batch", one)
    time.sleep(0.3)
    by_id = {e["request_id"]: e for e in _lines(server, "request")}
    want = {
        "ok": ("200", None, None),
        "items": ("413", "too-many-items", "POSE_MAX_BATCH_ITEMS"),
        "bytes": ("413", "payload-too-large", "POSE_MAX_BODY_BYTES"),
        "invalid": ("422", "invalid-request", None),
        "busy": ("429", "too-many-requests", "POSE_MAX_INFLIGHT_BYTES"),
    }
    for case, (status, fields, client) in answers.items():
        assert status.split()[1] == want[case][0], (case, status)
        line = by_id[fields["x-request-id"]]
        assert line["client"] == client, (case, line)
        assert (line.get("outcome"), line.get("limit")) == want[case][1:], (case, line)
