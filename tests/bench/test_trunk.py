"""``python -m bench.trunk``: its edits on real poses, and what it says of them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench import trunk
from service import fabrik_set
from tests.conftest import PosePairs


def test_the_trunk_table_puts_the_engine_beside_itself_without_the_retry(
    models_dir: Path, real_poses: PosePairs
) -> None:
    poses = np.asarray(real_poses.poses[real_poses.starts[:12]], dtype=np.float64)
    kept = fabrik_set._TRUNK
    res = trunk.run(models_dir, poses, seed=11)
    assert fabrik_set._TRUNK is kept  # (put back)
    assert len(res) == len(trunk.SETS) * len(trunk.METHODS)
    for ours, before in res.values():
        assert ours[3] <= 1e-3 and before[3] <= 1e-3  # every pin held, either way
    # the chest over pinned wrists: the retry reaches where the engine without it stalls
    chest = [v for k, v in res.items() if k[:2] == ("spine2", "left_wrist+right_wrist")]
    assert all(ours[0] < 0.01 < before[0] for ours, before in chest), chest
    table = trunk.table(res, len(poses))
    assert table.count("\n") == len(res) + 1 and " → " in table
    still, turned = trunk.reach_bound(poses, seed=11)
    assert 0.0 <= turned <= still < 0.2
