"""``make soak``: a bounded soak of the real service at saturation (not part of make test).

``pose-service`` (uvicorn, one worker) on 127.0.0.1, ``--concurrency`` kept-alive
connections in a closed loop (bench.http_load's raw asyncio client) for ``--seconds``
(default 60), a mix of soft, exact, pinned and FABRIK solves; RSS sampled every second.
Prints one JSON line: requests, errors (non-200), requests/s, p50/p99 and RSS at start,
peak and end. Exits 1 on any error."""

from __future__ import annotations

import argparse
import json
import tempfile
import threading
import time
from pathlib import Path

from bench.http_load import load
from tests.service.server import REPO, serve, solve_item


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="soak", description=__doc__)
    ap.add_argument("--models", type=Path, default=REPO / "models")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--concurrency", type=int, default=32)
    args = ap.parse_args(argv)
    payloads = [json.dumps(solve_item(seed, exact=seed % 4 == 0)).encode() for seed in range(256)]
    with (
        tempfile.TemporaryDirectory() as tmp,
        serve(args.models, Path(tmp), POSE_ACCESS_LOG="false") as server,
    ):
        rss = [server.rss_mib()]
        stop = threading.Event()

        def sample() -> None:
            while not stop.wait(1.0):
                rss.append(server.rss_mib())

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        t0 = time.perf_counter()
        stats = load(
            f"http://127.0.0.1:{server.port}/v1/solve", payloads, args.concurrency,
            max_requests=10**9, max_seconds=args.seconds,
        )  # fmt: skip
        stop.set()
        sampler.join()
        report = {
            **{k: round(v, 3) if isinstance(v, float) else v for k, v in stats.items()},
            "wall_s": round(time.perf_counter() - t0, 1),
            "rss_mib_start": round(rss[0], 1),
            "rss_mib_peak": round(max(rss), 1),
            "rss_mib_end": round(server.rss_mib(), 1),
        }
    print(json.dumps(report))
    return 1 if report["errors"] else 0


if __name__ == "__main__":
    raise SystemExit(main())
