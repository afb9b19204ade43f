"""Where a lone soft edit's time goes, step by step, on this machine:
``python -m bench.profile [--targets 2] [--windows 60] [--calls 200]``.

A lone neural soft edit (the TEST split's B1-style edits, :data:`bench.ab.SETS`; five
targets without the turn search) that its passes answer (no retry, no polish: the common
case) is solved whole, then each step of :meth:`service.engine.Engine._lean_single` alone,
each the best of ``windows`` windows of ``calls`` calls (wall time: a window a burst of
another tenant hits is not the best; each step alone runs with warm caches, so the steps
sum to less than the whole). The whole is also timed with the networks' runs replaced by
no-ops: what is not onnxruntime. Prints a markdown table (µs).

Steps are the engine's own internals (``service.lean.solve_one``'s kernels, the bound
runs): this module follows them, and ``tests/bench/test_profile.py`` runs it.
"""

from __future__ import annotations

import dataclasses
import timeit
from collections.abc import Callable
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from bench.ab import SETS
from bench.edits import edits_from_pairs, joint_idx, problems, sample_pairs, test_split
from core import compiled
from core.skeleton import NUM_JOINTS
from service import lean, networks
from service.engine import Engine
from service.problems import SolveProblem, _Items
from service.retry import last_steps
from service.runtime import Bound, _FewRows
from trainer.data.dataset import load_dataset


def best(fn: Callable[[], object], windows: int, calls: int) -> float:
    """The fastest window's time per call of ``fn``, µs."""
    return min(timeit.repeat(fn, number=calls, repeat=windows)) / calls * 1e6


def common_edit(engine: Engine, dataset: Path, targets: int, seed: int) -> SolveProblem:
    """The first of the seed's edits of ``targets`` targets that its passes answer."""
    test = test_split(load_dataset(dataset))
    a, b = sample_pairs(test, 32, np.random.default_rng(seed + 100))
    ed = edits_from_pairs(test, a, b, [joint_idx(SETS[targets])] * len(a))
    for p in problems(ed, "neural_bone"):
        p = dataclasses.replace(p, turn_search=False)
        if float(engine.solve([p])[0].errors.max()) <= engine.serving.retry_reach:
            return p
    raise ValueError("no edit of these that its passes answer")


def steps(engine: Engine, p: SolveProblem, windows: int, calls: int) -> dict[str, float]:
    """Each step's best time per call (µs), the whole first."""

    def timed(fn: Callable[[], object], n: int = calls) -> float:
        return best(fn, windows, n)

    out = {"whole (Engine.solve)": timed(lambda: engine.solve([p]), max(calls // 2, 1))}
    out["whole, onnxruntime runs as no-ops"] = without_runs(engine, p, windows, calls)
    tidx, w = compiled.as_i64(p.target_idx), compiled.as_f64(p.weights)
    out["solver plan (covering)"] = timed(lambda: lean.covering(engine, tidx, w))
    seq = lean.covering(engine, tidx, w)
    carry, mirror = engine.carry_of(p), engine.mirror_of(p)
    out["options as arrays (_Items.of_problem)"] = timed(
        lambda: _Items.of_problem(p, carry, mirror)
    )
    asked = _Items.of_problem(p, carry, mirror)
    s = engine.serving
    moves = (s.pelvis_travel, s.reach_travel, engine.turn_search.min_targets)
    out["travel (kernel)"] = timed(lambda: asked.travelled(*moves))
    items = asked.travelled(*moves)
    out["collar and pelvis flags"] = timed(
        lambda: (engine.collar_items(items), engine.pelvis_holds(items))
    )
    collar, hold = engine.collar_items(items), engine.pelvis_holds(items)
    passes = engine.passes_of(p)
    assert seq is not None
    out["all passes (solve_lean)"] = timed(lambda: lean.solve_lean(engine, items, passes, seq))
    found = networks.one_run(engine, seq, bool(items.mirror[0]))
    if found is not None:
        few, rows, cols, other, signs = found
        (x_in, t_in), dec, run = few.bound(((rows, 3 * NUM_JOINTS), (rows, cols.shape[0])))
        out[f"onnxruntime: one run of {rows} rows, x{passes}"] = passes * timed(run)
        ws = lean._workspace()
        canon, facing, trans, lengths, scales = ws
        body = engine.body_args
        rest = (items.floors, items.tidx, items.tpos, items.cnt, items.carry, engine.chain_mask,
                s.keep_ease, collar, hold, engine.pairs_of(items.body), s.bend_side, items.soft_ik,
                s.keep_feet)  # fmt: skip
        out["kernel prepare_into"] = timed(
            lambda: compiled.prepare_into(
                items.poses,
                items.floors,
                items.tidx,
                items.tpos,
                items.cnt,
                *body,
                cols,
                other,
                signs,
                x_in,
                t_in,
                *ws,
            )
        )
        out[f"kernel settle_prepare, x{passes - 1}"] = (passes - 1) * timed(
            lambda: compiled.settle_prepare(
                dec,
                scales,
                canon,
                lengths,
                facing,
                trans,
                *rest,
                *body,
                cols,
                other,
                signs,
                x_in,
                t_in,
            )
        )
        into = (np.empty((1, NUM_JOINTS, 3)), np.empty(items.tidx.shape), np.empty(1))
        out["kernel settle_last"] = timed(
            lambda: compiled.settle_last(dec, scales, canon, lengths, facing, trans, *rest, *into)
        )
    ans = lean.lean_answer(engine, items, passes, seq)
    out["retry check and pins (retry.last_steps)"] = timed(lambda: last_steps(engine, items, ans))
    out["the result (SolveResult)"] = timed(lambda: engine._result(p, ans, 0))
    return out


def without_runs(engine: Engine, p: SolveProblem, windows: int, calls: int) -> float:
    """The whole with every bound run a no-op (outputs as the last real run left them)."""
    bound = _FewRows.bound

    def idle(self: _FewRows, shapes: tuple[tuple[int, ...], ...]) -> Bound:
        bufs, out, _ = bound(self, shapes)
        return bufs, out, lambda: None

    _FewRows.bound = idle  # type: ignore[method-assign]
    try:
        return best(lambda: engine.solve([p]), windows, max(calls // 2, 1))
    finally:
        _FewRows.bound = bound  # type: ignore[method-assign]


def main(
    targets: Annotated[int, typer.Option(help="Targets: 1, 2 or 5 (bench.ab.SETS).")] = 2,
    models: Annotated[Path, typer.Option(help="Models folder.")] = Path("models"),
    dataset: Annotated[Path, typer.Option(help="Dataset file.")] = Path("data/poses.npz"),
    windows: Annotated[int, typer.Option(min=1, help="Windows per step (best kept).")] = 60,
    calls: Annotated[int, typer.Option(min=1, help="Calls per window.")] = 200,
    seed: Annotated[int, typer.Option(help="The edits' seed.")] = 0,
) -> None:
    """Time a lone soft edit's steps (see the module)."""
    engine = Engine(models, threads=1)
    p = common_edit(engine, dataset, targets, seed)
    print(f"| {targets} targets, one thread | µs per call |\n|---|---|")
    for name, us in steps(engine, p, windows, calls).items():
        print(f"| {name} | {us:.1f} |")


if __name__ == "__main__":
    typer.run(main)
