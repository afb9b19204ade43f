"""The carry below targets: the branch under a dragged joint turns with the dragged bone.

FABRIK carries every branch it does not solve as a rigid body: drag an elbow and the
forearm and wrist turn with the upper arm, as the start pose held them. The networks
place those joints themselves, and on bodies they never saw they place them worse than
the rigid branch does (docs/generalisation-serving.md item 20). :func:`carry_below` mixes the
two, bone by bone, after the bone pass: each joint below a targeted joint (never the
root's branches: dragging the pelvis moves the whole body) with no target of its own
below it gets the direction ``weight * carried + (1 - weight) * network``, normalised,
where *carried* is its bone in the start pose turned by the minimal rotation (swing) that
takes the targeted joint's bone from the start to the answer. Bone lengths stay exact.

Batched numpy over ``[..., 21, 3]`` with one target set: the reference the compiled
kernel (``core.compiled_limbs.carry_item``, in ``unscale``) is held to in tests.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import numpy.typing as npt

from core.kinematics import _swing
from core.skeleton import BONE_CHILDREN, JOINT_INDEX, NUM_JOINTS, PARENTS

F64 = npt.NDArray[np.float64]

_ROOT = JOINT_INDEX["pelvis"]
#: The bone (``lengths`` axis, ``BONES`` order) ending at each joint (the root: 0).
BONE_OF: npt.NDArray[np.int64] = np.zeros(NUM_JOINTS, dtype=np.int64)
BONE_OF[BONE_CHILDREN] = np.arange(len(BONE_CHILDREN))
_TINY = 1e-300


def carry_anchors(targets: Iterable[int]) -> npt.NDArray[np.int64]:
    """Per joint, the targeted joint whose bone carries it, or -1: joints below a targeted
    joint other than the root, with no targeted joint at or below them."""
    targeted = np.zeros(NUM_JOINTS, dtype=bool)
    targeted[list(targets)] = True
    above = targeted.copy()  # targeted, or has a targeted joint below
    for j in range(NUM_JOINTS - 1, 0, -1):
        above[PARENTS[j]] |= above[j]
    anchor = np.full(NUM_JOINTS, -1, dtype=np.int64)
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        if above[j]:
            continue
        if targeted[p] and p != _ROOT:
            anchor[j] = p
        elif anchor[p] >= 0:
            anchor[j] = anchor[p]
    return anchor


def _unit(v: F64) -> tuple[F64, npt.NDArray[np.bool_]]:
    n = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    ok = n[..., 0] > _TINY
    return np.where(ok[..., None], v / np.where(ok[..., None], n, 1.0), 0.0), ok


def _swing3(a: F64, b: F64, v: F64) -> F64:
    """``core.kinematics._swing`` over ``[..., 3]`` vectors: ``v`` turned by the minimal
    rotation taking ``a`` to ``b`` (unchanged where they are equal or degenerate)."""
    shape = np.broadcast_shapes(a.shape, b.shape, v.shape)
    flat = [np.broadcast_to(x, shape).reshape(-1, 3, 1) for x in (a, b, v)]
    out: F64 = _swing(*flat)[..., 0].reshape(shape)
    return out


def carry_below(
    pose: npt.ArrayLike, start: npt.ArrayLike, lengths: npt.ArrayLike,
    targets: Iterable[int], weight: float,
) -> F64:  # fmt: skip
    """``pose`` (``[..., 21, 3]``, bone lengths ``lengths [..., 20]`` exact, e.g. after the
    bone pass) with every carried joint (:func:`carry_anchors` of ``targets``) turned by
    ``weight`` towards its place on the rigid branch of ``start``. ``weight`` 0: ``pose``."""
    pose = np.asarray(pose, dtype=np.float64)
    start = np.asarray(start, dtype=np.float64)
    lengths = np.asarray(lengths, dtype=np.float64)
    anchors = carry_anchors(targets)
    out = pose.copy()
    if weight <= 0.0 or not (anchors >= 0).any():
        return out
    for j in np.flatnonzero(anchors >= 0).tolist():
        a, p = int(anchors[j]), PARENTS[j]
        pa = PARENTS[a]
        turned = _swing3(
            start[..., a, :] - start[..., pa, :],
            pose[..., a, :] - pose[..., pa, :],
            start[..., j, :] - start[..., p, :],
        )  # the start's bone, turned with the anchor's
        carried, ok_c = _unit(turned)
        d, ok_d = _unit(pose[..., j, :] - pose[..., p, :])
        both = (ok_c & ok_d)[..., None]
        mixed = np.where(both, weight * carried + (1.0 - weight) * d, carried)
        u, ok = _unit(np.where(ok_c[..., None], mixed, d))
        length = lengths[..., BONE_OF[j], None]
        out[..., j, :] = np.where(
            ok[..., None],
            out[..., p, :] + u * length,
            out[..., p, :] + pose[..., j, :] - pose[..., p, :],
        )
    return out
