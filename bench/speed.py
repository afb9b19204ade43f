"""In-process speed of the service Engine, one thread: latency per solve and batch
throughput. Timings use ``time.perf_counter_ns`` around ``Engine.solve``."""

from __future__ import annotations

import copy
import dataclasses
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from bench.edits import Edits, problems
from service.engine import Engine
from service.limits import Pricing, chunks, fan_out
from service.problems import SolveProblem
from service.turns import NO_SEARCH

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


def issue14(
    engine: Engine,
    sets: dict[int, tuple[str, Edits]],
    *,
    composed: dict[int, tuple[str, Edits]] | None = None,
    calls: int = 2000,
    warmup: int = 50,
    tolerance: float = 1e-4,
    batch: int = 4096,
    batch_rounds: int = 5,
) -> Json:
    """Issue 14's figures, side by side in one loop per target count (one thread):

    - ``neural``: ``engine.solve([p])``, neural + bone pass (soft), a different edit per call;
    - ``fabrik_compiled``: the same call with ``method=fabrik`` (the engine's compiled
      FABRIK), and ``fabrik_kernel``: the compiled FABRIK kernel alone on the canonical
      edit (no engine glue);
    - ``fabrik_numpy``: ``core.kinematics.fabrik`` (the numpy FABRIK the engine ran before);
    - ``neural_passes1``: the ``neural`` call with ``passes=1`` (``options.passes``), beside
      the engine's default (the models' ``serving.passes``);
    - ``neural_no_mirror``: with ``mirror=False`` (``options.mirror``), when the engine's
      default solves the mirror image too (``serving.solve_mirror``);
    - ``neural_numpy_mirror``: the ``neural`` call with the mirror image asked around the
      fused graphs in numpy (the engine without its mirror graphs, ``trainer.mirror``),
      when the default solves it and the models ship them;
    - ``neural_pinned``: the ``neural`` call with both ankles pinned where the start has
      them (sets without an ankle);
    - ``composed``: the same timings on sets no trained solver covers whole (several
      solvers composed), beside the goals' sets.

    FABRIK with ``tolerance`` (m) and the engine's iteration cap. Then in-process batch
    throughput of ``engine.solve_arrays`` and ``engine.solve`` on ``batch`` edits (2
    targets), at the default passes and at ``passes=1`` (``*_passes1``) or without the
    mirror image (``*_no_mirror``, when the default has it), and of
    ``solve_arrays`` on 2 threads (``solve_arrays_2threads``: the batch's priced parts
    fanned out as the service runs them on its 2 compute threads, ``service.limits``)."""
    rows = [
        _issue14_set(engine, k, name, edits, calls, warmup, tolerance)
        for k, (name, edits) in sets.items()
    ]
    extra = [
        _issue14_set(engine, k, name, edits, calls, warmup, tolerance)
        for k, (name, edits) in (composed or {}).items()
    ]
    two = sets[2][1]
    reps = -(-batch // len(two))
    starts = np.concatenate([two.start] * reps)[:batch]
    tidx = np.stack(two.joints * reps)[:batch]
    tpos = np.concatenate([np.stack(two.targets)] * reps)[:batch]
    probs = [p for _ in range(reps) for p in problems(two, "neural_bone")][:batch]
    probs1 = [dataclasses.replace(p, passes=1) for p in probs]
    plain = [dataclasses.replace(p, mirror=False) for p in probs]
    # a batch as the service runs it on 2 compute threads: its priced parts, fanned out
    parts = chunks(probs, Pricing.of(engine))

    def two_threads() -> object:
        return fan_out(lambda p: engine.solve_arrays(starts[p], tidx[p], tpos[p]), parts, 2)

    runs: dict[str, Callable[[], object]] = {
        "solve_arrays": lambda: engine.solve_arrays(starts, tidx, tpos),
        "solve_arrays_2threads": two_threads,
        "solve": lambda: engine.solve(probs),
        "solve_arrays_passes1": lambda: engine.solve_arrays(starts, tidx, tpos, passes=1),
        "solve_passes1": lambda: engine.solve(probs1),
    }
    if engine.serving.solve_mirror:  # the fast path a request can take: options.mirror false
        runs["solve_arrays_no_mirror"] = lambda: engine.solve_arrays(
            starts, tidx, tpos, mirror=False
        )
        runs["solve_no_mirror"] = lambda: engine.solve(plain)
    for fn in runs.values():
        fn()
    through = {
        label: batch / min(_timed(fn) for _ in range(batch_rounds)) for label, fn in runs.items()
    }
    ort_threads = engine.encoder.session.get_session_options().intra_op_num_threads
    return {
        **_network_ceiling(engine, two, starts, tpos, batch_rounds),
        "latency": rows,
        "composed": extra,
        "tolerance_m": tolerance,
        "iteration_cap": engine.fabrik_max_iterations,
        "batch": batch,
        "batch_poses_per_s": through,
        "threads": ort_threads,
        "passes": engine.serving.passes,
        "views": 2 if engine.serving.solve_mirror else 1,
    }


def _network_ceiling(
    engine: Engine, edits: Edits, starts: np.ndarray, targets: np.ndarray, rounds: int
) -> Json:
    """The networks alone on the batch: the fused graph of ``edits``' target set run once
    on every row (``network_rows_per_s``), so that a solve of ``engine.serving.passes``
    passes cannot exceed ``network_rows_per_s / passes`` poses/s on this thread whatever
    the geometry around it costs. Empty when no single fused graph covers the set."""
    from core.skeleton import JOINT_NAMES

    key = "+".join(sorted(JOINT_NAMES[j] for j in edits.joints[0]))
    net = engine.fused.get(key)
    if net is None:
        return {}
    x = np.ascontiguousarray(starts.reshape(len(starts), -1), dtype=np.float32)
    t = np.ascontiguousarray(targets.reshape(len(targets), -1), dtype=np.float32)
    net(x, t)
    rate = len(x) / min(_timed(lambda: net(x, t)) for _ in range(rounds))
    return {"network_set": key, "network_rows_per_s": rate}


def _issue14_set(
    engine: Engine, k: int, name: str, edits: Edits, calls: int, warmup: int, tolerance: float
) -> Json:
    """One target count of :func:`issue14`: the four timings interleaved per call."""
    from bench.ab import ankles_pinned
    from core import compiled_fabrik, kinematics
    from core.skeleton import bone_lengths

    cap = engine.fabrik_max_iterations
    neural = problems(edits, "neural_bone")
    neural1 = [dataclasses.replace(p, passes=1) for p in neural]
    no_mirror = [dataclasses.replace(p, mirror=False) for p in neural]
    fab = [dataclasses.replace(p, tolerance=tolerance) for p in problems(edits, "fabrik")]
    n = len(edits)
    start = np.ascontiguousarray(edits.start, dtype=np.float64)
    lens = np.ascontiguousarray(bone_lengths(start), dtype=np.float64)
    idx = edits.joints[0]
    goals = [np.ascontiguousarray(t[None], dtype=np.float64) for t in edits.targets]
    plans = compiled_fabrik.packed_plans(idx, np.ones(len(idx)))
    pinned = np.zeros(len(idx), dtype=bool)
    tol = np.full(1, tolerance)

    def kernel(i: int) -> object:
        return compiled_fabrik.solve_batch(
            False, start[i : i + 1], lens[i : i + 1], goals[i], tol, cap, plans.local_ints,
            plans.local_floats, plans.has_local, plans.ints, plans.floats, pinned, False, False,
        )  # fmt: skip

    def numpy_fabrik(i: int) -> object:
        return kinematics.fabrik(
            start[i], lens[i], idx, edits.targets[i], tolerance=tolerance, max_iterations=cap
        )

    runs: dict[str, Callable[[int], object]] = {
        "neural": lambda i: engine.solve([neural[i]]),
        "neural_passes1": lambda i: engine.solve([neural1[i]]),
        "fabrik_compiled": lambda i: engine.solve([fab[i]]),
        "fabrik_kernel": kernel,
        "fabrik_numpy": numpy_fabrik,
    }
    if engine.serving.solve_mirror:  # the default solves the mirror image too
        runs["neural_no_mirror"] = lambda i: engine.solve([no_mirror[i]])
    if engine.serving.solve_mirror and engine.mirror_graphs:  # the mirror graphs' share
        numpy_way = copy.copy(engine)
        numpy_way.mirror_graphs = {}
        runs["neural_numpy_mirror"] = lambda i: numpy_way.solve([neural[i]])
    feet = ankles_pinned(neural)  # feet pinned where they stand: the editor's pins
    if feet:
        runs["neural_pinned"] = lambda i: engine.solve([feet[i]])
    if engine.turn_search.searches("neural", len(idx), False):  # the default searches
        plain = copy.copy(engine)
        plain.turn_search = NO_SEARCH
        runs["neural_no_turn"] = lambda i: plain.solve([neural[i]])
    for i in range(warmup):
        for fn in runs.values():
            fn(i % n)
    times: dict[str, list[int]] = {m: [] for m in runs}
    for i in range(calls):
        for m, fn in runs.items():
            if m == "fabrik_numpy" and i % 8:
                continue  # the slow reference: every 8th call
            t0 = time.perf_counter_ns()
            fn(i % n)
            times[m].append(time.perf_counter_ns() - t0)
    return {"targets": k, "set": name, **{m: _stats(ns) for m, ns in times.items()}}


def _timed(fn: Callable[[], object]) -> float:
    t0 = time.perf_counter_ns()
    fn()
    return (time.perf_counter_ns() - t0) / 1e9
