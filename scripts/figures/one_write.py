"""``/v1/solve`` at concurrency 1 with and without the one-write answers of
``service.transport`` (docs/limits.md, "One write per small answer").

Two ``pose-service`` servers of this tree side by side (127.0.0.1, 18750-18799): as
shipped, and the same with ``service.transport.COALESCE_BYTES`` set to 0 in its process
(every write sent at once: the headers and the body of an answer in two ``send`` calls,
as uvicorn alone writes them). One client, a keep-alive connection to each, sends
``docs/examples/solve.json`` to the two in turn; each run prints the p50 and mean of each
server after a warm-up. The segment counts are ``tests/service/test_transport.py``'s.

    PYTHONPATH=. python scripts/figures/one_write.py                  # runs of 6,000 and 8,000
    PYTHONPATH=. python scripts/figures/one_write.py --requests 2000
"""

from __future__ import annotations

import argparse
import contextlib
import http.client
import json
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

from loopback import MODELS, example, host_load, port, server

from tests.service.server import Server, serve

SHIM = "--uncoalesced-shim"


@contextlib.contextmanager
def uncoalesced() -> Iterator[Server]:
    """The server as shipped but ``COALESCE_BYTES = 0`` (this file, run as its shim)."""
    wrap = [sys.executable, str(Path(__file__).resolve()), SHIM]
    with (
        tempfile.TemporaryDirectory() as tmp,
        serve(MODELS, Path(tmp), port=port(), wrap=wrap) as s,
    ):
        yield s


def shim() -> None:
    """``one_write.py --uncoalesced-shim python -c CODE``: CODE in this process, writes
    not coalesced."""
    import service.transport

    service.transport.COALESCE_BYTES = 0
    code = sys.argv[sys.argv.index("-c") + 1]
    sys.argv = ["-c"]
    exec(compile(code, "<pose-service>", "exec"), {"__name__": "__main__"})


def run(a: Server, b: Server, requests: int, warmup: int) -> dict[str, list[float]]:
    body = json.dumps(example("solve")).encode()
    conns = {
        name: http.client.HTTPConnection("127.0.0.1", s.port, timeout=30)
        for name, s in (("one write", a), ("two writes", b))
    }
    took: dict[str, list[float]] = {name: [] for name in conns}
    for i in range(warmup + requests):
        for name, conn in conns.items() if i % 2 else reversed(conns.items()):
            t = time.perf_counter()
            conn.request("POST", "/v1/solve", body, {"content-type": "application/json"})
            resp = conn.getresponse()
            resp.read()
            if resp.status != 200:
                raise RuntimeError(f"{name}: {resp.status}")
            if i >= warmup:
                took[name].append(time.perf_counter() - t)
    for conn in conns.values():
        conn.close()
    return took


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == SHIM:
        shim()
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, nargs="+", default=[6000, 8000])
    parser.add_argument("--warmup", type=int, default=200)
    args = parser.parse_args()
    with server() as a, uncoalesced() as b:
        for n in args.requests:
            took = run(a, b, n, args.warmup)
            cells = [
                f"{name} p50 {statistics.median(t) * 1000:.3f} ms, "
                f"mean {statistics.fmean(t) * 1000:.3f} ms"
                for name, t in took.items()
            ]
            print(f"{n} requests each, alternated: " + "; ".join(cells), host_load())


if __name__ == "__main__":
    main()
