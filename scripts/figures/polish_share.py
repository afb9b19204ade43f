"""How often the polish of what the retry leaves short runs (docs/service.md, "The polish
of what the retry leaves short": the share of real edits a batch's price leaves it out
for).

The edits are B1's (``make bench``'s accuracy part, :func:`bench.accuracy.evaluate_accuracy`):
``--edits`` in-studio TEST-split pairs 0.2-1 s apart (``bench.edits.sample_pairs`` seeded
``--seed``), the same pairs for every target set, each solved soft with bone lengths kept
(``bench.edits.problems``, method ``neural_bone``: the models' passes, mirror image and
turn search). An edit was polished where its ``solvers`` end with ``fabrik-polish``, or
``fabrik-fallback`` where exact reach's fallback from the caller's start answered instead
(no other step puts them there for these target sets, all of whose joints have a solver). Each
``--retry`` value is ``serving.retry_reach`` (m) for one column: the shipped models' (5
mm) and the 2 cm of the models before mx1-3ca9545e56de. Nothing in the engine is hooked.

    python scripts/figures/polish_share.py [--edits 1000] [--seed 0] [--retry 0.005 0.02]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.edits import (
    END_EFFECTORS,
    FIVE,
    edits_from_pairs,
    joint_idx,
    problems,
    sample_pairs,
    test_split,
)
from service.engine import Engine
from trainer.data.dataset import load_dataset

#: The last step of a solver path the retry's polish leaves (``service.retry.polish_short``).
POLISHED = ("fabrik-polish", "fabrik-fallback")

SETS: dict[str, tuple[str, ...]] = {
    "left_wrist": ("left_wrist",),
    "left_elbow": ("left_elbow",),
    "left_wrist+right_wrist": ("left_wrist", "right_wrist"),
    FIVE: END_EFFECTORS,
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, default=Path("models"))
    ap.add_argument("--dataset", type=Path, default=Path("data/poses.npz"))
    ap.add_argument("--edits", type=int, default=1000, help="edits per target set")
    ap.add_argument("--seed", type=int, default=0, help="B1's seed")
    ap.add_argument("--retry", type=float, nargs="+", default=[0.005, 0.02],
                    help="serving.retry_reach (m) of each column")  # fmt: skip
    args = ap.parse_args()

    engines = [Engine(args.models, threads=1, serving={"retry_reach": r}) for r in args.retry]
    test = test_split(load_dataset(args.dataset))
    a, b = sample_pairs(test, args.edits, np.random.default_rng(args.seed))
    e0 = engines[0]
    print(f"models {e0.version} (retry_polish {e0.serving.retry_polish}, passes "
          f"{e0.serving.passes}); {args.edits} B1 edits per set, seed {args.seed}")  # fmt: skip
    cols = " | ".join(f"retry_reach {r * 1000:g} mm" for r in args.retry)
    print(f"| set | {cols} |")
    print("|---|" + "---|" * len(args.retry))
    for name, joints in SETS.items():
        edits = edits_from_pairs(test, a, b, [joint_idx(joints)] * len(a))
        probs = problems(edits, "neural_bone")
        shares = []
        for engine in engines:
            polished = sum(r.solvers[-1] in POLISHED for r in engine.solve(probs))
            shares.append(f"{polished} ({100.0 * polished / len(probs):.1f} %)")
        print(f"| {name} | {' | '.join(shares)} |")


if __name__ == "__main__":
    main()
