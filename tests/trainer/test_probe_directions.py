"""The bone-direction probe's representation (real mocap): a pose read as pelvis and unit
bone directions comes back whole, on any body's lengths."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from core.bodies import random_bodies, rebuild
from core.skeleton import bone_lengths
from trainer.data.dataset import load_dataset
from trainer.probe_directions import from_directions, to_directions


def test_directions_and_lengths_give_the_pose_back(small_dataset: Path) -> None:
    world = load_dataset(small_dataset).world()[::7]
    poses = torch.from_numpy(world)
    features, lengths = to_directions(poses)
    assert features.shape == (len(world), 63)
    units = features[:, 3:].reshape(len(world), 20, 3)
    np.testing.assert_allclose(torch.linalg.vector_norm(units, dim=-1).numpy(), 1.0, atol=1e-12)
    np.testing.assert_allclose(from_directions(features, lengths).numpy(), world, atol=1e-9)


def test_the_same_directions_on_another_body_have_its_lengths(small_dataset: Path) -> None:
    """Directions hold no proportions: laid on another body's lengths, the pose has those
    lengths exactly and each bone keeps its direction."""
    world = load_dataset(small_dataset).world()[::11]
    body = random_bodies(np.random.default_rng(3), len(world), symmetric=False, placement={})
    other = rebuild(world, body)
    features, _ = to_directions(torch.from_numpy(world))
    _, other_lengths = to_directions(torch.from_numpy(other))
    laid = from_directions(features * 1.5, other_lengths).numpy()  # scale: not a unit
    np.testing.assert_allclose(bone_lengths(laid), bone_lengths(other), atol=1e-9)
    np.testing.assert_allclose(to_directions(torch.from_numpy(laid))[0][:, 3:].numpy(),
                               features[:, 3:].numpy(), atol=1e-9)  # fmt: skip
