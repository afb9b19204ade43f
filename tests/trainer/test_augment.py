"""Training-time variety: pairs in the start's frame and random bodies (real mocap)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from core.bodies import PLACEMENT
from core.geometry import canonical_transform
from core.skeleton import JOINT_INDEX, MIRROR, PARENTS, bone_lengths
from trainer.augment import (
    FrameSource,
    augment_pairs,
    goal_in_start_frame,
    lift_onto,
    mirror,
    random_bodies,
    rebuild,
    turn,
)
from trainer.config import AugmentConfig
from trainer.data.dataset import load_dataset

PELVIS = JOINT_INDEX["pelvis"]


def _source(path: Path) -> tuple[FrameSource, np.ndarray]:
    ds = load_dataset(path)
    src = FrameSource(
        poses=torch.from_numpy(ds.positions),
        yaw=torch.from_numpy(ds.yaw),
        root=torch.from_numpy(ds.root),
    )
    return src, ds.world()


def _pairs(world: np.ndarray, n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    rng = np.random.default_rng(seed)
    start = rng.integers(0, len(world) - 31, n)
    return torch.from_numpy(start), torch.from_numpy(start + rng.integers(6, 30, n))


def test_goal_in_start_frame_is_the_world_goal_seen_from_the_start(small_dataset: Path) -> None:
    """With the recorded root motion kept, the pair equals the two world poses both put in
    the START pose's canonical frame: the body's turn and travel between frames survive."""
    src, world = _source(small_dataset)
    start, goal = _pairs(world, 64, 0)
    cfg = AugmentConfig(align_pelvis=0.0, align_floor=0.0)
    s, g = goal_in_start_frame(src, start, goal, np.random.default_rng(1), cfg)
    frame = canonical_transform(world[start.numpy()])
    np.testing.assert_allclose(s.numpy(), frame.to_canonical(world[start.numpy()]), atol=1e-4)
    np.testing.assert_allclose(g.numpy(), frame.to_canonical(world[goal.numpy()]), atol=1e-4)


def test_aligned_pairs_put_the_start_on_the_goals_pelvis(small_dataset: Path) -> None:
    src, world = _source(small_dataset)
    start, goal = _pairs(world, 64, 2)
    cfg = AugmentConfig(align_pelvis=1.0, align_floor=0.0)
    s, g = goal_in_start_frame(src, start, goal, np.random.default_rng(3), cfg)
    torch.testing.assert_close(s[:, PELVIS], g[:, PELVIS], atol=1e-5, rtol=0)
    # the start keeps its own shape: only lifted
    lift = (s - src.poses[start])[..., 1]
    torch.testing.assert_close(lift, lift[:, :1].expand_as(lift))


def test_lifted_canonical_starts_share_the_goals_pelvis(small_dataset: Path) -> None:
    """``augment.lift_start``: a canonical start lifted onto the goal's pelvis height has
    the goal's pelvis (both are over the origin) and its own shape; the others unmoved."""
    src, world = _source(small_dataset)
    start, goal = _pairs(world, 64, 4)
    s, g = src.poses[start], src.poses[goal]
    which = torch.arange(64) % 2 == 0
    out = lift_onto(s, g, which)
    torch.testing.assert_close(out[which, PELVIS], g[which, PELVIS], atol=1e-6, rtol=0)
    assert (s[which, PELVIS, 1] - g[which, PELVIS, 1]).abs().max() > 0.01  # it did move
    torch.testing.assert_close(out[~which], s[~which], atol=0, rtol=0)
    d = out - s
    torch.testing.assert_close(d[..., [0, 2]], torch.zeros_like(d[..., [0, 2]]))
    torch.testing.assert_close(d[..., 1], d[:, :1, 1].expand_as(d[..., 1]))


def test_rebuild_gives_the_requested_bone_lengths(small_dataset: Path) -> None:
    src, _ = _source(small_dataset)
    poses = src.poses[:32].double()
    scale = torch.from_numpy(np.random.default_rng(4).uniform(0.7, 1.4, (32, 20)))
    out = rebuild(poses, scale, torch.zeros(32, dtype=torch.float64))
    want = bone_lengths(poses.numpy()) * scale.numpy()
    np.testing.assert_allclose(bone_lengths(out.numpy()), want, rtol=1e-9)
    # directions kept
    moved = rebuild(poses, scale, torch.full((32,), 0.3, dtype=torch.float64))
    up = (out[:, JOINT_INDEX["spine1"]] - out[:, PELVIS]) * 0.3
    torch.testing.assert_close(moved[:, PELVIS] - out[:, PELVIS], up)


