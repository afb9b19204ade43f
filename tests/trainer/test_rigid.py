"""trainer.rigid: the service's bone pass in torch, so solvers train on what is served."""

from __future__ import annotations

import numpy as np
import torch

from core.carry import carry_below
from core.ends import active, keep_ends
from core.kinematics import bone_pass
from core.skeleton import JOINT_INDEX, NUM_JOINTS, bone_lengths
from tests.conftest import PosePairs
from trainer.rigid import bone_lengths_t, bone_pass_t, carry_t, ends_t


def test_bone_pass_equals_the_service_one_on_real_poses(real_poses: PosePairs) -> None:
    """Real poses with their bones stretched and bent by noise, given back the start
    pose's lengths: the torch pass lands where the service's numpy pass does."""
    rng = np.random.default_rng(3)
    start = real_poses.poses[real_poses.starts]
    noisy = real_poses.poses[real_poses.goals] + rng.normal(0.0, 0.03, start.shape)
    lengths = bone_lengths(start)
    want = bone_pass(noisy, lengths)
    got = bone_pass_t(
        torch.from_numpy(noisy.reshape(len(noisy), -1)), torch.from_numpy(lengths)
    ).numpy()
    assert np.abs(got.reshape(want.shape) - want).max() < 1e-6  # the eps of the norm
    assert np.allclose(bone_lengths(got.reshape(want.shape)), lengths, atol=1e-6)
    assert np.abs(noisy - want).max() > 0.01  # the noise really was corrected
    np.testing.assert_allclose(
        bone_lengths_t(torch.from_numpy(start.reshape(len(start), -1))).numpy(), lengths
    )


def test_gradient_is_finite_where_a_child_sits_on_its_parent(real_poses: PosePairs) -> None:
    pose = torch.tensor(real_poses.poses[:4].reshape(4, -1), requires_grad=True)
    collapsed = pose.clone()
    flat = collapsed.reshape(4, NUM_JOINTS, 3)
    flat = torch.cat([flat[:, :1], flat[:, :1], flat[:, 2:]], dim=1)  # joint 1 on the root
    lengths = torch.from_numpy(bone_lengths(real_poses.poses[:4]))
    out = bone_pass_t(flat.reshape(4, -1), lengths)
    (grad,) = torch.autograd.grad(out.sum(), pose)
    assert torch.isfinite(grad).all()
    assert torch.isfinite(out).all()


def test_carry_equals_the_service_one_on_real_poses(real_poses: PosePairs) -> None:
    """Answers of three solvers (elbow, knee, both wrists) on real pairs, carried below
    their targets: the torch carry lands where the service's numpy one does, with a
    finite gradient."""
    start = real_poses.poses[real_poses.starts]
    lengths = bone_lengths(start)
    answer = bone_pass(real_poses.poses[real_poses.goals], lengths, reference=start)
    sets = [[JOINT_INDEX["left_elbow"]], [JOINT_INDEX["right_knee"]],
            [JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]]]  # fmt: skip
    flat = torch.tensor(np.stack([answer.reshape(len(start), -1)] * 3), requires_grad=True)
    got = carry_t(
        flat, torch.from_numpy(start.reshape(len(start), -1)), torch.from_numpy(lengths),
        sets, 0.5,
    )  # fmt: skip
    for s, targets in enumerate(sets):
        want = carry_below(answer, start, lengths, targets, 0.5)
        assert np.abs(got[s].detach().numpy().reshape(want.shape) - want).max() < 1e-6
    assert torch.equal(got[2], flat[2])  # nothing hangs below the wrists
    (grad,) = torch.autograd.grad(got.sum(), flat)
    assert torch.isfinite(grad).all()


def test_ends_equal_the_service_ones_on_real_poses(real_poses: PosePairs) -> None:
    """Stand-in network answers (real goals with other limb lengths) after the bone pass to
    the starts' lengths, their targeted limb ends kept (left wrist; both ankles; the left
    elbow, which keeps nothing with the limb ends alone, and its shoulder and elbow with the
    elbows too): the torch step lands where the service's numpy one does, with a finite
    gradient."""
    start = real_poses.poses[real_poses.starts]
    lengths = bone_lengths(start)
    scale = np.random.default_rng(5).uniform(0.8, 1.25, lengths.shape)
    goal = real_poses.poses[real_poses.goals]
    network = bone_pass(goal, lengths * scale, reference=goal)
    answer = bone_pass(network, lengths, reference=start)
    sets = [[JOINT_INDEX["left_wrist"]], [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]],
            [JOINT_INDEX["left_elbow"]]]  # fmt: skip
    flat = torch.tensor(np.stack([answer.reshape(len(start), -1)] * 3), requires_grad=True)
    net = torch.tensor(np.stack([network.reshape(len(start), -1)] * 3), requires_grad=True)
    got = ends_t(flat, net, sets)
    for s, targets in enumerate(sets):
        want = keep_ends(answer, network, targets)
        assert np.abs(got[s].detach().numpy().reshape(want.shape) - want).max() < 1e-6
    assert not torch.equal(got[0], flat[0]) and torch.equal(got[2], flat[2])
    elbows = active(ends=True, elbows=True)
    with_elbows = ends_t(flat, net, sets, elbows)
    assert torch.equal(with_elbows[:2], got[:2]) and not torch.equal(with_elbows[2], flat[2])
    want = keep_ends(answer, network, sets[2], elbows)
    assert np.abs(with_elbows[2].detach().numpy().reshape(want.shape) - want).max() < 1e-6
    got = torch.cat([got[:2], with_elbows[2:]])
    (g_answer, g_net) = torch.autograd.grad(got.sum(), (flat, net))
    assert torch.isfinite(g_answer).all() and torch.isfinite(g_net).all()
    assert g_net[0].abs().sum() > 0 and g_net[2].abs().sum() > 0  # kept: follows the network
