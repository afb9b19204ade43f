"""The hinge step of a character's retarget, compiled (numba, :mod:`core.jit`):
:func:`keep_hinges_into` is the arithmetic of :func:`core.hinges.keep_hinges` (which
says what it does and why) for every limb in one call, where the numpy steps of each
limb, two forward kinematics and a copy of the pose cost ~0.1 ms a limb (0.42 of a
2.1 ms BVH edit in soft reach). Products in source order (no BLAS, no fused
multiply-add): the same answer on every run, numpy's to rounding
(``tests/core/test_hinges.py`` holds it to a numpy reference).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.compiled_characters import forward_kinematics_into, mul33_into
from core.compiled_reach import points_into
from core.jit import jit

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


@jit
def _turn_into(axis: F64, angle: float, out: F64) -> None:  # pragma: no cover - compiled
    """``out [3, 3]``: the rotation by ``angle`` about unit ``axis`` (Rodrigues)."""
    s, c1 = np.sin(angle), 1.0 - np.cos(angle)
    kx = ((0.0, -axis[2], axis[1]), (axis[2], 0.0, -axis[0]), (-axis[1], axis[0], 0.0))
    for r in range(3):
        for q in range(3):
            kk = kx[r][0] * kx[0][q] + kx[r][1] * kx[1][q] + kx[r][2] * kx[2][q]
            out[r, q] = (1.0 if r == q else 0.0) + s * kx[r][q] + c1 * kk


@jit
def _dot(a: F64, b: F64) -> float:  # pragma: no cover - compiled
    return float(a[0] * b[0] + a[1] * b[1] + a[2] * b[2])


@jit
def _angle(axis: F64, a: F64, b: F64) -> float:  # pragma: no cover - compiled
    """The signed angle about unit ``axis`` from ``a`` to ``b`` (both projected across it)."""
    da, db = _dot(a, axis), _dot(b, axis)
    pa = np.empty(3)
    pb = np.empty(3)
    for r in range(3):
        pa[r] = a[r] - da * axis[r]
        pb[r] = b[r] - db * axis[r]
    x = pa[1] * pb[2] - pa[2] * pb[1]
    y = pa[2] * pb[0] - pa[0] * pb[2]
    z = pa[0] * pb[1] - pa[1] * pb[0]
    return float(np.arctan2(axis[0] * x + axis[1] * y + axis[2] * z, _dot(pa, pb)))


@jit
def _hinge(axis: F64, v: F64, bone: F64, want: F64, got: F64) -> bool:  # pragma: no cover
    """The hinge's angle ``t`` > 0 and the twist ``f`` about unit ``bone`` with
    ``turn(axis, t) v = turn(bone, -f) want``, of the two the smaller twist, into ``got``
    ``[2]``; False where none exists (``core.hinges``: the bend asked is not one a turn
    about ``axis`` gives, or the axis lies along the bone)."""
    c = _dot(axis, bone)
    s2 = 1.0 - c * c
    if s2 < 1e-12:
        return False
    c1, c2 = _dot(v, axis), _dot(want, bone)
    alpha, beta = (c1 - c2 * c) / s2, (c2 - c1 * c) / s2
    base = np.empty(3)
    for r in range(3):
        base[r] = alpha * axis[r] + beta * bone[r]
    rest = _dot(v, v) - _dot(base, base)
    if rest < 0.0:
        return False
    n = np.empty(3)
    n[0] = axis[1] * bone[2] - axis[2] * bone[1]
    n[1] = axis[2] * bone[0] - axis[0] * bone[2]
    n[2] = axis[0] * bone[1] - axis[1] * bone[0]
    gamma = np.sqrt(rest / s2)
    x = np.empty(3)
    found = False
    for sign in (1.0, -1.0):
        for r in range(3):
            x[r] = base[r] + sign * gamma * n[r]
        t = _angle(axis, v, x)
        f = -_angle(bone, want, x)
        if t > 0.0 and (not found or abs(f) < abs(got[1])):
            got[0], got[1] = t, f
            found = True
    return found


@jit
def _mul_t_vec(m: F64, a: F64, out: F64) -> None:  # pragma: no cover - compiled
    """``out [3] = m.T a``."""
    for r in range(3):
        out[r] = m[0, r] * a[0] + m[1, r] * a[1] + m[2, r] * a[2]


@jit
def keep_hinges_into(
    parents: I64,
    rotations: F64,
    translations: F64,
    anchor_joints: I64,
    anchor_offsets: F64,
    limbs: I64,
    quats: F64,
    held_start: I64,
    held: I64,
    min_bend: float,
    sin_lean: float,
    still: float,
    turned: npt.NDArray[np.uint8],
) -> None:  # pragma: no cover - compiled
    """:func:`core.hinges.keep_hinges` of ``rotations [J, 3, 3]`` in place: for each limb
    ``limbs[i] = (upper joint, hinge joint, end canonical joint)``, in order, whose hinge
    the frame as sent bends by the unit quaternion ``quats[i]`` (``[x, y, z, w]``), the
    upper joint's twist and the hinge's bend about that quaternion's axis chosen so the
    lower bone points where it did; the hinge's children ``held[held_start[i]:held_start[i
    + 1]]`` (those placing a mapped point) keep their world rotations. A limb is kept only
    where no canonical point moves more than ``still`` times its length; ``turned[j]`` set
    for each joint whose rotation it changed."""
    n = parents.shape[0]
    g_rot, g_pos = np.empty((n, 3, 3)), np.empty((n, 3))
    g2_rot, g2_pos = np.empty((n, 3, 3)), np.empty((n, 3))
    points = np.empty((anchor_joints.shape[0], 3))
    points2 = np.empty((anchor_joints.shape[0], 3))
    trial = np.empty((n, 3, 3))
    axis, lower, v = np.empty(3), np.empty(3), np.empty(3)
    bone, up, down, got = np.empty(3), np.empty(3), np.empty(3), np.empty(2)
    twist, turn, bent = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    tmp, held_rot = np.empty((3, 3)), np.empty((3, 3))
    forward_kinematics_into(parents, rotations, translations, g_rot, g_pos)
    points_into(g_rot, g_pos, anchor_joints, anchor_offsets, points)
    for i in range(limbs.shape[0]):
        upper, hinge, end = limbs[i, 0], limbs[i, 1], limbs[i, 2]
        q = quats[i]
        sv = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])
        if 2.0 * np.arctan2(sv, q[3]) < min_bend:
            continue
        for r in range(3):
            axis[r] = q[r] / sv
            bone[r] = g_pos[hinge, r] - g_pos[upper, r]
            lower[r] = points[end, r] - g_pos[hinge, r]
        length = np.sqrt(_dot(bone, bone))
        if length <= 0.0:
            continue
        for r in range(3):
            bone[r] = bone[r] / length
        _mul_t_vec(g_rot[hinge], lower, v)
        if abs(_dot(axis, v)) > sin_lean * np.sqrt(_dot(v, v)):
            continue  # no hinge: the joint rolls the lower bone too
        pm = g_rot[parents[hinge]]
        _mul_t_vec(pm, bone, up)
        _mul_t_vec(pm, lower, down)
        if not _hinge(axis, v, up, down, got):
            continue
        # the trial pose: the upper joint twisted about the world bone, the hinge bent
        for j in range(n):
            for r in range(3):
                for c in range(3):
                    trial[j, r, c] = rotations[j, r, c]
        _turn_into(bone, got[1], twist)
        mul33_into(twist, g_rot[upper], tmp)
        above = parents[upper]
        if above < 0:
            trial[upper] = tmp
        else:
            mul33_into(g_rot[above].T, tmp, bent)
            trial[upper] = bent
        _turn_into(axis, got[0], turn)
        trial[hinge] = turn
        mul33_into(twist, pm, tmp)
        mul33_into(tmp, turn, held_rot)
        for m in range(held_start[i], held_start[i + 1]):
            c = held[m]
            mul33_into(held_rot.T, g_rot[c], bent)
            trial[c] = bent
        forward_kinematics_into(parents, trial, translations, g2_rot, g2_pos)
        points_into(g2_rot, g2_pos, anchor_joints, anchor_offsets, points2)
        worst = 0.0
        for k in range(points.shape[0]):
            for r in range(3):
                worst = max(worst, abs(points2[k, r] - points[k, r]))
        if worst > still * (length + np.sqrt(_dot(lower, lower))):
            continue
        for j in range(n):
            for r in range(3):
                for c in range(3):
                    if trial[j, r, c] != rotations[j, r, c]:
                        turned[j] = 1
                    rotations[j, r, c] = trial[j, r, c]
        g_rot[:], g_pos[:], points[:] = g2_rot, g2_pos, points2


def warm() -> None:
    """Compile (or load from the cache) :func:`keep_hinges_into` with its callers'
    signature."""
    parents = np.array([-1, 0, 1], dtype=np.int64)
    rotations = np.repeat(np.eye(3)[None], 3, axis=0)
    translations = np.array([[0.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, -1.0, 0.0]])
    keep_hinges_into(
        parents, rotations, translations, np.array([0, 1, 2], np.int64), np.zeros((3, 3)),
        np.array([[0, 1, 2]], np.int64), np.array([[0.0, 0.0, 0.0, 1.0]]),
        np.zeros(2, np.int64), np.zeros(0, np.int64), 0.03, 0.17, 1e-9, np.zeros(3, np.uint8),
    )  # fmt: skip
