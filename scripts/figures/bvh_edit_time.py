"""CPU time of a whole BVH edit of ``docs/examples/bvh_solve.json`` (docs/characters.md, "A
character item costs by its size": the exact reach of that file, and the aim pass).

``bench.ab.bvh_edits``: ``POST /v1/bvh/solve`` minus HTTP (read the file, map its joints,
solve, retarget, write the file back) in CPU time of this thread, p50 of ``--calls``
calls after three to warm, as given (``exact``: 22 joints, two pins) and in soft reach
without its pins (``soft``); ``--rounds`` rounds, each printed (the machine is shared:
the least disturbed round is the best). The same rows as ``python -m bench.ab``'s
``bvh exact`` / ``bvh soft``, which compares two revisions.

    python scripts/figures/bvh_edit_time.py [--calls 20] [--rounds 3]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.ab import bvh_edits
from service.engine import Engine


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, default=Path("models"))
    ap.add_argument("--calls", type=int, default=20, help="timed calls per round")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()

    engine = Engine(args.models, threads=1)
    rounds = [bvh_edits(engine, args.calls) for _ in range(args.rounds)]
    print(f"models {engine.version}; docs/examples/bvh_solve.json, CPU p50 of {args.calls} "
          f"calls per round (ms)")  # fmt: skip
    for case in rounds[0]:
        each = [r[case] / 1e3 for r in rounds]
        print(f"{case}: {' / '.join(f'{x:.2f}' for x in each)} (best {min(each):.2f})")


if __name__ == "__main__":
    main()
