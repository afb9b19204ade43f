"""Behaviour of the bone-length pass and the FABRIK solvers (core.kinematics)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from core.kinematics import FabrikResult, bone_pass, fabrik, polish
from core.rest import rest_lengths, rest_pose
from core.skeleton import (
    BONES,
    DEPTH,
    JOINT_INDEX,
    MIRROR,
    NUM_JOINTS,
    PARENTS,
    bone_lengths,
    chain_to_root,
)

F64 = npt.NDArray[np.float64]
J = JOINT_INDEX
ROOT = PARENTS.index(-1)
ANKLES = [J["left_ankle"], J["right_ankle"]]
TOL = 1e-3


def max_rel_length_error(positions: npt.ArrayLike, lengths: npt.ArrayLike) -> float:
    got = bone_lengths(np.asarray(positions, dtype=np.float64))
    return float(np.max(np.abs(got / np.asarray(lengths, dtype=np.float64) - 1.0)))


def standing() -> F64:
    """A relaxed standing pose: the rest pose with the arms hanging down."""
    pose = rest_pose()
    for side, sx in (("left", 1.0), ("right", -1.0)):
        shoulder = pose[J[f"{side}_shoulder"]]
        pose[J[f"{side}_elbow"]] = shoulder + np.array([0.05 * sx, -0.265, -0.02])
        pose[J[f"{side}_wrist"]] = pose[J[f"{side}_elbow"]] + np.array([0.02 * sx, -0.24, 0.07])
    return np.asarray(bone_pass(pose, rest_lengths()), dtype=np.float64)


def perturbed(shape: tuple[int, ...], scale: float, seed: int = 0) -> F64:
    rng = np.random.default_rng(seed)
    return standing() + rng.normal(0.0, scale, (*shape, NUM_JOINTS, 3))


def arm_reach(side: str = "left") -> float:
    """Length of the chain from the root to the wrist."""
    lengths = rest_lengths()
    bone_of = {child: b for b, (child, _) in enumerate(BONES)}
    joints = [f"{side}_wrist", *chain_to_root(f"{side}_wrist")]
    return float(sum(lengths[bone_of[J[name]]] for name in joints))


# --------------------------------------------------------------------------------------
# rest pose
# --------------------------------------------------------------------------------------


def test_rest_pose_is_a_plausible_standing_t_pose() -> None:
    pose = rest_pose()
    assert pose.shape == (NUM_JOINTS, 3)
    assert pose.dtype == np.float64
    assert 0.8 < pose[ROOT, 1] < 1.1
    assert pose[:, 1].min() >= 0.0  # nothing below the floor
    assert pose[J["head"], 1] > pose[J["neck"], 1] > pose[ROOT, 1]
    mirrored = pose[list(MIRROR)] * [-1.0, 1.0, 1.0]
    np.testing.assert_allclose(mirrored, pose, atol=1e-12)
    assert np.all(rest_lengths() > 0.05)
    pose[0] = 99.0  # a fresh copy every call
    assert rest_pose()[0, 0] == 0.0


# --------------------------------------------------------------------------------------
# bone_pass
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("shape", [(), (5,), (2, 3)])
def test_bone_pass_restores_lengths(shape: tuple[int, ...], dtype: type) -> None:
    rng = np.random.default_rng(1)
    poses: npt.NDArray[np.floating] = perturbed(shape, 0.05).astype(dtype)
    lengths = rest_lengths() * rng.uniform(0.9, 1.1, (*shape, len(BONES)))
    assert max_rel_length_error(poses, lengths) > 0.05
    out = bone_pass(poses, lengths)
    assert out.shape == (*shape, NUM_JOINTS, 3)
    assert out.dtype == dtype
    assert np.all(np.isfinite(out))
    assert max_rel_length_error(out, lengths) <= 1e-5


def test_bone_pass_broadcasts_shared_lengths_over_wild_poses() -> None:
    rng = np.random.default_rng(2)
    poses = rng.normal(0.0, 1.0, (64, NUM_JOINTS, 3))  # nothing like a human
    out = bone_pass(poses, rest_lengths())
    assert max_rel_length_error(out, np.broadcast_to(rest_lengths(), (64, len(BONES)))) <= 1e-5


def test_bone_pass_keeps_a_pose_with_right_lengths() -> None:
    pose = standing()
    lengths = bone_lengths(pose)
    np.testing.assert_allclose(bone_pass(pose, lengths), pose, rtol=0, atol=1e-9)


def test_bone_pass_never_moves_the_root() -> None:
    poses = perturbed((7,), 0.1)
    out = bone_pass(poses, rest_lengths() * 1.3)
    assert np.array_equal(out[:, ROOT], poses[:, ROOT])


def test_bone_pass_is_the_fabrik_backward_step() -> None:
    """Each joint lies on the ray from its parent's new position to its old position."""
    poses = perturbed((3,), 0.05, seed=3)
    lengths = rest_lengths()
    out = bone_pass(poses, lengths)
    for b, (child, parent) in enumerate(BONES):
        expected_dir = poses[:, child] - out[:, parent]
        expected_dir /= np.linalg.norm(expected_dir, axis=-1, keepdims=True)
        np.testing.assert_allclose(out[:, child], out[:, parent] + lengths[b] * expected_dir)


