"""A dragged pelvis turned to fit the legs (``service.fabrik_set.tilted``), on real poses:
moved onto its goal, turned about it as one rigid body where that is what brings each
pinned foot within its leg's reach, and refused where no turn does."""

from __future__ import annotations

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX, PARENTS, bone_lengths
from service.fabrik_set import FIT, MAX_TILT, tilted, within_reach
from tests.conftest import PosePairs

PELVIS = JOINT_INDEX["pelvis"]
HIPS = {s: JOINT_INDEX[f"{s}_hip"] for s in ("left", "right")}
ANKLES = {s: JOINT_INDEX[f"{s}_ankle"] for s in ("left", "right")}
IDX = np.array([PELVIS, ANKLES["left"], ANKLES["right"]], dtype=np.int64)
HOLD = np.array([False, True, True])


def _leg(pose: np.ndarray, side: str) -> float:
    """The reach of a leg from its hip to its ankle (its two bones)."""
    lengths, j, out = bone_lengths(pose), ANKLES[side], 0.0
    while j != HIPS[side]:
        out += float(lengths[j - 1])
        j = PARENTS[j]
    return out


def _short_by(pose: np.ndarray, goal: np.ndarray, side: str) -> float:
    """How far the ankle lies beyond the leg's reach once the pelvis is moved to ``goal``."""
    hip = goal + pose[HIPS[side]] - pose[PELVIS]
    return float(np.linalg.norm(hip - pose[ANKLES[side]])) - _leg(pose, side)


def _drag(pose: np.ndarray, side: str, beyond: float) -> np.ndarray:
    """A pelvis goal across, away from ``side``'s ankle, that leaves that leg ``beyond``
    metres short of its ankle once moved there unturned."""
    across = pose[HIPS["left"]] - pose[HIPS["right"]]
    across[1] = 0.0
    away = across / np.linalg.norm(across) * (-1.0 if side == "left" else 1.0)
    lo, hi = 0.0, 0.5
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        short = _short_by(pose, pose[PELVIS] + mid * away, side) < beyond
        lo, hi = (mid, hi) if short else (lo, mid)
    return np.asarray(pose[PELVIS] + hi * away)


@pytest.fixture(scope="module")
def poses(real_poses: PosePairs) -> np.ndarray:
    """Real standing poses: both legs nearly straight (within 20 % of their reach)."""
    out = []
    for pose in real_poses.poses[real_poses.starts]:
        reach = [float(np.linalg.norm(pose[HIPS[s]] - pose[ANKLES[s]])) / _leg(pose, s)
                 for s in ("left", "right")]  # fmt: skip
        if min(reach) > 0.8:
            out.append(pose)
    assert len(out) >= 20
    return np.stack(out[:40]).astype(np.float64)


def _goals(pose: np.ndarray, pelvis: np.ndarray) -> np.ndarray:
    return np.stack([pelvis, pose[ANKLES["left"]], pose[ANKLES["right"]]])


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_pelvis_one_leg_cannot_follow_is_turned_towards_that_leg_as_one_body(
    poses: np.ndarray, side: str
) -> None:
    other = "right" if side == "left" else "left"
    tried = 0
    for pose in poses:
        goal = _drag(pose, side, 0.01)  # 1 cm beyond that leg's reach, moved unturned
        if abs(_short_by(pose, goal, side) - 0.01) > 1e-6 or _short_by(pose, goal, other) > -0.03:
            continue  # not within 50 cm, or the other leg short too (or nearly): not the case
        tried += 1
        out = tilted(pose, bone_lengths(pose), _goals(pose, goal), IDX, HOLD)
        assert out is not None
        np.testing.assert_allclose(out[PELVIS], goal, atol=1e-12)
        # one rigid body: every distance between two joints as in the start
        d0 = np.linalg.norm(pose[:, None] - pose[None], axis=-1)
        np.testing.assert_allclose(np.linalg.norm(out[:, None] - out[None], axis=-1), d0, atol=1e-9)
        for s in ("left", "right"):  # each leg now reaches its ankle, the short one just
            gap = float(np.linalg.norm(out[HIPS[s]] - pose[ANKLES[s]])) - _leg(pose, s)
            assert gap <= -FIT + 1e-6, (s, gap)
        gap = float(np.linalg.norm(out[HIPS[side]] - pose[ANKLES[side]])) - _leg(pose, side)
        assert gap > -FIT - 1e-3  # the least turn: not much past what it takes
        turn = np.degrees(np.arccos(np.clip(
            np.dot(*(u / np.linalg.norm(u) for u in (out[HIPS["left"]] - out[HIPS["right"]],
                                                     pose[HIPS["left"]] - pose[HIPS["right"]]))),
            -1.0, 1.0)))  # fmt: skip
        assert 0.5 < turn < np.degrees(MAX_TILT), turn
    assert tried >= 4, tried


def test_a_pelvis_both_legs_can_follow_is_only_moved(poses: np.ndarray) -> None:
    for pose in poses:
        goal = pose[PELVIS] + np.array([0.0, -0.05, 0.0])  # 5 cm down: both legs bend
        out = tilted(pose, bone_lengths(pose), _goals(pose, goal), IDX, HOLD)
        assert out is not None
        np.testing.assert_allclose(out, pose + (goal - pose[PELVIS]), atol=1e-12)


def test_a_pelvis_no_turn_lets_the_legs_follow_is_refused(poses: np.ndarray) -> None:
    for pose in poses:
        up = pose[PELVIS] + np.array([0.0, 0.2, 0.0])  # 20 cm up: both legs short
        assert tilted(pose, bone_lengths(pose), _goals(pose, up), IDX, HOLD) is None
        far = _drag(pose, "left", 0.3)  # 30 cm beyond: past any turn of the pelvis
        assert tilted(pose, bone_lengths(pose), _goals(pose, far), IDX, HOLD) is None


def test_a_pelvis_beyond_its_legs_reach_stops_at_the_nearest_pelvis_they_reach(
    poses: np.ndarray,
) -> None:
    """``within_reach``: where no turn fits, the start moved (unturned) onto the point
    nearest the goal from which both legs reach their ankles; a goal they reach, onto it."""
    for pose in poses:
        lengths = bone_lengths(pose)
        for goal in (pose[PELVIS] + np.array([0.0, 0.2, 0.0]), _drag(pose, "left", 0.3)):
            out = within_reach(pose[None], lengths[None], _goals(pose, goal)[None], IDX)[0]
            assert out is not None
            np.testing.assert_allclose(out - out[PELVIS], pose - pose[PELVIS], atol=1e-12)
            gaps = [float(np.linalg.norm(out[HIPS[s]] - pose[ANKLES[s]])) - _leg(pose, s)
                    for s in ("left", "right")]  # fmt: skip
            assert max(gaps) <= -FIT + 1e-6, gaps
            # the nearest: 1 mm further towards the goal, a leg falls short
            to = goal - out[PELVIS]
            assert np.linalg.norm(to) > 0.01
            step = out + 0.001 * to / np.linalg.norm(to)
            assert max(float(np.linalg.norm(step[HIPS[s]] - pose[ANKLES[s]])) - _leg(pose, s)
                       for s in ("left", "right")) > -FIT  # fmt: skip
        down = pose[PELVIS] + np.array([0.0, -0.05, 0.0])
        out = within_reach(pose[None], lengths[None], _goals(pose, down)[None], IDX)[0]
        assert out is not None
        np.testing.assert_allclose(out, pose + (down - pose[PELVIS]), atol=1e-9)
