"""The ``synthetic_poses`` fixture (tests/conftest.py) and the ``mocap`` marker hook."""

from __future__ import annotations

import numpy as np
import pytest

from core.rest import rest_lengths, rest_pose
from core.skeleton import JOINT_INDEX, NUM_JOINTS, bone_lengths
from tests.conftest import (
    MOCAP_FIXTURES,
    SYNTH_PAIRS,
    PosePairs,
    make_synthetic_poses,
    pose_from_rotations,
)

J = JOINT_INDEX


def test_shape_like_real_poses(synthetic_poses: PosePairs) -> None:
    poses = synthetic_poses.poses
    assert poses.shape == (2 * SYNTH_PAIRS, NUM_JOINTS, 3) and poses.dtype == np.float64
    assert np.all(np.isfinite(poses))
    starts, goals = synthetic_poses.starts, synthetic_poses.goals
    assert len(starts) == len(goals) == SYNTH_PAIRS
    assert not set(starts.tolist()) & set(goals.tolist())
    pose = synthetic_poses.pose_dict(int(starts[0]))
    assert len(pose) == NUM_JOINTS and all(len(v) == 3 for v in pose.values())


def test_bone_lengths_are_the_rest_lengths(synthetic_poses: PosePairs) -> None:
    got = bone_lengths(synthetic_poses.poses)
    assert np.abs(got - rest_lengths()).max() < 1e-12


def test_deterministic(synthetic_poses: PosePairs) -> None:
    again = make_synthetic_poses()
    assert np.array_equal(again.poses, synthetic_poses.poses)
    assert np.array_equal(again.starts, synthetic_poses.starts)
    assert np.array_equal(again.goals, synthetic_poses.goals)
    other = make_synthetic_poses(seed=1)
    assert not np.allclose(other.poses, synthetic_poses.poses)


def test_upright(synthetic_poses: PosePairs) -> None:
    p = synthetic_poses.poses
    spine = p[:, J["neck"]] - p[:, J["pelvis"]]
    tilt = np.degrees(np.arccos(spine[:, 1] / np.linalg.norm(spine, axis=-1)))
    assert tilt.max() < 45.0
    assert np.all(p[:, J["head"], 1] > p[:, J["neck"], 1])
    assert np.all(p[:, J["neck"], 1] > p[:, J["pelvis"], 1] + 0.4)
    for side in ("left", "right"):
        assert np.all(p[:, J[f"{side}_knee"], 1] < p[:, J["pelvis"], 1])
        assert np.all(p[:, J[f"{side}_ankle"], 1] < p[:, J["pelvis"], 1] - 0.4)
    # near the floor: the pelvis within a few centimetres of the rest height
    assert np.abs(p[:, J["pelvis"], 1] - rest_pose()[J["pelvis"], 1]).max() <= 0.025


def test_random_yaw_and_root(synthetic_poses: PosePairs) -> None:
    p = synthetic_poses.poses[synthetic_poses.starts]
    hips = p[:, J["left_hip"]] - p[:, J["right_hip"]]
    facing = np.arctan2(-hips[:, 0], hips[:, 2])  # left is +X when facing +Z
    assert np.ptp(facing) > np.pi  # all round, not one heading
    assert np.ptp(p[:, J["pelvis"], 0]) > 0.5 and np.ptp(p[:, J["pelvis"], 2]) > 0.5


def test_goals_are_moderate_changes_of_their_starts(synthetic_poses: PosePairs) -> None:
    s = synthetic_poses.poses[synthetic_poses.starts]
    g = synthetic_poses.poses[synthetic_poses.goals]
    assert np.array_equal(s[:, J["pelvis"]], g[:, J["pelvis"]])  # same root and yaw
    moved = np.linalg.norm(g - s, axis=-1).max(axis=-1)
    assert moved.min() > 0.01 and moved.max() < 1.0


def test_identity_rotations_give_the_rest_pose() -> None:
    local = np.broadcast_to(np.eye(3), (2, NUM_JOINTS, 3, 3))
    yaw = np.array([0.0, np.pi / 2])
    root = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, -2.0]])
    got = pose_from_rotations(local, yaw, root)
    rest = rest_pose()
    assert np.allclose(got[0], rest, atol=1e-12)
    quarter = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], dtype=np.float64)  # +90 deg about +Y
    pelvis = rest[J["pelvis"]]
    want = (rest - pelvis) @ quarter.T + pelvis + root[1]
    assert np.allclose(got[1], want, atol=1e-12)


def test_mocap_marker_follows_the_fixtures(request: pytest.FixtureRequest) -> None:
    """Every collected test that needs a mocap fixture carries ``mocap``; others do not."""
    items = request.session.items
    assert request.node.get_closest_marker("mocap") is None
    for item in items:
        needs = bool(MOCAP_FIXTURES & set(getattr(item, "fixturenames", ())))
        assert (item.get_closest_marker("mocap") is not None) == needs, item.nodeid
