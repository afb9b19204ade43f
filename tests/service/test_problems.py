"""A batch's arrays (:mod:`service.problems`): the starts moved across before the networks
(``_Items.travelled``, compiled as :func:`core.compiled.travel`) as the serving settings
say, checked against the rule written out in numpy on real poses."""

from __future__ import annotations

import numpy as np

from core.skeleton import BONES, JOINT_INDEX, NUM_JOINTS, bone_lengths
from service.problems import PELVIS, _Items
from tests.conftest import PosePairs

FEW = 5  # serving.turn_min_targets of the shipped models: fewer targets may step across


def _chain(lengths: np.ndarray, joint: int) -> float:
    """The summed bones from the pelvis to ``joint``."""
    bone = {child: (i, parent) for i, (child, parent) in enumerate(BONES)}
    total, j = 0.0, joint
    while j != PELVIS:
        i, j = bone[j]
        total += lengths[i]
    return total


def _expected(items: _Items, pelvis: bool, reach: bool) -> np.ndarray:
    """The documented rule, item by item."""
    out = items.poses.copy()
    for b in range(len(out)):
        if items.fab[b] or items.cnt[b] != items.n_t[b]:
            continue  # FABRIK, or pins: the start stays
        mine = list(items.tidx[b, : items.n_t[b]])
        if pelvis and PELVIS in mine:
            q = mine.index(PELVIS)
            out[b] += (items.tpos[b, q] - out[b, PELVIS]) * np.array([1.0, 0.0, 1.0])
        if reach and items.n_t[b] < FEW:
            lengths = bone_lengths(out[b])
            over = [
                (np.hypot(*(items.tpos[b, q] - out[b, PELVIS])[[0, 2]]) - _chain(lengths, j), q)
                for q, j in enumerate(mine)
            ]
            excess, q = max(over)
            if excess > 0:
                across = (items.tpos[b, q] - out[b, PELVIS]) * np.array([1.0, 0.0, 1.0])
                out[b] += across * excess / np.linalg.norm(across)
    return out


def _items(real: PosePairs, names: tuple[str, ...], reach_out: float, pins: int = 0) -> _Items:
    """30 real edits of ``names`` (the last ``pins`` of them pins), each target moved
    ``reach_out`` m across from where the real pose has it; every third one FABRIK."""
    idx = np.asarray([JOINT_INDEX[n] for n in names], dtype=np.int64)
    starts, goals = real.poses[real.starts[:30]], real.poses[real.goals[:30]]
    tpos = goals[:, idx] + np.array([reach_out, 0.0, -0.5 * reach_out])
    n = len(starts)
    return _Items.of_arrays(
        starts, np.tile(idx, (n, 1)), tpos, counts=None, n_targets=len(idx) - pins,
        weights=None, fabrik=np.arange(n) % 3 == 2, preserve_bone_lengths=True, exact=False,
        tolerance=1e-3, floor=0.0, carry=0.5, turn_search=True, mirror=True,
    )  # fmt: skip


def test_starts_travel_onto_a_pelvis_target_and_towards_targets_out_of_reach(
    real_poses: PosePairs,
) -> None:
    """Neural starts without pins move: horizontally onto their pelvis target, then (fewer
    than five targets) by the excess of the target farthest beyond its chain's reach; the
    others stay as they are. Settings off: nothing moves."""
    cases = [
        (("pelvis", "left_wrist"), 0.0, 0),
        (("left_wrist", "right_ankle"), 1.5, 0),
        (("pelvis", "head", "right_wrist"), 1.5, 0),
        (("left_wrist", "head", "right_ankle", "left_ankle", "right_wrist"), 1.5, 0),
        (("left_wrist", "pelvis"), 1.5, 1),  # the pelvis pinned
    ]
    moved = 0
    for names, out, pins in cases:
        items = _items(real_poses, names, out, pins)
        for pelvis, reach in ((True, True), (True, False), (False, True)):
            got = items.travelled(pelvis, reach, FEW).poses
            np.testing.assert_allclose(got, _expected(items, pelvis, reach), rtol=0, atol=1e-12)
            moved += int((got != items.poses).any(axis=(1, 2)).sum())
            assert got.shape == (30, NUM_JOINTS, 3)
        assert items.travelled(False, False, FEW) is items
        fixed = items.fab | (items.cnt != items.n_t)
        assert np.array_equal(items.travelled(True, True, FEW).poses[fixed], items.poses[fixed])
    assert moved >= 80  # the cases do move starts (real edits, targets put out of reach)