def test_bone_pass_degenerate_pose_uses_rest_directions() -> None:
    collapsed = np.zeros((NUM_JOINTS, 3))  # every child on top of its parent
    out = bone_pass(collapsed, rest_lengths())
    assert np.all(np.isfinite(out))
    assert max_rel_length_error(out, rest_lengths()) <= 1e-5
    # The first level has no direction at all (everything sits on the root): rest pose.
    first = [j for j in range(NUM_JOINTS) if DEPTH[j] == 1]
    np.testing.assert_allclose(out[first] - out[ROOT], rest_pose()[first] - rest_pose()[ROOT])


def test_bone_pass_degenerate_bone_follows_reference() -> None:
    pose = standing()
    wrist, elbow = J["left_wrist"], J["left_elbow"]
    pose[wrist] = pose[elbow]  # this bone has no direction
    reference = perturbed((), 0.05, seed=4)
    out = bone_pass(pose, rest_lengths(), reference=reference)
    got = out[wrist] - out[elbow]
    want = reference[wrist] - reference[elbow]
    np.testing.assert_allclose(got / np.linalg.norm(got), want / np.linalg.norm(want))
    assert max_rel_length_error(out, rest_lengths()) <= 1e-5


def test_bone_pass_zero_length_bones_stay_finite() -> None:
    lengths = rest_lengths()
    lengths[[0, 5, 12]] = 0.0
    poses = perturbed((4,), 0.05)
    out = bone_pass(poses, lengths)
    assert np.all(np.isfinite(out))
    got = bone_lengths(out)
    np.testing.assert_allclose(got, np.broadcast_to(lengths, got.shape), atol=1e-12)


def test_bone_pass_is_deterministic() -> None:
    poses = perturbed((9,), 0.05, seed=5).astype(np.float32)
    lengths = rest_lengths()
    assert np.array_equal(bone_pass(poses, lengths), bone_pass(poses.copy(), lengths.copy()))


def test_bone_pass_rejects_wrong_shapes() -> None:
    with pytest.raises(ValueError, match="positions"):
        bone_pass(np.zeros((20, 3)), rest_lengths())
    with pytest.raises(ValueError, match="lengths"):
        bone_pass(np.zeros((21, 3)), np.ones(21))


# --------------------------------------------------------------------------------------
# fabrik
# --------------------------------------------------------------------------------------


def check_result(res: FabrikResult, lengths: F64 | None = None) -> None:
    assert np.all(np.isfinite(res.positions))
    assert (
        max_rel_length_error(res.positions, rest_lengths() if lengths is None else lengths) <= 1e-5
    )
    np.testing.assert_array_equal(res.reached, res.errors <= TOL)


