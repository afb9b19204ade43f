"""Training-time variety (torch, batched over ``[B, 21, 3]``): bodies, mirror, facing, frames.

Every network must work on a body it never saw, posed in the world as a user poses it.
The mocap holds a few bodies only, so each training sample is rebuilt on a random body:

* :func:`rebuild` scales every bone vector root-outwards (a bone keeps its direction, gets
  a new length) and moves some joints along a bone, as other studios place them: the
  pelvis along the spine, and (``joint_shift``) the neck, head and collars along their
  parent bones, within ``core.bodies.PLACEMENT``'s limits (the stress set's);
* :func:`mirror` swaps left and right (x -> -x);
* :func:`turn` rotates about +Y through the pelvis floor point;
* :func:`normalise_size` scales a body to the reference total bone length, as the service
  does before the networks see a pose (the manifest's reference bone lengths).

:func:`pair_batch` builds solver pairs as a user makes them: the goal is a later (or
earlier) frame of the same clip expressed in the START pose's canonical frame, so the body
may have turned and moved between the two, with the start optionally moved onto the goal's
pelvis (how ``bench`` builds its world-space edits). The dataset keeps every frame's
canonical transform (``yaw``, ``root``) for this.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from core.bodies import PLACEMENT
from core.skeleton import BONE_CHILDREN, BONE_PARENTS, DEPTH, JOINT_INDEX, MIRROR, PARENTS
from trainer.config import AugmentConfig

_PELVIS = JOINT_INDEX["pelvis"]
_SPINE1 = JOINT_INDEX["spine1"]
_CHILD = torch.from_numpy(BONE_CHILDREN.astype(np.int64))
_PARENT = torch.from_numpy(BONE_PARENTS.astype(np.int64))
#: Bones grouped by the depth of their child joint: one vectorised step per level.
_LEVELS = [
    torch.tensor([b for b, c in enumerate(BONE_CHILDREN.tolist()) if DEPTH[c] == d])
    for d in range(1, max(DEPTH) + 1)
]
#: Bone index of each bone's mirror image.
_BONE_MIRROR = torch.tensor(
    [BONE_CHILDREN.tolist().index(MIRROR[c]) for c in BONE_CHILDREN.tolist()]
)
_MIRROR_JOINTS = torch.tensor(MIRROR)
#: The joints ``joint_shift`` moves (all of ``PLACEMENT`` but the pelvis): index, parent,
#: largest fraction of the parent bone.
_PLACED = [
    (JOINT_INDEX[n], PARENTS[JOINT_INDEX[n]], f) for n, f in PLACEMENT.items() if n != "pelvis"
]


def bone_lengths(poses: torch.Tensor) -> torch.Tensor:
    """``[..., 21, 3] -> [..., 20]`` in ``core.skeleton.BONES`` order."""
    lengths: torch.Tensor = (poses[..., _CHILD, :] - poses[..., _PARENT, :]).norm(dim=-1)
    return lengths


def rebuild(poses: torch.Tensor, scale: torch.Tensor, shift: torch.Tensor) -> torch.Tensor:
    """Poses ``[B, 21, 3]`` on new bodies: bone ``b`` scaled by ``scale[:, b]`` (root outwards,
    directions kept), then joints moved, their children staying where they are: the pelvis
    by ``shift[:, 0]`` times the pelvis->spine1 vector, and where ``shift`` is ``[B, 21]``
    every other joint ``j`` by ``shift[:, j]`` times its parent bone (``core.bodies.Body``'s
    convention). ``shift`` ``[B]``: the pelvis alone."""
    vec = poses[:, _CHILD] - poses[:, _PARENT]  # [B, 20, 3]
    out = poses.clone()
    for bones in _LEVELS:
        out[:, _CHILD[bones]] = out[:, _PARENT[bones]] + vec[:, bones] * scale[:, bones, None]
    scaled = out.clone()  # every move is measured on the scaled pose: order does not matter
    pelvis = shift if shift.dim() == 1 else shift[:, _PELVIS]
    out[:, _PELVIS] = out[:, _PELVIS] + pelvis[:, None] * (scaled[:, _SPINE1] - scaled[:, _PELVIS])
    if shift.dim() == 2:
        for j, parent, _ in _PLACED:
            out[:, j] = out[:, j] + shift[:, j, None] * (scaled[:, j] - scaled[:, parent])
    return out


def random_bodies(
    n: int, rng: np.random.Generator, cfg: AugmentConfig, *, placement: bool = True
) -> tuple[torch.Tensor, torch.Tensor]:
    """Bone scales ``[n, 20]`` and joint shifts (:func:`rebuild`): log-normal per bone, left
    and right equal in ``symmetric_fraction`` of bodies, plus a per-body limb/trunk factor;
    the pelvis shifted up to ``pelvis_shift``; a share ``1 - body_fraction`` keeps the
    recorded body (scale 1, shift 0). With ``placement`` and ``joint_shift`` > 0 the shifts
    are ``[n, 21]``: the neck, head and collars too, each uniform within ``joint_shift``
    times its ``PLACEMENT`` limit (mirror joints alike in symmetric bodies); else ``[n]``,
    the pelvis alone (the random stream as before ``joint_shift`` existed)."""
    log = rng.normal(0.0, cfg.bone_sigma, (n, len(BONE_CHILDREN)))
    sym = rng.random(n) < cfg.symmetric_fraction
    log[sym] = 0.5 * (log[sym] + log[sym][:, _BONE_MIRROR.numpy()])
    log += rng.normal(0.0, cfg.limb_sigma, (n, 1))  # long- or short-limbed bodies
    scale = np.clip(np.exp(log), cfg.min_scale, cfg.max_scale)
    shift = rng.uniform(-cfg.pelvis_shift, cfg.pelvis_shift, n)
    keep = rng.random(n) >= cfg.body_fraction
    scale[keep], shift[keep] = 1.0, 0.0
    if not (placement and cfg.joint_shift > 0):
        return torch.from_numpy(scale).float(), torch.from_numpy(shift).float()
    shifts = np.zeros((n, len(MIRROR)))
    shifts[:, _PELVIS] = shift
    for j, _, limit in _PLACED:
        shifts[:, j] = rng.uniform(-1.0, 1.0, n) * cfg.joint_shift * limit
    mirrored = shifts[:, list(MIRROR)]
    first = np.arange(len(MIRROR)) <= np.asarray(MIRROR)  # one of each pair gives its value
    shifts[sym] = np.where(first, shifts[sym], mirrored[sym])
    shifts[keep] = 0.0
    return torch.from_numpy(scale).float(), torch.from_numpy(shifts).float()


def mirror(poses: torch.Tensor) -> torch.Tensor:
    """Left <-> right: joints swapped with their mirror images and x negated."""
    return poses[:, _MIRROR_JOINTS] * torch.tensor([-1.0, 1.0, 1.0])


def turn(poses: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Rotate ``[B, J, 3]`` about +Y through the origin by ``angle [B]`` radians (the sense
    of ``core.geometry.yaw_matrix``: +Z turns towards +X)."""
    c, s = torch.cos(angle)[:, None], torch.sin(angle)[:, None]
    x, y, z = poses[..., 0], poses[..., 1], poses[..., 2]
    return torch.stack([c * x + s * z, y, -s * x + c * z], dim=-1)


