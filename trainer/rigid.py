"""The service's bone pass in torch, so the solvers can be trained on the answer as it is
served (``solver.rigid_loss``).

The service gives every answer the start pose's exact bone lengths with
:func:`core.kinematics.bone_pass`: root outwards, each joint goes to
``parent_new + length * unit(child_old - parent_new)``. A network that reaches its target
with bones of the wrong length (a body it never saw) then misses it by what the chain's
length errors add up to (3-4 cm at a wrist on held-out bodies, against 0.6 cm before the
pass; docs/generalisation.md). The same step here is differentiable, so a loss on its
output teaches the solvers to reach with the body's own bones.
"""

from __future__ import annotations

import torch

from core.skeleton import BONE_CHILDREN, BONE_PARENTS, BONES, NUM_JOINTS
from trainer.augment import bone_lengths

#: Eps of the direction's norm: keeps the gradient finite where a child sits on its parent.
EPS = 1e-9


def bone_lengths_t(flat_poses: torch.Tensor) -> torch.Tensor:
    """Bone lengths ``[..., 20]`` of flattened poses ``[..., 63]`` (``BONES`` order)."""
    return bone_lengths(flat_poses.reshape(*flat_poses.shape[:-1], NUM_JOINTS, 3))


def parent_offsets_t(flat_poses: torch.Tensor) -> torch.Tensor:
    """Each joint relative to its parent, the root as it is: ``[..., 63] -> [..., 63]``
    in the same joint-major columns (a joint carried along by its parent keeps its offset)."""
    joints = flat_poses.reshape(*flat_poses.shape[:-1], NUM_JOINTS, 3)
    children, parents = torch.as_tensor(BONE_CHILDREN), torch.as_tensor(BONE_PARENTS)
    out = joints.index_copy(-2, children, joints[..., children, :] - joints[..., parents, :])
    return out.reshape(flat_poses.shape)


def bone_pass_t(flat_poses: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """``core.kinematics.bone_pass`` of flattened poses ``[..., 63]`` to ``lengths``
    ``[..., 20]`` (broadcastable), differentiable; the root keeps its position."""
    joints = flat_poses.reshape(*flat_poses.shape[:-1], NUM_JOINTS, 3)
    lengths = lengths.expand(*joints.shape[:-2], len(BONES))
    out: list[torch.Tensor | None] = [None] * NUM_JOINTS
    out[0] = joints[..., 0, :]
    for b, (child, parent) in enumerate(BONES):  # topological: parents come first
        base = out[parent]
        assert base is not None
        step = joints[..., child, :] - base
        unit = step / (step.norm(dim=-1, keepdim=True) + EPS)
        out[child] = base + lengths[..., b : b + 1] * unit
    stacked = torch.stack([j for j in out if j is not None], dim=-2)
    return stacked.reshape(flat_poses.shape)
