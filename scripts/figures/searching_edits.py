"""Edits that search the body's turn, over HTTP (docs/limits.md, "Work per request": the
turn search's place, in a worker thread, and what a flood of such edits does to requests
not read yet). Each sub-command starts a fresh ``pose-service`` of this tree
(127.0.0.1, 18750-18799, default settings: a 2 s deadline).

    PYTHONPATH=. python scripts/figures/searching_edits.py lone    # one client, 5-target edits
    PYTHONPATH=. python scripts/figures/searching_edits.py mixed   # 5-target and 2-target at once
    PYTHONPATH=. python scripts/figures/searching_edits.py unread  # 64 clients, 18 targets
    PYTHONPATH=. python scripts/figures/searching_edits.py bare    # uvloop against asyncio

An edit's targets are its joints in ``docs/examples/solve.json``'s pose turned a quarter
about the vertical through the pelvis (a turn the gate, ``serving.turn_gate``, searches
for); the 2-target edit moves both wrists 5 cm (it never searches). Each line tells how
many answers the search turned (their solver path ends ``turn <deg>`` or ``fit <deg>``;
one that searched and kept its start says nothing: the 18-target edit searches, 14
solves, ~20 ms of engine time against ~6 with ``turn_search: false``, and keeps it).

``unread``: each client sends its edits one after another on its own connection; the
time a request waited unread is the client's time (send to answer) less the server's
``X-Total-Time`` (its clock starts when the HTTP protocol has read the request's head).

``bare``: no service, a bare HTTP server on one event loop (uvloop's, then asyncio's, each
in a process of its own) that blocks its loop ``--step-ms`` for every request, as a
solve on the loop did; the same clients stamp the send time (``time.time()``) in a
header, and the server answers with how long after it read the request's head.
"""

from __future__ import annotations

import argparse
import asyncio
import http.client
import json
import multiprocessing
import statistics
import threading
import time
from typing import Any

import numpy as np
from loopback import example, host_load, port, server

from core.skeleton import JOINT_NAMES
from tests.service.server import Server

FIVE = ["head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"]
EIGHTEEN = list(JOINT_NAMES[3:])


def edit(joints: list[str], turn_deg: float, passes: int | None = None) -> bytes:
    """The example pose with ``joints`` targeted where a ``turn_deg`` turn about the
    vertical through the pelvis carries them (0: both wrists moved 5 cm up instead)."""
    pose = example("solve")["pose"]
    pelvis = np.asarray(pose["pelvis"])
    a = np.radians(turn_deg)
    turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    targets = []
    for j in joints:
        p = np.asarray(pose[j])
        goal = pelvis + turn @ (p - pelvis) if turn_deg else p + np.array([0, 0.05, 0])
        targets.append({"joint": j, "position": goal.round(5).tolist()})
    options: dict[str, Any] = {} if passes is None else {"passes": passes}
    return json.dumps({"pose": pose, "targets": targets, "options": options}).encode()


def turned(body: bytes) -> bool:
    solvers = json.loads(body).get("solvers", [""])
    return bool(solvers) and solvers[-1].split(" ")[0] in ("turn", "fit")


class Client:
    """One keep-alive connection sending ``body`` to ``/v1/solve`` again and again."""

    def __init__(self, s: Server, body: bytes, timeout: float = 60.0) -> None:
        self.conn = http.client.HTTPConnection("127.0.0.1", s.port, timeout=timeout)
        self.body = body
        self.seconds: list[float] = []  # client's time, send to whole answer
        self.unread: list[float] = []  # that less the server's X-Total-Time
        self.codes: list[int] = []
        self.turned = 0

    def send(self) -> None:
        t = time.perf_counter()
        self.conn.request("POST", "/v1/solve", self.body, {"content-type": "application/json"})
        resp = self.conn.getresponse()
        data = resp.read()
        took = time.perf_counter() - t
        self.seconds.append(took)
        total = float((resp.getheader("x-total-time") or "nan").removesuffix("ms")) / 1000
        self.unread.append(took - total)
        self.codes.append(resp.status)
        self.turned += resp.status == 200 and turned(data)


def ms(values: list[float], q: float = 0.5) -> str:
    return f"{np.quantile(values, q) * 1000:.2f} ms"


def lone(args: argparse.Namespace) -> None:
    """One client, a 5-target searching edit at a time: p50 and mean over HTTP."""
    with server() as s:
        c = Client(s, edit(FIVE, 90.0))
        for _ in range(args.warmup):
            c.send()
        c.seconds.clear()
        c.turned = 0
        for _ in range(args.requests):
            c.send()
    print(
        f"a lone 5-target edit ({c.turned} of {args.requests} turned), one client: "
        f"p50 {ms(c.seconds)}, mean {statistics.fmean(c.seconds) * 1000:.2f} ms"
    )


