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

import numpy as np
import numpy.typing as npt
import torch

from core.carry import BONE_OF, carry_anchors
from core.ends import BELOW, CHAINS, kept_chains
from core.skeleton import BONE_CHILDREN, BONE_PARENTS, BONES, NUM_JOINTS, PARENTS
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


def across_pelvis_t(flat_poses: torch.Tensor) -> torch.Tensor:
    """Each joint relative to its pose's pelvis across (x, z), its height as it is:
    ``[..., 63] -> [..., 63]`` (a body moved across as a whole is where it was; one moved
    up or down, or reshaped, is not)."""
    joints = flat_poses.reshape(*flat_poses.shape[:-1], NUM_JOINTS, 3)
    across = joints[..., :1, :] * torch.tensor(
        [1.0, 0.0, 1.0], dtype=joints.dtype, device=joints.device
    )
    return (joints - across).reshape(flat_poses.shape)


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


def _unit(v: torch.Tensor) -> torch.Tensor:
    out: torch.Tensor = v / (v.norm(dim=-1, keepdim=True) + EPS)
    return out


def carry_t(
    answers: torch.Tensor, start: torch.Tensor, lengths: torch.Tensor,
    sets: list[list[int]], weight: float,
) -> torch.Tensor:  # fmt: skip
    """``core.carry.carry_below`` of every solver's answer ``[S, B, 63]`` (bone lengths
    ``lengths [B, 20]`` exact, after :func:`bone_pass_t`) from the start poses ``[B, 63]``,
    solver ``s`` carrying below its own joints ``sets[s]``; differentiable (the degenerate
    cases the service falls back on are kept finite, not matched)."""
    if weight <= 0.0:
        return answers
    n_sets, b = answers.shape[0], answers.shape[1]
    joints = answers.reshape(n_sets, b, NUM_JOINTS, 3)
    st = start.reshape(b, NUM_JOINTS, 3)
    out = []
    for s, targets in enumerate(sets):
        anchors = carry_anchors(targets)
        if not (anchors >= 0).any():
            out.append(joints[s])
            continue
        pose = list(joints[s].unbind(dim=-2))
        for j in range(1, NUM_JOINTS):
            a = int(anchors[j])
            if a < 0:
                continue
            p, pa = PARENTS[j], PARENTS[a]
            a_s, a_o = _unit(st[:, a] - st[:, pa]), _unit(pose[a] - pose[pa])
            v = _unit(st[:, j] - st[:, p])
            c = (a_s * a_o).sum(-1, keepdim=True)
            w = torch.linalg.cross(a_s, a_o, dim=-1)
            k = (w * v).sum(-1, keepdim=True) / (1.0 + c).clamp_min(1e-12)  # as kinematics._swing
            carried = c * v + torch.linalg.cross(w, v, dim=-1) + w * k
            d = _unit(joints[s, :, j] - joints[s, :, p])
            u = _unit(weight * carried + (1.0 - weight) * d)
            b_j = int(BONE_OF[j])
            pose[j] = pose[p] + lengths[:, b_j : b_j + 1] * u
        out.append(torch.stack(pose, dim=-2))
    return torch.stack(out).reshape(answers.shape)


def ends_t(
    answers: torch.Tensor,
    network: torch.Tensor,
    sets: list[list[int]],
    chains: npt.NDArray[np.bool_] | None = None,
) -> torch.Tensor:
    """``core.ends.keep_ends`` of every solver's answer ``[S, B, 63]`` (after
    :func:`bone_pass_t`, and the carry if any) with the networks' poses ``network [S, B,
    63]`` (before it), solver ``s`` keeping the ends of its own targets ``sets[s]`` (of the
    chains ``chains`` marks, default the limb ends);
    differentiable (the degenerate cases the service leaves alone are kept finite, not
    matched)."""
    n_sets, b = answers.shape[0], answers.shape[1]
    joints = answers.reshape(n_sets, b, NUM_JOINTS, 3)
    net = network.reshape(n_sets, b, NUM_JOINTS, 3)
    out = []
    for s, targets in enumerate(sets):
        pose = list(joints[s].unbind(dim=-2))
        for c in kept_chains(targets, chains):
            top, mid, end = (int(j) for j in CHAINS[c])
            a = (pose[mid] - pose[top]).norm(dim=-1, keepdim=True)
            bl = (pose[end] - pose[mid]).norm(dim=-1, keepdim=True)
            line = net[s, :, end] - pose[top]
            d0 = line.norm(dim=-1, keepdim=True)
            u = line / d0.clamp_min(EPS)
            d = torch.minimum(torch.maximum(d0, (a - bl).abs()), a + bl)
            e0 = pose[mid] - pose[top]
            bend = e0 - (e0 * u).sum(-1, keepdim=True) * u
            v = bend / bend.norm(dim=-1, keepdim=True).clamp_min(EPS)
            cos = ((a * a + d * d - bl * bl) / (2.0 * a * d).clamp_min(EPS)).clamp(-1.0, 1.0)
            sin = (1.0 - cos * cos).clamp_min(1e-12).sqrt()  # a finite gradient at full reach
            shift = pose[top] + d * u - pose[end]
            pose[mid] = pose[top] + a * (cos * u + sin * v)
            pose[end] = pose[end] + shift
            for j in BELOW[c].nonzero()[0].tolist():
                pose[j] = pose[j] + shift
        out.append(torch.stack(pose, dim=-2))
    return torch.stack(out).reshape(answers.shape)
