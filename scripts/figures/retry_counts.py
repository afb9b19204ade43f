"""How many edits the retry gives one more pass, per passes setting (docs/service.md,
"Passes" and "The retry").

The edits are ``python -m bench.ab``'s: ``--edits`` in-studio TEST-split pairs 0.2-1 s
apart (``bench.edits.sample_pairs`` seeded ``--seed`` + 100, as the probe draws them), each
solved soft with bone lengths kept for 1, 2 and 5 targets (``bench.ab.SETS``). An edit was
retried where its answer differs from the same engine's with ``serving.retry_reach`` 0 (no
retry, no polish after it): the retry is the only step that setting turns off. Of those,
the ones still short after the retry are polished (``serving.retry_polish``): their
``solvers`` end with ``fabrik-polish``, or ``fabrik-fallback`` where exact reach's
fallback from the caller's start answered instead (no other step puts them there for these
target sets).
Nothing in the engine is hooked.

    python scripts/figures/retry_counts.py [--edits 128] [--seed 0] [--passes 1 default]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.ab import SETS
from bench.edits import edits_from_pairs, joint_idx, problems, sample_pairs, test_split
from service.engine import Engine
from trainer.data.dataset import load_dataset

#: The last step of a solver path the retry's polish leaves (``service.retry.polish_short``).
POLISHED = ("fabrik-polish", "fabrik-fallback")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, default=Path("models"))
    ap.add_argument("--dataset", type=Path, default=Path("data/poses.npz"))
    ap.add_argument("--edits", type=int, default=128, help="edits per target set")
    ap.add_argument("--seed", type=int, default=0, help="bench.ab's --seed (edits: seed + 100)")
    ap.add_argument(
        "--passes", nargs="+", default=["1", "default"],
        help="options.passes of every edit ('default': the models' serving.passes)",
    )  # fmt: skip
    args = ap.parse_args()

    engine = Engine(args.models, threads=1)
    no_retry = Engine(args.models, threads=1, serving={"retry_reach": 0.0})
    test = test_split(load_dataset(args.dataset))
    a, b = sample_pairs(test, args.edits, np.random.default_rng(args.seed + 100))
    print(
        f"models {engine.version}: retry_reach {engine.serving.retry_reach} m, retry_polish "
        f"{engine.serving.retry_polish}, serving.passes {engine.serving.passes}; "
        f"{args.edits} edits per set (bench.ab's, seed {args.seed})"
    )
    print("| passes | targets | retried | of them polished |")
    print("|---|---|---|---|")
    for asked in args.passes:
        passes = None if asked == "default" else int(asked)
        label = f"{engine.serving.passes} (default)" if passes is None else str(passes)
        for k, names in SETS.items():
            edits = edits_from_pairs(test, a, b, [joint_idx(names)] * len(a))
            probs = [dataclasses.replace(p, passes=passes) for p in problems(edits, "neural_bone")]
            got, plain = engine.solve(probs), no_retry.solve(probs)
            retried = [not np.array_equal(g.pose, q.pose) for g, q in zip(got, plain, strict=True)]
            polished = [g.solvers[-1] in POLISHED for g in got]
            both = sum(r and p for r, p in zip(retried, polished, strict=True))
            print(f"| {label} | {k} | {sum(retried)} / {len(got)} | {both} |")


if __name__ == "__main__":
    main()