def normalise_size(
    poses: torch.Tensor, reference_total: float, *others: torch.Tensor
) -> tuple[torch.Tensor, ...]:
    """Scale ``poses`` (and ``others``, by the same factor) so that the first pose's total
    bone length is ``reference_total``: the networks see every body at one size."""
    factor = reference_total / bone_lengths(poses).sum(dim=-1)  # [B]
    return tuple(p * factor[:, None, None] for p in (poses, *others))


@dataclass(frozen=True)
class FrameSource:
    """Canonical poses of one split with each frame's canonical transform."""

    poses: torch.Tensor  # [N, 21, 3] canonical
    yaw: torch.Tensor  # [N]
    root: torch.Tensor  # [N, 3]


def goal_in_start_frame(
    src: FrameSource, start: torch.Tensor, goal: torch.Tensor, rng: np.random.Generator,
    cfg: AugmentConfig,
) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """``(start pose, goal pose)`` ``[B, 21, 3]`` in the start pose's canonical frame.

    Per pair, one of: the start moved onto the goal's pelvis (``align_pelvis``: both
    pelvises coincide), the start moved onto the goal's pelvis floor point
    (``align_floor``), or the recorded root motion kept (the rest)."""
    rel = src.yaw[goal] - src.yaw[start]
    g = turn(src.poses[goal], rel)  # goal in the start's facing, its own floor point
    s = src.poses[start]
    u = rng.random(len(start))
    keep_motion = torch.from_numpy(u >= cfg.align_pelvis + cfg.align_floor)
    lift = torch.from_numpy(u < cfg.align_pelvis)
    moved = src.root[goal] - src.root[start]  # world floor offset between the frames
    c, si = torch.cos(src.yaw[start]), torch.sin(src.yaw[start])
    local = torch.stack(
        [c * moved[:, 0] - si * moved[:, 2], moved[:, 1], si * moved[:, 0] + c * moved[:, 2]], 1
    )
    g = g + torch.where(keep_motion[:, None], local, torch.zeros_like(local))[:, None, :]
    return lift_onto(s, g, lift), g


