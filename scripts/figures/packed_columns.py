"""What a columnar batch's JSON costs against packed columns (docs/limits.md, "The
columnar batch"): a 1,024-edit 2-target batch of TEST edits (as ``make bench`` builds its
HTTP batch), its bytes, and in process the least of ``--rounds`` times of reading it
(orjson and ``service.columnar.parse``), of solving it and of writing its answer, with
``poses`` and ``targets.positions`` as JSON numbers and packed (base64 float64).

    python scripts/figures/packed_columns.py [--rounds 7]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import orjson

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from bench.edits import edits_from_pairs, joint_idx, sample_pairs, test_split  # noqa: E402
from bench.heldout import engine_for  # noqa: E402
from bench.http_load import columnar_body  # noqa: E402
from service import columnar  # noqa: E402
from trainer.data.dataset import load_dataset  # noqa: E402


def least(rounds: int, fn: Callable[[], Any]) -> tuple[float, Any]:
    """The least time of ``rounds`` calls of ``fn`` (ms), and its last answer."""
    best, out = float("inf"), None
    for _ in range(rounds):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, default=ROOT / "models")
    ap.add_argument("--dataset", type=Path, default=ROOT / "data/poses.npz")
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    engine = engine_for(args.models, None, threads=1)
    test = test_split(load_dataset(args.dataset))
    a, b = sample_pairs(test, 1024, np.random.default_rng(100))  # (make bench's seed 0 + 100)
    edits = edits_from_pairs(test, a, b, [joint_idx(("left_wrist", "right_wrist"))] * len(a))
    for packed in (False, True):
        body = orjson.dumps(columnar_body(edits, range(1024), packed=packed))
        read, cols = least(args.rounds, lambda b=body: columnar.parse(orjson.loads(b), 8192, False))
        solve, part = least(args.rounds, lambda c=cols: columnar.solve(engine, c, slice(0, 1024)))
        write, out = least(
            args.rounds, lambda c=cols, p=part: columnar.answer(c, p, engine.version)
        )
        name = "packed columns" if packed else "JSON numbers"
        print(f"{name}: {len(body):,} bytes sent, {len(out):,} answered; read {read:.2f} ms, "
              f"solve {solve:.2f} ms, answer {write:.2f} ms")  # fmt: skip
    print(json.dumps({"rounds": args.rounds, "models": str(args.models)}))


if __name__ == "__main__":
    main()
