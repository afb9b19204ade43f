"""Elbows and knees that bend as hinges stay hinges (numpy; the last step of
:func:`core.retarget.retarget`).

The retarget aims each bone by its swing alone, so the upper arm (thigh) keeps its twist
and the forearm (shin) reaches its solved place by whatever turn of the elbow (knee) takes
it there: on CMU salsa, whose ``lForeArm`` never turns more than 0.9 degrees off one axis in
the whole clip, a wrist dragged 15-20 cm left the elbow 10-27 degrees off it, the target
met. The same points are reached with the upper arm twisted about its own bone instead.

:func:`keep_hinges`: where the frame as sent bends an elbow or knee as a hinge, by at
least :data:`MIN_BEND` about an axis (its local rotation's, in its parent's frame) within
:data:`MAX_LEAN` of square to the lower bone (no roll of the forearm about itself), the
answer's bends about that same axis: the upper arm's (thigh's) turn about the line from
its joint to the elbow's (knee's) and the elbow's angle are chosen so the forearm (shin)
points where the answer put it, keeping the bend's side (a positive angle about the axis)
and, of the two such, the smaller twist. A joint below the elbow (knee) whose turn places a
mapped point (an ankle: the toe) keeps its world rotation (its local rotation takes the
difference), so every mapped point stays where the answer had it (checked: a limb that
would move one by more than rounding is left as it was); the others (a hand and its
fingers: none of them is mapped below the wrist) keep their local rotations, as in the
aim. Bone lengths are the character's own (no offset changes).
"""

from __future__ import annotations

import numpy as np

from core.characters import F64, Pose, Skeleton, forward_kinematics, matrix_to_quat
from core.characters_maps import JointMap
from core.skeleton import JOINT_INDEX

#: (top, hinge, end) canonical joints: the arms and legs
LIMBS = tuple(
    tuple(JOINT_INDEX[f"{side}_{j}"] for j in names)
    for names in (("shoulder", "elbow", "wrist"), ("hip", "knee", "ankle"))
    for side in ("left", "right")
)
#: radians: the least bend whose axis is taken as the hinge's (below it, a straight limb's
#: axis is mostly the capture's noise: salsa's elbows wander up to 0.9 degrees off theirs,
#: 0.1 in 95 % of its frames; a 2-degree bend's axis is within 3 degrees of the clip's
#: there, and the FAIR child's elbow, a hinge to the last digit, bent 4.6 degrees)
MIN_BEND = np.radians(2.0)
#: the most a hinge's axis may lean off square to the lower bone (a rotation with more
#: turns the forearm about itself too: Bandai-Namco's elbows, 12-70 degrees off, carry the
#: forearm's roll, and bending them about their axis took a 29-degree bend to 96 degrees)
MAX_LEAN = np.radians(10.0)
#: a mapped point may move this much (times the limb's length) by rounding, no more
_STILL = 1e-9


