"""In-process speed of the service Engine, one thread: latency per solve and batch
throughput. Timings use ``time.perf_counter_ns`` around ``Engine.solve``."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from bench.edits import Edits, problems
from service.engine import Engine, SolveProblem

Json = dict[str, Any]


def _stats(ns: Sequence[int]) -> Json:
    ms = np.asarray(ns, dtype=np.float64) / 1e6
    return {
        "n": len(ms),
        "p50_ms": float(np.percentile(ms, 50)),
        "p99_ms": float(np.percentile(ms, 99)),
        "mean_ms": float(ms.mean()),
    }


def latency(
    engine: Engine,
    sets: dict[int, tuple[str, Edits]],
    *,
    calls: int = 2000,
    fabrik_every: int = 4,
    warmup: int = 50,
) -> Json:
    """Per-call latency of ``engine.solve([p])`` for each target count: neural + bone pass
    (soft) every call and FABRIK every ``fabrik_every``-th call, interleaved in one loop
    (so both see the same machine state). Also neural + exact reach, every 4th call."""
    rows: list[Json] = []
    ratio: dict[str, float] = {}
    for k, (name, edits) in sets.items():
        by_method: dict[str, list[SolveProblem]] = {
            m: problems(edits, m) for m in ("neural_bone", "fabrik", "neural_exact")
        }
        n = len(edits)
        for i in range(warmup):
            for m in by_method:
                engine.solve([by_method[m][i % n]])
        times: dict[str, list[int]] = {m: [] for m in by_method}
        for i in range(calls):
            order = ["neural_bone"]
            if i % fabrik_every == 0:
                order.append("fabrik")
            if i % fabrik_every == 1:
                order.append("neural_exact")
            for m in order:
                p = by_method[m][i % n]
                t0 = time.perf_counter_ns()
                engine.solve([p])
                times[m].append(time.perf_counter_ns() - t0)
        for m, ns in times.items():
            rows.append({"targets": k, "set": name, "method": m, **_stats(ns)})
        neural = next(r for r in rows if r["targets"] == k and r["method"] == "neural_bone")
        fab = next(r for r in rows if r["targets"] == k and r["method"] == "fabrik")
        ratio[str(k)] = fab["p50_ms"] / neural["p50_ms"]
    return {"latency": rows, "ratio": ratio}


def throughput(
    engine: Engine,
    edits: Edits,
    *,
    sizes: Sequence[int] = (1, 4, 16, 64, 256, 1024, 4096),
    fabrik_sizes: Sequence[int] = (1, 16, 256),
    min_seconds: float = 0.5,
    min_items: int = 4096,
) -> list[Json]:
    """Poses/s of one ``Engine.solve`` call per batch, for growing batch sizes."""
    rows: list[Json] = []
    for method, batch_sizes in (("neural_bone", sizes), ("fabrik", fabrik_sizes)):
        probs = problems(edits, method)
        n = len(probs)
        for size in batch_sizes:
            batches = [[probs[(s + j) % n] for j in range(size)] for s in range(0, 4 * size, size)]
            engine.solve(batches[0])  # warm-up
            done, spent, b = 0, 0, 0
            cap = min_items if method == "neural_bone" else min(min_items, 512)
            while spent < min_seconds * 1e9 or done < min(cap, size * 3):
                batch = batches[b % len(batches)]
                t0 = time.perf_counter_ns()
                engine.solve(batch)
                spent += time.perf_counter_ns() - t0
                done += size
                b += 1
                if spent > 10 * min_seconds * 1e9 and b >= 3:
                    break
            rows.append(
                {
                    "method": method,
                    "batch": size,
                    "items": done,
                    "seconds": spent / 1e9,
                    "poses_per_s": done / (spent / 1e9),
                }
            )
    return rows