@pytest.mark.parametrize(
    "offset", [(0.1, 0.3, 0.3), (0.0, -0.5, 0.3), (0.3, 0.55, 0.0), (-0.4, 0.1, 0.3)]
)
def test_fabrik_drags_a_wrist_with_the_feet_pinned(offset: tuple[float, float, float]) -> None:
    pose = standing()
    idx = [J["left_wrist"], *ANKLES]
    targets = np.stack([pose[J["left_wrist"]] + offset, pose[ANKLES[0]], pose[ANKLES[1]]])
    res = fabrik(pose, rest_lengths(), idx, targets)
    check_result(res)
    assert res.reached.all()
    assert bool(res.converged)
    assert np.linalg.norm(res.positions[J["left_wrist"]] - targets[0]) <= TOL
    assert np.linalg.norm(res.positions[ANKLES] - pose[ANKLES], axis=-1).max() <= TOL


def test_fabrik_reaches_both_wrists_and_the_head() -> None:
    pose = standing()
    idx = [J["left_wrist"], J["right_wrist"], J["head"]]
    targets = pose[idx] + [[0.1, 0.2, 0.2], [-0.1, 0.25, 0.2], [0.0, -0.03, 0.05]]
    res = fabrik(pose, rest_lengths(), idx, targets)
    check_result(res)
    assert res.reached.all()
    assert np.linalg.norm(res.positions[idx] - targets, axis=-1).max() <= TOL


def test_fabrik_unreachable_target_stretches_towards_it() -> None:
    pose = standing()
    wrist = J["left_wrist"]
    root = pose[ROOT]
    reach = arm_reach()
    direction = np.array([0.8, 0.3, 0.52]) / np.linalg.norm([0.8, 0.3, 0.52])
    target = root + 2.0 * reach * direction
    res = fabrik(pose, rest_lengths(), [wrist], target[None])
    check_result(res)
    assert not res.reached[0]
    assert bool(res.converged)
    got = res.positions[wrist]
    assert np.array_equal(res.positions[ROOT], root)  # a lone drag does not float the body
    # On the line root -> target, as far as the chain stretches.
    assert np.linalg.norm(np.cross(got - root, direction)) <= TOL
    assert abs(np.linalg.norm(got - root) - reach) <= TOL
    assert abs(res.errors[0] - reach) <= TOL


def test_fabrik_unreachable_drag_keeps_pinned_feet() -> None:
    pose = standing()
    idx = [J["left_wrist"], *ANKLES]
    targets = np.stack([pose[J["left_wrist"]] + [1.5, 1.5, 0.0], pose[ANKLES[0]], pose[ANKLES[1]]])
    res = fabrik(pose, rest_lengths(), idx, targets)
    check_result(res)
    np.testing.assert_array_equal(res.reached, [False, True, True])
    # The body leans and the pelvis rises towards the target, within leg reach.
    assert res.positions[ROOT, 1] > pose[ROOT, 1] + 0.01
    assert res.errors[0] < np.linalg.norm(targets[0] - pose[J["left_wrist"]]) - 0.3


BOTH_ANKLES = ("left_ankle", "right_ankle")


@pytest.mark.parametrize(
    ("joint", "offset", "pinned"),
    [
        ("left_elbow", (0.05, 0.1, 0.1), BOTH_ANKLES),
        ("right_knee", (0.0, 0.15, 0.2), ("left_ankle",)),
        ("pelvis", (0.0, -0.1, -0.05), BOTH_ANKLES),
        ("spine2", (0.0, -0.05, 0.1), BOTH_ANKLES),
    ],
)
def test_fabrik_targets_intermediate_joints(
    joint: str, offset: tuple[float, float, float], pinned: tuple[str, ...]
) -> None:
    pose = standing()
    pins = [J[n] for n in pinned]
    idx = [J[joint], *pins]
    targets = pose[idx].copy()
    targets[0] += offset
    res = fabrik(pose, rest_lengths(), idx, targets)
    check_result(res)
    assert res.reached.all()
    assert np.linalg.norm(res.positions[J[joint]] - targets[0]) <= TOL
    assert np.linalg.norm(res.positions[pins] - pose[pins], axis=-1).max() <= TOL


