"""The carry below targets: the branch under a dragged joint turns with the dragged bone.

FABRIK carries every branch it does not solve as a rigid body: drag an elbow and the
forearm and wrist turn with the upper arm, as the start pose held them. The networks
place those joints themselves, and on bodies they never saw they place them worse than
the rigid branch does (docs/generalisation.md item 20). :func:`carry_below` mixes the
two, bone by bone, after the bone pass: each joint below a targeted joint (never the
root's branches: dragging the pelvis moves the whole body) with no target of its own
below it gets the direction ``weight * carried + (1 - weight) * network``, normalised,
where *carried* is its bone in the start pose turned by the minimal rotation (swing) that
takes the targeted joint's bone from the start to the answer. Bone lengths stay exact.

Batched numpy over ``[..., 21, 3]`` with one target set: the reference the compiled
kernel (``core.compiled.carry_item``, in ``unscale``) is held to in tests.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import numpy.typing as npt

from core.skeleton import BONE_CHILDREN, JOINT_INDEX, NUM_JOINTS, PARENTS

F64 = npt.NDArray[np.float64]

_ROOT = JOINT_INDEX["pelvis"]
_BONE_OF = {int(c): b for b, c in enumerate(BONE_CHILDREN)}
#: ``1 + cos`` at or below which a bone is taken to have turned right round: no swing.
OPPOSITE = 1e-9
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


def swing(a: F64, b: F64, v: F64) -> F64:
    """Rotate ``v`` by the minimal rotation taking unit ``a`` to unit ``b`` (``[..., 3]``)."""
    c = np.sum(a * b, axis=-1, keepdims=True)
    w = np.cross(a, b)
    k = np.sum(w * v, axis=-1, keepdims=True) / (1.0 + c)
    out: F64 = c * v + np.cross(w, v) + w * k
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
        a_s, ok_s = _unit(start[..., a, :] - start[..., pa, :])
        a_o, ok_o = _unit(pose[..., a, :] - pose[..., pa, :])
        v, ok_v = _unit(start[..., j, :] - start[..., p, :])
        d, ok_d = _unit(pose[..., j, :] - pose[..., p, :])
        c = np.sum(a_s * a_o, axis=-1)
        turns = ok_s & ok_o & ok_v & (1.0 + c > OPPOSITE)
        carried = swing(a_s, a_o, v)
        mixed = np.where(ok_d[..., None], weight * carried + (1.0 - weight) * d, carried)
        u, ok_u = _unit(np.where(turns[..., None], mixed, d))
        ok = np.where(turns, ok_u, ok_d)
        length = lengths[..., _BONE_OF[j], None]
        out[..., j, :] = np.where(
            ok[..., None],
            out[..., p, :] + u * length,
            out[..., p, :] + pose[..., j, :] - pose[..., p, :],
        )
    return out