def lift_onto(start: torch.Tensor, goal: torch.Tensor, which: torch.Tensor) -> torch.Tensor:
    """Canonical starts ``[B, 21, 3]`` moved up or down, where ``which`` ``[B]``, so that
    their pelvis is at the goal's height: both canonical pelvises are over the origin, so
    they then coincide, as in a world-space edit made on the goal's pelvis."""
    dy = goal[:, _PELVIS, 1] - start[:, _PELVIS, 1]
    out = start.clone()
    out[:, :, 1] += torch.where(which, dy, torch.zeros_like(dy))[:, None]
    return out


def augment_pairs(
    start: torch.Tensor, goal: torch.Tensor, rng: np.random.Generator, cfg: AugmentConfig,
    reference_total: float,
) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """The same random body, mirror and size normalisation for both poses of each pair."""
    n = len(start)
    scale, shift = random_bodies(n, rng, cfg)
    start, goal = rebuild(start, scale, shift), rebuild(goal, scale, shift)
    if cfg.mirror:
        flip = torch.from_numpy(rng.random(n) < 0.5)[:, None, None]
        start = torch.where(flip, mirror(start), start)
        goal = torch.where(flip, mirror(goal), goal)
    if cfg.normalise_size:
        start, goal = normalise_size(start, reference_total, goal)
    return start, goal


def augment_poses(
    poses: torch.Tensor, rng: np.random.Generator, cfg: AugmentConfig, reference_total: float
) -> torch.Tensor:
    """Single poses for the autoencoder: a random body, mirror, size, and a random facing
    and floor offset of the sizes pairs produce (a goal seen from the start's frame)."""
    n = len(poses)
    out, _ = augment_pairs(poses, poses, rng, cfg, reference_total)
    angle = torch.from_numpy(rng.normal(0.0, math.radians(cfg.yaw_sigma_deg), n)).float()
    out = turn(out, angle)
    offset = torch.from_numpy(rng.normal(0.0, cfg.offset_sigma, (n, 3))).float()
    offset[:, 1] *= 0.5
    moved = torch.from_numpy(rng.random(n) < cfg.offset_fraction)[:, None]
    return out + torch.where(moved, offset, torch.zeros_like(offset))[:, None, :]