def test_fabrik_untargeted_branches_keep_their_shape() -> None:
    pose = standing()
    idx = [J["left_wrist"], *ANKLES]
    targets = np.stack([pose[J["left_wrist"]] + [0.0, -0.5, 0.3], pose[ANKLES[0]], pose[ANKLES[1]]])
    res = fabrik(pose, rest_lengths(), idx, targets)
    out = res.positions
    # The untargeted right arm moves as a rigid body with the chest.
    arm = [J[n] for n in ("right_collar", "right_shoulder", "right_elbow", "right_wrist")]
    before = np.linalg.norm(pose[arm][:, None] - pose[arm][None], axis=-1)
    after = np.linalg.norm(out[arm][:, None] - out[arm][None], axis=-1)
    np.testing.assert_allclose(after, before, atol=1e-9)
    assert np.linalg.norm(out[arm] - pose[arm], axis=-1).max() > 0.05  # it did move


def test_fabrik_is_batched_like_single_solves() -> None:
    poses = bone_pass(perturbed((3,), 0.02, seed=6), rest_lengths())
    idx = [J["right_wrist"], J["left_foot"]]
    offsets = np.array([[[0.1, 0.1, 0.1], [0.0, 0.0, 0.0]], [[0.0, 0.4, 0.2], [0.05, 0.1, 0.0]]])
    targets = poses[:, idx][:, None] + offsets[None]  # [3, 2, 2, 3]
    res = fabrik(poses[:, None], rest_lengths(), idx, targets)
    assert res.positions.shape == (3, 2, NUM_JOINTS, 3)
    assert res.errors.shape == res.reached.shape == (3, 2, 2)
    assert res.converged.shape == (3, 2)
    for i in range(3):
        for k in range(2):
            one = fabrik(poses[i], rest_lengths(), idx, targets[i, k])
            np.testing.assert_allclose(res.positions[i, k], one.positions, atol=1e-9)
            np.testing.assert_allclose(res.errors[i, k], one.errors, atol=1e-9)


def test_fabrik_is_deterministic_and_accepts_float32() -> None:
    pose = perturbed((), 0.03, seed=7).astype(np.float32)
    idx = [J["head"], J["left_wrist"]]
    targets = pose[idx] + np.float32(0.1)
    a = fabrik(pose, rest_lengths(), idx, targets)
    b = fabrik(pose.copy(), rest_lengths(), idx, targets.copy())
    assert a.positions.dtype == np.float32
    assert np.array_equal(a.positions, b.positions)
    assert np.array_equal(a.errors, b.errors)
    assert a.iterations == b.iterations
    check_result(a)


def test_fabrik_survives_a_collapsed_start() -> None:
    collapsed = np.zeros((NUM_JOINTS, 3))
    res = fabrik(collapsed, rest_lengths(), [J["left_wrist"], J["head"]], np.zeros((2, 3)))
    check_result(res)
    assert np.all(np.isfinite(res.errors))


def test_fabrik_without_targets_returns_the_length_fixed_pose() -> None:
    pose = perturbed((), 0.03)
    res = fabrik(pose, rest_lengths(), [], np.zeros((0, 3)))
    np.testing.assert_array_equal(res.positions, bone_pass(pose, rest_lengths()))
    assert res.iterations == 0
    assert res.errors.shape == (0,)


def test_fabrik_rejects_bad_targets() -> None:
    pose = standing()
    with pytest.raises(ValueError, match="indices"):
        fabrik(pose, rest_lengths(), [NUM_JOINTS], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="target_pos"):
        fabrik(pose, rest_lengths(), [1, 2], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="weights"):
        fabrik(pose, rest_lengths(), [1], np.zeros((1, 3)), weights=[0.0])


def test_fabrik_weights_decide_conflicts() -> None:
    """Two targets on one joint cannot both be met: the heavier one wins more."""
    pose = standing()
    wrist = J["left_wrist"]
    targets = np.stack([pose[wrist] + [0.1, 0.0, 0.0], pose[wrist] - [0.1, 0.0, 0.0]])
    res = fabrik(pose, rest_lengths(), [wrist, wrist], targets, weights=[3.0, 1.0])
    check_result(res)
    assert res.errors[0] < res.errors[1]


