"""``python -m bench.pins``: its edits on real poses, and what it says of them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench import pins
from tests.conftest import PosePairs


def test_pins_hold_across_the_bench_edits(models_dir: Path, real_poses: PosePairs) -> None:
    poses = real_poses.poses[real_poses.starts[:1]]
    res = pins.run(models_dir, poses, seed=0)
    assert set(res) == {*pins.PIN_SETS, pins.RANDOM_PINS}
    rows = [r for per_set in res.values() for r in per_set]
    skipped = sum(bool(set(p) & set(t)) for p in pins.PIN_SETS for t in pins.TARGET_SETS)
    fixed = (len(pins.PIN_SETS) * len(pins.TARGET_SETS) - skipped) * 3 * 4
    assert len(rows) == fixed + pins.RANDOM_SETS * 4
    off = np.asarray([r[0] for r in rows])
    assert off.max() <= 1e-3, np.sort(off)[-5:]  # every pin within its tolerance
    assert all(np.isfinite(r[1]) for r in rows)
