"""Time of the turn search on a batch and on lone edits (docs/service.md, "The turn
search": a batch of searching edits solves their unturned starts first).

``--edits`` in-studio 5-end-effector edits (TEST-split pairs 0.2-1 s apart,
``bench.edits.sample_pairs`` seeded ``--seed``: B1's first pairs; soft, bone lengths kept:
the models' passes and mirror image) solved in one ``Engine.solve`` call, ``--rounds``
times, with the models' turn search, with the search and ``serving.turn_gate`` 0 (every
edit searches, as before the gate), and with ``options.turn_search: false``; then the
first ``--lone`` of them one by one (p50 of one call each, after ``--warm`` warm-up
calls). Times are wall clock and CPU time of this thread (``time.thread_time``); the
machine is shared, so compare rows of one run. Also how many answers turned (their
``solvers`` hold ``turn <deg>`` or ``fit <deg>``): the others ended at their unturned
start, whether or not their targets moved enough to search.

The one-batch search this staged search replaced (every candidate of every edit in one
batch) is gone from the code and is not timed here.

    python scripts/figures/turn_batching.py [--edits 1024] [--rounds 2] [--lone 200]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.edits import (
    END_EFFECTORS,
    edits_from_pairs,
    joint_idx,
    problems,
    sample_pairs,
    test_split,
)
from service.engine import Engine
from service.problems import SolveProblem
from trainer.data.dataset import load_dataset


def timed(engine: Engine, probs: list[SolveProblem]) -> tuple[float, float]:
    """Wall and thread CPU seconds of one ``Engine.solve`` call on ``probs``."""
    w, c = time.perf_counter(), time.thread_time()
    engine.solve(probs)
    return time.perf_counter() - w, time.thread_time() - c


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, default=Path("models"))
    ap.add_argument("--dataset", type=Path, default=Path("data/poses.npz"))
    ap.add_argument("--edits", type=int, default=1024)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rounds", type=int, default=2, help="batch calls per column")
    ap.add_argument("--lone", type=int, default=200, help="edits timed one by one")
    ap.add_argument("--warm", type=int, default=10)
    args = ap.parse_args()

    engine = Engine(args.models, threads=1)
    ungated = Engine(args.models, threads=1, serving={"turn_gate": 0.0})
    test = test_split(load_dataset(args.dataset))
    a, b = sample_pairs(test, args.edits, np.random.default_rng(args.seed))
    edits = edits_from_pairs(test, a, b, [joint_idx(END_EFFECTORS)] * len(a))
    searching = problems(edits, "neural_bone")
    cases = {
        f"turn search, turn_gate {engine.serving.turn_gate:g} m (models')": (engine, searching),
        "turn search, turn_gate 0": (ungated, searching),
        "turn_search: false": (engine, problems(edits, "neural_bone", turn_search=False)),
    }
    print(f"models {engine.version} (turn_yaws {engine.serving.turn_yaws}); {args.edits} "
          f"in-studio 5-end-effector edits, seed {args.seed}")  # fmt: skip
    print(f"| case | turned | one call, {args.edits} edits: wall ms (each round) | CPU ms | "
          f"lone edit p50, wall / CPU ms ({args.lone} edits) |")  # fmt: skip
    print("|---|---|---|---|---|")
    for name, (engine, probs) in cases.items():
        got = engine.solve(probs)
        turned = sum(any(s.startswith(("turn ", "fit ")) for s in r.solvers) for r in got)
        rounds = [timed(engine, probs) for _ in range(args.rounds)]
        for p in probs[: args.warm]:
            engine.solve([p])
        lone = np.array([timed(engine, [p]) for p in probs[: args.lone]])
        wall = " / ".join(f"{w * 1e3:.0f}" for w, _ in rounds)
        cpu = " / ".join(f"{c * 1e3:.0f}" for _, c in rounds)
        p50 = np.median(lone, axis=0) * 1e3
        print(f"| {name} | {turned} | {wall} | {cpu} | {p50[0]:.2f} / {p50[1]:.2f} |")


if __name__ == "__main__":
    main()
