"""trainer.rigid: the service's bone pass in torch, so solvers train on what is served."""

from __future__ import annotations

import numpy as np
import torch

from core.kinematics import bone_pass
from core.skeleton import NUM_JOINTS, bone_lengths
from tests.conftest import PosePairs
from trainer.rigid import bone_lengths_t, bone_pass_t


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