def mixed(args: argparse.Namespace) -> None:
    """Two clients at once for ``--seconds``: one sends 5-target searching edits, the
    other 2-target ones; the p50 of each."""
    with server() as s:
        five, two = Client(s, edit(FIVE, 90.0)), Client(s, edit(["left_wrist", "right_wrist"], 0))
        for c in (five, two):
            c.send()
            c.seconds.clear()
            c.turned = 0
        end = time.monotonic() + args.seconds

        def loop(c: Client) -> None:
            while time.monotonic() < end:
                c.send()

        threads = [threading.Thread(target=loop, args=(c,)) for c in (five, two)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
    print(
        f"two clients at once, {args.seconds:g} s: 5-target edits p50 {ms(five.seconds)} "
        f"({len(five.seconds)}, {five.turned} turned), 2-target p50 {ms(two.seconds)} "
        f"({len(two.seconds)}, {two.turned} turned)"
    )


def unread(args: argparse.Namespace) -> None:
    """``--clients`` clients each sending ``--each`` of one 18-target, 4-pass searching edit
    one after another: statuses, the longest client wait and how long requests waited
    unread by the server."""
    body = edit(EIGHTEEN, 90.0, passes=args.passes)
    with server() as s:
        clients = [Client(s, body) for _ in range(args.clients)]
        start = threading.Barrier(args.clients)

        def run(c: Client) -> None:
            start.wait()
            for _ in range(args.each):
                c.send()

        threads = [threading.Thread(target=run, args=(c,)) for c in clients]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
    waits = [w for c in clients for w in c.seconds]
    gaps = [g for c in clients for g in c.unread]
    codes = [code for c in clients for code in c.codes]
    counts = " ".join(f"{k}×{codes.count(k)}" for k in sorted(set(codes)))
    print(
        f"{args.clients} clients × {args.each} of an 18-target {args.passes}-pass edit "
        f"({sum(c.turned for c in clients)} turned): {counts}; longest client wait "
        f"{max(waits):.2f} s; unread by the server: p50 {ms(gaps)}, p99 {ms(gaps, 0.99)}, "
        f"max {max(gaps):.2f} s"
    )


def bare_server(port: int, loop: str, step: float) -> None:
    """The bare server: each request's head read, ``step`` s of the loop blocked, an
    answer whose body is the time (s) from the client's stamp to the head's read."""

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while True:
                head = await reader.readuntil(b"\r\n\r\n")
                read = time.time()
                sent = next(float(h.split(b":")[1]) for h in head.split(b"\r\n")
                            if h.lower().startswith(b"x-sent:"))  # fmt: skip
                time.sleep(step)  # a solve on the loop
                body = f"{read - sent:.6f}".encode()
                writer.write(b"HTTP/1.1 200 OK\r\ncontent-length: %d\r\n\r\n%s" % (len(body), body))
                await writer.drain()
        except (asyncio.IncompleteReadError, ConnectionError):
            writer.close()

    async def serve() -> None:
        srv = await asyncio.start_server(handle, "127.0.0.1", port, backlog=256)
        async with srv:
            await srv.serve_forever()

    if loop == "uvloop":
        import uvloop

        uvloop.run(serve())
    else:
        asyncio.run(serve())


def bare_gaps(loop: str, clients: int, each: int, step: float) -> list[float]:
    """The bare server on ``loop`` in a process of its own, ``clients`` × ``each``
    requests: each one's time unread (s)."""
    p = port()
    proc = multiprocessing.Process(target=bare_server, args=(p, loop, step))
    proc.start()
    gaps: list[float] = []
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                probe = http.client.HTTPConnection("127.0.0.1", p, timeout=1)
                probe.connect()
                probe.close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        start = threading.Barrier(clients)

        def run() -> None:
            conn = http.client.HTTPConnection("127.0.0.1", p, timeout=120)
            start.wait()
            for _ in range(each):
                conn.request("GET", "/", headers={"x-sent": f"{time.time():.6f}"})
                gaps.append(float(conn.getresponse().read()))
            conn.close()

        threads = [threading.Thread(target=run) for _ in range(clients)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
    finally:
        proc.terminate()
        proc.join()
    return gaps


def bare(args: argparse.Namespace) -> None:
    """``--clients`` clients × ``--each`` requests against the bare server on each loop:
    how long requests waited unread (client stamp to the server's read)."""
    for loop in ("uvloop", "asyncio"):
        gaps = bare_gaps(loop, args.clients, args.each, args.step_ms / 1000)
        print(
            f"bare {loop} server, {args.step_ms:g} ms blocked a request, {args.clients} clients "
            f"× {args.each}: unread p50 {ms(gaps)}, p99 {np.quantile(gaps, 0.99):.2f} s, "
            f"max {max(gaps):.2f} s"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="figure", required=True)
    p = sub.add_parser("lone", help=lone.__doc__)
    p.add_argument("--requests", type=int, default=2000)
    p.add_argument("--warmup", type=int, default=100)
    p.set_defaults(run=lone)
    p = sub.add_parser("mixed", help=mixed.__doc__)
    p.add_argument("--seconds", type=float, default=20.0)
    p.set_defaults(run=mixed)
    p = sub.add_parser("unread", help=unread.__doc__)
    p.add_argument("--clients", type=int, default=64)
    p.add_argument("--each", type=int, default=4)
    p.add_argument("--passes", type=int, default=4)
    p.set_defaults(run=unread)
    p = sub.add_parser("bare", help=bare.__doc__)
    p.add_argument("--clients", type=int, default=64)
    p.add_argument("--each", type=int, default=4)
    p.add_argument("--step-ms", type=float, default=20.0)
    p.set_defaults(run=bare)
    args = parser.parse_args()
    args.run(args)
    print(host_load())


if __name__ == "__main__":
    main()