def _turn(axis: F64, angle: float) -> F64:
    """The rotation by ``angle`` about unit ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.asarray(np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k))


def _cross(a: F64, b: F64) -> F64:
    """``np.cross`` of two 3-vectors, without its overhead."""
    x, y, z = a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]
    return np.array([x, y, z])


def _angle(axis: F64, a: F64, b: F64) -> float:
    """The signed angle about unit ``axis`` from ``a`` to ``b`` (both projected across it)."""
    pa, pb = a - (a @ axis) * axis, b - (b @ axis) * axis
    return float(np.arctan2(axis @ _cross(pa, pb), pa @ pb))


def _hinge(axis: F64, v: F64, bone: F64, want: F64) -> tuple[float, float] | None:
    """The hinge's angle ``t`` > 0 and the twist ``f`` about unit ``bone`` (the upper bone)
    with ``turn(axis, t) v = turn(bone, -f) want`` (all in the hinge's parent's frame;
    ``v`` the lower bone as the hinge's own frame has it, ``want`` where it must point);
    of the two, the smaller twist. None where no such pair exists (the bend the answer
    asks is not one a turn about ``axis`` gives) or the axis lies along the bone."""
    c = float(axis @ bone)
    s2 = 1.0 - c * c
    if s2 < 1e-12:
        return None
    c1, c2 = float(v @ axis), float(want @ bone)
    alpha, beta = (c1 - c2 * c) / s2, (c2 - c1 * c) / s2
    base = alpha * axis + beta * bone
    rest = float(v @ v) - float(base @ base)
    if rest < 0.0:
        return None
    n = _cross(axis, bone)
    gamma = np.sqrt(rest / s2)
    best = None
    for x in (base + gamma * n, base - gamma * n):
        t = _angle(axis, v, x)
        f = -_angle(bone, want, x)
        if t > 0.0 and (best is None or abs(f) < abs(best[1])):
            best = (t, f)
    return best


def keep_hinges(
    skel: Skeleton, before: Pose, pose: Pose, jmap: JointMap, changed: set[int]
) -> set[int]:
    """Turn ``pose`` (in place; the answer to the frame ``before``) so each limb whose
    hinge ``before`` bends by :data:`MIN_BEND` or more bends about the same axis (module
    docstring); ``changed``: the joints the answer changed (a limb none of whose two
    joints is among them is left). Returns the joints whose local rotation it changed."""
    out: set[int] = set()
    limbs = [(top, mid, end) for top, mid, end in LIMBS
             if _applies(skel, jmap, jmap.anchors[top].joint, jmap.anchors[mid].joint, top, mid,
                         changed)]  # fmt: skip
    if not limbs:
        return out
    quats = matrix_to_quat(before.rotations[[jmap.anchors[mid].joint for _, mid, _ in limbs]])
    g_rot, g_pos = forward_kinematics(skel, pose)  # (kept up to date as limbs turn)
    points = jmap.points(g_rot, g_pos)
    for (top, mid, end), q in zip(limbs, quats, strict=True):
        upper, hinge = jmap.anchors[top].joint, jmap.anchors[mid].joint
        bend = 2.0 * float(np.arctan2(np.linalg.norm(q[:3]), q[3]))
        if bend < MIN_BEND:
            continue
        axis = q[:3] / np.linalg.norm(q[:3])
        top_at, at = g_pos[upper], g_pos[hinge]
        length = float(np.linalg.norm(at - top_at))
        if length <= 0.0:
            continue
        parent = g_rot[skel.parents[hinge]]
        lower = points[end] - at
        v = g_rot[hinge].T @ lower
        if abs(float(axis @ v)) > np.sin(MAX_LEAN) * float(np.linalg.norm(v)):
            continue  # no hinge: the joint rolls the lower bone too
        got = _hinge(
            axis,
            v,
            parent.T @ ((at - top_at) / length),
            parent.T @ lower,
        )
        if got is None:
            continue
        trial = _bent(skel, jmap, pose, g_rot, upper, hinge, (at - top_at) / length, axis, *got)
        g2_rot, g2_pos = forward_kinematics(skel, trial)
        points2 = jmap.points(g2_rot, g2_pos)
        if float(np.abs(points2 - points).max()) > _STILL * (length + float(np.linalg.norm(lower))):
            continue
        moved = (trial.rotations != pose.rotations).any(axis=(1, 2))
        turned = {int(j) for j in np.flatnonzero(moved)}
        pose.rotations = trial.rotations
        g_rot, g_pos, points = g2_rot, g2_pos, points2
        out |= turned
    return out


def _applies(
    skel: Skeleton, jmap: JointMap, upper: int, hinge: int, top: int, mid: int, changed: set[int]
) -> bool:
    """Whether a limb's twist can be chosen: both joints turn, the hinge hangs below the
    upper joint, both canonical points sit on their joints, and the answer changed one."""
    if upper == hinge or not (skel.rotatable[upper] and skel.rotatable[hinge]):
        return False
    if upper not in changed and hinge not in changed:
        return False
    if np.any(jmap.anchors[top].offset != 0) or np.any(jmap.anchors[mid].offset != 0):
        return False
    return skel.is_ancestor(upper, skel.parents[hinge])


def _bent(
    skel: Skeleton, jmap: JointMap, pose: Pose, g_rot: F64, upper: int, hinge: int, bone: F64,
    axis: F64, t: float, f: float,
) -> Pose:  # fmt: skip
    """A copy of ``pose`` (``g_rot``: its world rotations) with ``upper`` turned by ``f``
    about the world direction ``bone``, ``hinge``'s local rotation ``t`` about ``axis``, and
    the children of ``hinge`` that place mapped points (an ankle: the toe) keeping their
    world rotations; the others (a hand, fingers) keep their local ones and follow the
    lower bone's turn about itself, as they follow it in the swing-only aim."""
    out = pose.copy()
    twist = _turn(bone, f)
    above = skel.parents[upper]
    turned = twist @ g_rot[upper]
    out.rotations[upper] = turned if above < 0 else g_rot[above].T @ turned
    out.rotations[hinge] = _turn(axis, t)
    held = twist @ g_rot[skel.parents[hinge]] @ out.rotations[hinge]
    for c in skel.children(hinge):
        if skel.rotatable[c] and _places(skel, jmap, c):
            out.rotations[c] = held.T @ g_rot[c]
    return out


def _places(skel: Skeleton, jmap: JointMap, joint: int) -> bool:
    """Whether ``joint``'s rotation places a mapped point (one hangs below it, or off its
    origin on it: an ankle's toe), not only itself (a hand at the wrist's point)."""
    for anchor in jmap.anchors:
        if anchor.joint == joint and np.any(anchor.offset != 0):
            return True
        if anchor.joint != joint and skel.is_ancestor(joint, anchor.joint):
            return True
    return False