# --------------------------------------------------------------------------------------
# polish
# --------------------------------------------------------------------------------------


def network_like_answer(seed: int = 8) -> F64:
    """A plausible pose with exact lengths (what the model would return, bone-passed)."""
    return np.asarray(bone_pass(perturbed((), 0.02, seed=seed), rest_lengths()), dtype=np.float64)


def test_polish_fixes_a_small_miss_by_moving_only_the_limb() -> None:
    start = network_like_answer()
    wrist = J["left_wrist"]
    target = start[[wrist]] + [[0.02, -0.03, 0.01]]
    res = polish(start, rest_lengths(), [wrist], target)
    check_result(res)
    assert res.reached.all()
    moved = np.linalg.norm(res.positions - start, axis=-1)
    arm = {J[n] for n in ("left_collar", "left_shoulder", "left_elbow", "left_wrist")}
    others = [j for j in range(NUM_JOINTS) if j not in arm]
    assert moved[others].max() <= 1e-12  # trunk, head, other limbs untouched

    from_rest = fabrik(rest_pose(), rest_lengths(), [wrist], target)
    assert from_rest.reached.all()
    moved_from_rest = np.linalg.norm(from_rest.positions - start, axis=-1)
    untargeted = [j for j in range(NUM_JOINTS) if j != wrist]
    assert moved[untargeted].sum() < 0.1 * moved_from_rest[untargeted].sum()


def test_polish_moves_the_trunk_only_when_the_limb_cannot_reach() -> None:
    start = network_like_answer(seed=9)
    idx = [J["left_wrist"], *ANKLES]
    targets = start[idx].copy()
    targets[0] += [0.5, 0.45, 0.3]  # too far for the arm alone
    res = polish(start, rest_lengths(), idx, targets)
    check_result(res)
    assert res.reached.all()
    assert np.linalg.norm(res.positions[J["spine2"]] - start[J["spine2"]]) > 1e-3
    right_leg = [J[n] for n in ("right_hip", "right_knee", "right_ankle", "right_foot")]
    leg_before = np.linalg.norm(start[right_leg][:, None] - start[right_leg][None], axis=-1)
    leg_after = np.linalg.norm(
        res.positions[right_leg][:, None] - res.positions[right_leg][None], axis=-1
    )
    assert np.abs(leg_after - leg_before).max() < 0.02  # pinned legs barely reshape


def test_polish_leaves_a_pose_that_already_reaches_alone() -> None:
    start = network_like_answer()
    idx = [J["right_wrist"], J["head"]]
    targets = start[idx] + [[0.0, 0.0, 0.0005], [0.0004, 0.0, 0.0]]
    res = polish(start, rest_lengths(), idx, targets)
    assert res.iterations == 0
    assert res.reached.all()
    np.testing.assert_allclose(res.positions, start, rtol=0, atol=1e-12)


def test_polish_unreachable_target_is_reported() -> None:
    start = network_like_answer()
    wrist = J["right_wrist"]
    target = start[ROOT] + [-3.0 * arm_reach("right"), 0.0, 0.0]
    res = polish(start, rest_lengths(), [wrist], target[None])
    check_result(res)
    assert not res.reached[0]
    assert bool(res.converged)
    assert res.errors[0] < 3.0 * arm_reach("right")


def test_polish_fixes_lengths_of_the_start_pose_too() -> None:
    start = perturbed((4,), 0.02, seed=10)  # lengths off by a couple of cm
    idx = [J["left_wrist"], J["right_ankle"]]
    res = polish(start, rest_lengths(), idx, start[:, idx] + [0.0, 0.02, 0.0])
    assert res.positions.shape == (4, NUM_JOINTS, 3)
    assert max_rel_length_error(res.positions, np.broadcast_to(rest_lengths(), (4, 20))) <= 1e-5
    assert res.reached.all()


def test_depth_is_consistent_with_parents() -> None:
    """The solvers rely on parents preceding children (guards the skeleton contract)."""
    for child, parent in enumerate(PARENTS):
        if parent >= 0:
            assert parent < child
            assert DEPTH[child] == DEPTH[parent] + 1
