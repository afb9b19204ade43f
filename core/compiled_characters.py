"""Forward kinematics and the aim pass of a client's own skeleton, compiled (numba,
:mod:`core.jit`).

A character solve aims the skeleton's joints group by group and reads the world pose
after each (``core.retarget``): about 200 forward kinematics for one exact-reach edit of
a 22-joint skeleton, which took half of its 110 ms as numpy loops over the joints. Here
one call is a few µs (that edit: 108.6 -> 41.3 ms median, with the anchors' points taken
in one array operation, ``JointMap.points``). The products are written out in source
order (no BLAS, no fused multiply-add), so an answer is the same on every run; they differ
from numpy's ``@`` (BLAS) by rounding only (6e-17 on the docs' BVH example;
tests/core/test_characters.py holds them to 1e-12 on real files).

The aim pass itself is compiled too (:func:`aim_singles_into`): every group that aims one
child (an arm's, a leg's, the neck's joints) is turned here by its swing, one call for a
run of such groups; a group that aims two children or more (a chest, a pelvis) goes back
to numpy for its least-squares turn (an SVD: numba's needs SciPy, which the service does
not install). The docs' BVH edit, read to written back: 25.2 -> 8.5 ms CPU p50
(``python -m bench.ab``'s ``bvh exact`` row, docs/characters.md).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.jit import jit

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


@jit
def forward_kinematics_into(
    parents: I64, rotations: F64, translations: F64, g_rot: F64, g_pos: F64
) -> None:  # pragma: no cover - compiled
    """World rotations ``g_rot [J, 3, 3]`` and positions ``g_pos [J, 3]`` of local
    ``rotations [J, 3, 3]`` and ``translations [J, 3]``; ``parents [J]`` in topological
    order (-1: a root)."""
    for j in range(parents.shape[0]):
        p = parents[j]
        if p < 0:
            for r in range(3):
                for c in range(3):
                    g_rot[j, r, c] = rotations[j, r, c]
                g_pos[j, r] = translations[j, r]
            continue
        for r in range(3):
            a0, a1, a2 = g_rot[p, r, 0], g_rot[p, r, 1], g_rot[p, r, 2]
            for c in range(3):
                g_rot[j, r, c] = (
                    a0 * rotations[j, 0, c] + a1 * rotations[j, 1, c] + a2 * rotations[j, 2, c]
                )
            g_pos[j, r] = g_pos[p, r] + (
                a0 * translations[j, 0] + a1 * translations[j, 1] + a2 * translations[j, 2]
            )


def forward_kinematics(parents: I64, rotations: F64, translations: F64) -> tuple[F64, F64]:
    """:func:`forward_kinematics_into` into new arrays (inputs made contiguous, writable
    float64: the one signature :func:`warm` compiles; a read-only array would compile
    another on a request)."""
    n = parents.shape[0]
    g_rot = np.empty((n, 3, 3))
    g_pos = np.empty((n, 3))
    forward_kinematics_into(
        np.require(parents, np.int64, ["C", "W"]),
        np.require(rotations, np.float64, ["C", "W"]),
        np.require(translations, np.float64, ["C", "W"]),
        g_rot,
        g_pos,
    )
    return g_rot, g_pos


@jit
def mul33_into(a: F64, b: F64, out: F64) -> None:  # pragma: no cover - compiled
    """``out [3, 3] = a b`` (either may be a transposed view; ``out`` neither of them),
    each sum in source order."""
    for r in range(3):
        for q in range(3):
            out[r, q] = a[r, 0] * b[0, q] + a[r, 1] * b[1, q] + a[r, 2] * b[2, q]


@jit
def swing_matrix_into(a: F64, b: F64, out: F64) -> None:  # pragma: no cover - compiled
    """``out [3, 3]``: the minimal rotation taking the direction of ``a`` to that of ``b``
    (``core.characters.swing``, the same steps written for 3-vectors; opposite directions
    give a half turn). Not ``core.compiled_limbs.swing_into``: that one turns a vector and leaves
    it as it is where the directions are opposite, as the pose path's ``_swing`` does);
    the identity where either has no direction (zero length)."""
    na = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    nb = np.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    if not (na > 0.0 and nb > 0.0):
        for r in range(3):
            for k in range(3):
                out[r, k] = 1.0 if r == k else 0.0
        return
    ua0, ua1, ua2 = a[0] / na, a[1] / na, a[2] / na
    ub0, ub1, ub2 = b[0] / nb, b[1] / nb, b[2] / nb
    x, y, z = ua1 * ub2 - ua2 * ub1, ua2 * ub0 - ua0 * ub2, ua0 * ub1 - ua1 * ub0
    s = np.sqrt(x * x + y * y + z * z)
    c = ua0 * ub0 + ua1 * ub1 + ua2 * ub2
    if s < 1e-12:
        for r in range(3):
            for k in range(3):
                out[r, k] = 1.0 if r == k else 0.0
        if c > 0:
            return
        # opposite: half a turn about an axis perpendicular to a
        m = 0
        if abs(ua1) < abs(ua0):
            m = 1
        if abs(ua2) < min(abs(ua0), abs(ua1)):
            m = 2
        e0, e1, e2 = (1.0 if m == 0 else 0.0), (1.0 if m == 1 else 0.0), (1.0 if m == 2 else 0.0)
        p0, p1, p2 = ua1 * e2 - ua2 * e1, ua2 * e0 - ua0 * e2, ua0 * e1 - ua1 * e0
        n = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        p = (p0 / n, p1 / n, p2 / n)
        for r in range(3):
            for k in range(3):
                out[r, k] = 2.0 * p[r] * p[k] - (1.0 if r == k else 0.0)
        return
    k0, k1, k2 = x / s, y / s, z / s
    kx = ((0.0, -k2, k1), (k2, 0.0, -k0), (-k1, k0, 0.0))
    for r in range(3):
        for q in range(3):
            kk = kx[r][0] * kx[0][q] + kx[r][1] * kx[1][q] + kx[r][2] * kx[2][q]
            out[r, q] = (1.0 if r == q else 0.0) + s * kx[r][q] + (1.0 - c) * kk


@jit
def aim_singles_into(
    parents: I64,
    rotations: F64,
    translations: F64,
    original: F64,
    aims: I64,
    kid_start: I64,
    kids: I64,
    anchor_joints: I64,
    anchor_offsets: F64,
    goal: F64,
    start: int,
    skip: int,
    g_rot: F64,
    g_pos: F64,
    changed: npt.NDArray[np.uint8],
) -> int:  # pragma: no cover - compiled
    """The aim pass of ``core.retarget`` from group ``start`` on, groups in order: group
    ``i`` turns joint ``aims[i]`` (from its ``original`` local rotation) so its canonical
    children ``kids[kid_start[i]:kid_start[i + 1]]`` (anchored at ``anchor_joints`` /
    ``anchor_offsets``) point at ``goal``, by the swing of the one child that can aim;
    ``changed[i]`` set where the rotation changed. Returns the first group with two
    children or more that can aim (their least-squares turn is numpy's SVD, left to the
    caller), or ``len(aims)`` once all are done. ``g_rot`` / ``g_pos`` are work space."""
    v = np.empty((kids.shape[0], 3))
    u = np.empty((kids.shape[0], 3))
    nv = np.empty(kids.shape[0])
    nu = np.empty(kids.shape[0])
    turn = np.empty((3, 3))
    new = np.empty((3, 3))
    local = np.empty((3, 3))
    for i in range(start, aims.shape[0]):
        b = aims[i]
        if b == skip:
            continue
        for r in range(3):
            for c in range(3):
                rotations[b, r, c] = original[b, r, c]
        forward_kinematics_into(parents, rotations, translations, g_rot, g_pos)
        lo, hi = kid_start[i], kid_start[i + 1]
        top = 0.0
        for m in range(lo, hi):
            k = kids[m]
            j = anchor_joints[k]
            for r in range(3):
                point = g_pos[j, r] + (
                    g_rot[j, r, 0] * anchor_offsets[k, 0]
                    + g_rot[j, r, 1] * anchor_offsets[k, 1]
                    + g_rot[j, r, 2] * anchor_offsets[k, 2]
                )
                v[m, r] = point - g_pos[b, r]
                u[m, r] = goal[k, r] - g_pos[b, r]
            nv[m] = np.sqrt(v[m, 0] * v[m, 0] + v[m, 1] * v[m, 1] + v[m, 2] * v[m, 2])
            nu[m] = np.sqrt(u[m, 0] * u[m, 0] + u[m, 1] * u[m, 1] + u[m, 2] * u[m, 2])
            top = max(top, nv[m])
        count, one = 0, -1
        for m in range(lo, hi):
            if nv[m] > 1e-9 * max(1.0, top) and nu[m] > 1e-12:
                count += 1
                if one < 0:
                    one = m
        if count == 0:
            continue
        if count > 1:
            return i
        swing_matrix_into(v[one], u[one], turn)
        p = parents[b]
        mul33_into(turn, g_rot[b], new)
        if p >= 0:
            mul33_into(g_rot[p].T, new, local)
        else:
            local[:] = new
        differs = False
        for r in range(3):
            for c in range(3):
                if not abs(local[r, c] - original[b, r, c]) <= 1e-15:
                    differs = True
        if differs:  # compared before writing: ``original`` may be ``rotations`` itself
            changed[i] = 1
            for r in range(3):
                for c in range(3):
                    rotations[b, r, c] = local[r, c]
    return int(aims.shape[0])


def warm() -> None:
    """Compile (or load from the cache) this module's kernels, with the signatures the
    callers use."""
    parents = np.array([-1, 0], dtype=np.int64)
    rotations = np.repeat(np.eye(3)[None], 2, axis=0)
    translations = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    forward_kinematics(parents, rotations, translations)
    ints = np.array([0], dtype=np.int64)
    aim_singles_into(
        parents, rotations.copy(), translations, rotations, ints, np.array([0, 1], np.int64),
        ints, np.array([1], np.int64), np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]]), 0, -1,
        np.empty((2, 3, 3)), np.empty((2, 3)), np.zeros(1, np.uint8),
    )  # fmt: skip