def test_joint_shift_places_neck_head_and_collars_anew(small_dataset: Path) -> None:
    src, _ = _source(small_dataset)
    poses = src.poses[:256]
    cfg = AugmentConfig(body_fraction=0.75, joint_shift=1.0)
    scale, shift = random_bodies(256, np.random.default_rng(8), cfg)
    assert shift.shape == (256, 21)
    # the pelvis and the body draw as without joint_shift (its stream comes after them)
    scale0, pelvis = random_bodies(256, np.random.default_rng(8), AugmentConfig(body_fraction=0.75))
    torch.testing.assert_close(scale, scale0, atol=0, rtol=0)
    torch.testing.assert_close(shift[:, PELVIS], pelvis, atol=0, rtol=0)
    recorded = (scale == 1.0).all(dim=1)
    assert recorded.any() and not shift[recorded].any()  # a recorded body keeps its joints
    moved = [JOINT_INDEX[n] for n in PLACEMENT if n != "pelvis"]
    limits = torch.tensor([PLACEMENT[n] for n in PLACEMENT if n != "pelvis"])
    assert (shift[:, moved].abs() <= limits + 1e-7).all()
    assert (shift[~recorded][:, moved].abs() > 0.05 * limits).float().mean() > 0.8
    others = [j for j in range(21) if j not in moved and j != PELVIS]
    assert not shift[:, others].any()
    # symmetric bodies move both collars alike; others may not
    lc, rc = JOINT_INDEX["left_collar"], JOINT_INDEX["right_collar"]
    same = shift[:, lc] == shift[:, rc]
    assert same[~recorded].any() and not same[~recorded].all()
    # each moved joint goes along its parent bone; its children stay where they were
    out = rebuild(poses, torch.ones_like(scale), shift)
    for j in moved:
        along = shift[:, j, None] * (poses[:, j] - poses[:, PARENTS[j]])
        torch.testing.assert_close(out[:, j] - poses[:, j], along, atol=1e-6, rtol=0)
    rest = [j for j in range(21) if j not in moved and j != PELVIS]
    torch.testing.assert_close(out[:, rest], poses[:, rest], atol=1e-6, rtol=0)
    # completion's bodies (placement=False) are the pelvis-only ones, whatever joint_shift
    _, alone = random_bodies(256, np.random.default_rng(8), cfg, placement=False)
    torch.testing.assert_close(alone, pelvis, atol=0, rtol=0)


def test_pairs_share_one_body_and_are_normalised(small_dataset: Path) -> None:
    src, world = _source(small_dataset)
    start, goal = _pairs(world, 128, 5)
    cfg = AugmentConfig(body_fraction=1.0)
    s, g = augment_pairs(src.poses[start], src.poses[goal], np.random.default_rng(6), cfg, 4.0)
    ls, lg = bone_lengths(s.numpy()), bone_lengths(g.numpy())
    np.testing.assert_allclose(ls.sum(-1), 4.0, rtol=1e-5)
    # same body: bone lengths of start and goal agree as well as the recording's do
    rec = np.abs(bone_lengths(src.poses[start].numpy()) / bone_lengths(src.poses[goal].numpy()) - 1)
    assert np.abs(ls / lg - 1).max() <= rec.max() + 1e-4
    # and the bodies differ from each other (random proportions)
    shape = ls / ls.sum(-1, keepdims=True)
    assert shape.std(axis=0).mean() > 0.002


def test_mirror_and_turn() -> None:
    rng = np.random.default_rng(7)
    poses = torch.from_numpy(rng.normal(size=(4, 21, 3)))
    twice = mirror(mirror(poses))
    torch.testing.assert_close(twice, poses)
    assert mirror(poses)[:, 0, 0].neg().allclose(poses[:, MIRROR[0], 0])
    quarter = turn(poses, torch.full((4,), np.pi / 2, dtype=torch.float64))
    torch.testing.assert_close(quarter[..., 0], poses[..., 2])  # +Z turns to +X
    torch.testing.assert_close(quarter[..., 2], -poses[..., 0])


@pytest.mark.parametrize("flip", [False, True])
def test_pair_mirror_is_applied_to_both_poses(small_dataset: Path, flip: bool) -> None:
    src, world = _source(small_dataset)
    start, goal = _pairs(world, 64, 8)
    cfg = AugmentConfig(body_fraction=0.0, mirror=flip, normalise_size=False)
    s, g = augment_pairs(src.poses[start], src.poses[goal], np.random.default_rng(9), cfg, 4.0)
    same = torch.isclose(s, src.poses[start], atol=1e-5).all(dim=(1, 2))
    same_g = torch.isclose(g, src.poses[goal], atol=1e-5).all(dim=(1, 2))
    assert torch.equal(same, same_g)  # a pair is mirrored as a whole or not at all
    assert bool(same.all()) is (not flip)
