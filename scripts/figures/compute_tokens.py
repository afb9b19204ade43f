"""How a server's compute tokens are shared (docs/limits.md, "Work per request"): one
figure per sub-command, each on a fresh ``pose-service`` of this tree (127.0.0.1,
18750-18799) but ``threads``, which runs the app in this process.

    PYTHONPATH=. python scripts/figures/compute_tokens.py threads       # a lone batch, 1|2 threads
    PYTHONPATH=. python scripts/figures/compute_tokens.py answer-write  # 504s before the answer
    PYTHONPATH=. python scripts/figures/compute_tokens.py token-wait    # 64 at once: the last 504
    PYTHONPATH=. python scripts/figures/compute_tokens.py oldest-first  # 16, 42 at 2 s; 8 at 30 s

The columnar batches are 1,024 real edits each (``data/poses.npz``'s test split, both
wrists; ``loopback.columnar_batches``, seed 0), the item batches
``tests/service/server.py``'s ``heavy_batch`` (exact reach, pinned ankles, distinct
target sets). Every figure prints as one line to paste.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Sequence

from loopback import (
    MODELS,
    Answer,
    at_once,
    columnar_batches,
    host_load,
    reset_peak,
    server,
    statuses,
    vm_mib,
)

from tests.service.server import heavy_batch

BATCH = "/v1/solve/batch"


def spread(values: Sequence[float], unit: str = "s") -> str:
    return f"{min(values):.2f}–{max(values):.2f} {unit}" if values else "none"


def threads(args: argparse.Namespace) -> None:
    """``X-Compute-Time`` (the engine's own time) of one columnar batch of 1,024 edits at
    2 passes, sent alone, in-process (FastAPI's TestClient), with ``compute_threads`` 1 and
    2 in turn; per round the median of ``--requests`` requests after one warm-up. With
    the CPU time this process spent a request: two threads can only beat one where the
    host leaves this process a second core."""
    from tests.conftest import make_client

    body = columnar_batches(1, passes=args.passes)[0]
    medians: dict[int, list[float]] = {1: [], 2: []}
    cpus: dict[int, list[float]] = {1: [], 2: []}  # this process's CPU s a request, app and all
    for _ in range(args.rounds):
        for width in (1, 2):
            with make_client(MODELS, compute_threads=width, deadline_seconds=60.0) as c:
                c.post(BATCH, content=body, headers={"content-type": "application/json"})
                ms = []
                for _ in range(args.requests):
                    cpu = time.process_time()
                    r = c.post(BATCH, content=body, headers={"content-type": "application/json"})
                    cpus[width].append(time.process_time() - cpu)
                    assert r.status_code == 200, r.text
                    ms.append(float(r.headers["x-compute-time"].removesuffix("ms")))
                medians[width].append(statistics.median(ms))
    one, two = (", ".join(f"{m:.1f}" for m in medians[w]) for w in (1, 2))
    print(
        f"1,024 columnar edits at {args.passes} passes, engine time (median of "
        f"{args.requests} a round, {args.rounds} rounds): one thread {one} ms, two {two} ms; "
        f"CPU time a request (the whole app, median) {statistics.median(cpus[1]) * 1000:.0f} "
        f"and {statistics.median(cpus[2]) * 1000:.0f} ms"
    )


def before_writing(answers: Sequence[Answer]) -> int:
    return sum(a.status == 504 and "before writing the answer" in a.problem() for a in answers)


def answer_write(args: argparse.Namespace) -> None:
    """``--at-once`` columnar batches sent at once, ``--rounds`` times, at a 2 s deadline:
    how many 504s said "before writing the answer" (a batch whose items were all done)."""
    bodies = columnar_batches(args.at_once)
    late, seen = 0, []
    with server(POSE_DEADLINE_SECONDS=str(args.deadline)) as s:
        for _ in range(args.rounds):
            answers = at_once(s, BATCH, bodies)
            late += before_writing(answers)
            seen.extend(answers)
    print(
        f"{args.at_once} columnar 1,024-edit batches at once, {args.deadline:g} s deadline, "
        f"{args.rounds} rounds: {late} 504s before writing the answer in {len(seen)} requests "
        f"({statuses(seen)})"
    )


def token_wait(args: argparse.Namespace) -> None:
    """``--at-once`` item batches of 1,024 exact-reach items sent at once at a 2 s
    deadline: when the last answer (and the last 504) came, and the server's peak RSS."""
    bodies = [heavy_batch(1024, seed=1024 * i) for i in range(args.at_once)]
    with server(POSE_DEADLINE_SECONDS=str(args.deadline)) as s:
        time.sleep(0.3)
        reset_peak(s.proc.pid)
        answers = at_once(s, BATCH, bodies)
        peak = vm_mib(s.proc.pid, "VmHWM")
    t0 = min(a.sent for a in answers)
    ends = [a.sent + a.seconds - t0 for a in answers]
    late = [e for e, a in zip(ends, answers, strict=True) if a.status == 504]
    print(
        f"{args.at_once} item batches of 1,024 exact-reach items at once, {args.deadline:g} s "
        f"deadline: {statuses(answers)}; last answer after {max(ends):.2f} s, last 504 after "
        f"{max(late) if late else float('nan'):.2f} s; peak RSS {peak:.0f} MiB"
    )


def oldest_first(args: argparse.Namespace) -> None:
    """Columnar 1,024-edit batches sent at once: how many of 16 and of 42 are answered at
    a 2 s deadline (the rest 504), and with 8 at a 30 s deadline (no deadline pressure)
    when the first and the last answer came."""
    for n, deadline in ((16, 2.0), (42, 2.0), (8, 30.0)):
        bodies = columnar_batches(n)
        with server(POSE_DEADLINE_SECONDS=str(deadline)) as s:
            answers = at_once(s, BATCH, bodies)
        t0 = min(a.sent for a in answers)
        done = sorted(a.sent + a.seconds - t0 for a in answers if a.status == 200)
        first_last = f"first {done[0]:.2f} s, last {done[-1]:.2f} s" if done else "none"
        print(
            f"{n} at once, {deadline:g} s deadline: {sum(a.status == 200 for a in answers)} "
            f"answered ({statuses(answers)}), answers {first_last}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="figure", required=True)
    p = sub.add_parser("threads", help=threads.__doc__)
    p.add_argument("--passes", type=int, default=2)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--requests", type=int, default=5)
    p.set_defaults(run=threads)
    p = sub.add_parser("answer-write", help=answer_write.__doc__)
    p.add_argument("--at-once", type=int, default=16)
    p.add_argument("--rounds", type=int, default=6)
    p.add_argument("--deadline", type=float, default=2.0)
    p.set_defaults(run=answer_write)
    p = sub.add_parser("token-wait", help=token_wait.__doc__)
    p.add_argument("--at-once", type=int, default=64)
    p.add_argument("--deadline", type=float, default=2.0)
    p.set_defaults(run=token_wait)
    p = sub.add_parser("oldest-first", help=oldest_first.__doc__)
    p.set_defaults(run=oldest_first)
    args = parser.parse_args()
    args.run(args)
    print(host_load())


if __name__ == "__main__":
    main()
