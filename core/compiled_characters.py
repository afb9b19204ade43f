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

The aim pass itself is compiled too (:func:`aim_pass_into`): a group that aims one child
(an arm's, a leg's, the neck's joints) is turned by its swing, a group that aims two or
more (a chest, a pelvis) by their weighted least-squares turn (:func:`best_rotation_into`:
Horn's quaternion, the top eigenvector of a 4 x 4 symmetric matrix by Jacobi's sweeps,
since numba's SVD needs SciPy, which the service does not install), one call for the
whole pass. The docs' BVH edit, read to written back: 25.2 -> 8.5 ms CPU p50 with the
single-child groups compiled (``python -m bench.ab``'s ``bvh exact`` row,
docs/characters.md).
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
def _horn_quaternion(s: F64, q: F64) -> None:  # pragma: no cover - compiled
    """``q [4]`` (w, x, y, z), a unit quaternion: the rotation ``R`` that maximises
    ``trace(R s)`` for a 3 x 3 ``s`` (Horn 1987): the eigenvector of the largest eigenvalue
    of the 4 x 4 symmetric matrix made of ``s``, by cyclic Jacobi rotations (each sweep in
    a fixed order, so the answer is the same on every run); its sign as it comes."""
    a = np.empty((4, 4))
    a[0, 0] = s[0, 0] + s[1, 1] + s[2, 2]
    a[1, 1] = s[0, 0] - s[1, 1] - s[2, 2]
    a[2, 2] = -s[0, 0] + s[1, 1] - s[2, 2]
    a[3, 3] = -s[0, 0] - s[1, 1] + s[2, 2]
    a[0, 1] = a[1, 0] = s[1, 2] - s[2, 1]
    a[0, 2] = a[2, 0] = s[2, 0] - s[0, 2]
    a[0, 3] = a[3, 0] = s[0, 1] - s[1, 0]
    a[1, 2] = a[2, 1] = s[0, 1] + s[1, 0]
    a[1, 3] = a[3, 1] = s[2, 0] + s[0, 2]
    a[2, 3] = a[3, 2] = s[1, 2] + s[2, 1]
    e = np.zeros((4, 4))
    for r in range(4):
        e[r, r] = 1.0
    scale = 0.0
    for r in range(4):
        for c in range(4):
            scale = max(scale, abs(a[r, c]))
    for _ in range(_SWEEPS):
        off = 0.0
        for p in range(3):
            for k in range(p + 1, 4):
                off = max(off, abs(a[p, k]))
        if off <= 1e-300 or off <= 1e-17 * scale:
            break
        for p in range(3):
            for k in range(p + 1, 4):
                if a[p, k] == 0.0:
                    continue
                theta = (a[k, k] - a[p, p]) / (2.0 * a[p, k])
                t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta < 0.0:
                    t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                sn = t * c
                for m in range(4):  # columns p and k of a J
                    amp, amk = a[m, p], a[m, k]
                    a[m, p] = c * amp - sn * amk
                    a[m, k] = sn * amp + c * amk
                for m in range(4):  # rows p and k of J^T (a J)
                    apm, akm = a[p, m], a[k, m]
                    a[p, m] = c * apm - sn * akm
                    a[k, m] = sn * apm + c * akm
                for m in range(4):
                    emp, emk = e[m, p], e[m, k]
                    e[m, p] = c * emp - sn * emk
                    e[m, k] = sn * emp + c * emk
    top = 0
    for r in range(1, 4):
        if a[r, r] > a[top, top]:
            top = r
    norm = np.sqrt(e[0, top] ** 2 + e[1, top] ** 2 + e[2, top] ** 2 + e[3, top] ** 2)
    for r in range(4):
        q[r] = e[r, top] / norm


@jit
def best_rotation_into(v: F64, u: F64, w: F64, n: int, out: F64) -> None:  # pragma: no cover
    """``out [3, 3]``: the rotation ``R`` minimising ``sum_k w_k |R v_k - u_k|^2`` over the
    first ``n`` rows of ``v`` and ``u`` ``[K, 3]`` (Kabsch / Wahba): the one maximising
    ``trace(R S)``, ``S`` the weighted cross-covariance (:func:`_horn_quaternion`)."""
    s = np.zeros((3, 3))
    for k in range(n):
        for r in range(3):
            for c in range(3):
                s[r, c] += w[k] * v[k, r] * u[k, c]
    q = np.empty(4)
    _horn_quaternion(s, q)
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    out[0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    out[1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    out[2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3
    out[0, 1] = 2.0 * (q1 * q2 - q0 * q3)
    out[1, 0] = 2.0 * (q1 * q2 + q0 * q3)
    out[0, 2] = 2.0 * (q1 * q3 + q0 * q2)
    out[2, 0] = 2.0 * (q1 * q3 - q0 * q2)
    out[1, 2] = 2.0 * (q2 * q3 - q0 * q1)
    out[2, 1] = 2.0 * (q2 * q3 + q0 * q1)


@jit
def matrix_quats_into(m: F64, out: F64) -> None:  # pragma: no cover - compiled
    """``out [N, 4]`` (x, y, z, w): the unit quaternion of the rotation nearest each of
    ``m [N, 3, 3]`` (the one maximising ``trace(R m^T)``, :func:`_horn_quaternion`: a
    product of many rotations gives its best rotation's, not its drift's), w >= 0, and
    where w is 0 (a half turn) the largest of x, y, z positive."""
    s = np.empty((3, 3))
    q = np.empty(4)
    for i in range(m.shape[0]):
        for r in range(3):
            for c in range(3):
                s[r, c] = m[i, c, r]
        _horn_quaternion(s, q)
        big = 1
        for r in range(2, 4):
            if abs(q[r]) > abs(q[big]):
                big = r
        sign = -1.0 if q[0] < 0.0 or (q[0] == 0.0 and q[big] < 0.0) else 1.0
        out[i, 0], out[i, 1], out[i, 2] = sign * q[1], sign * q[2], sign * q[3]
        out[i, 3] = sign * q[0]


#: Jacobi sweeps at most (a 4 x 4 matrix takes 3-5 to rounding; more only where the
#: largest eigenvalues tie, and then any of their eigenvectors is a best turn)
_SWEEPS = 32


@jit
def aim_pass_into(
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
    skip: int,
    weigh: F64,
    g_rot: F64,
    g_pos: F64,
    changed: npt.NDArray[np.uint8],
) -> None:  # pragma: no cover - compiled
    """The aim pass of ``core.retarget``, groups in order: group ``i`` turns joint
    ``aims[i]`` (from its ``original`` local rotation; not ``skip``) so its canonical
    children ``kids[kid_start[i]:kid_start[i + 1]]`` (anchored at ``anchor_joints`` /
    ``anchor_offsets``) point at ``goal``: by the swing of the one child that can aim, or
    by the least-squares turn of those that can (:func:`best_rotation_into`), each child
    weighing its length times ``weigh [21]`` (a pinned one's more); ``changed[i]`` set
    where the rotation changed. ``g_rot`` / ``g_pos`` are work space."""
    v = np.empty((kids.shape[0], 3))
    u = np.empty((kids.shape[0], 3))
    nv = np.empty(kids.shape[0])
    nu = np.empty(kids.shape[0])
    sv = np.empty((kids.shape[0], 3))
    su = np.empty((kids.shape[0], 3))
    sw = np.empty(kids.shape[0])
    turn = np.empty((3, 3))
    new = np.empty((3, 3))
    local = np.empty((3, 3))
    for i in range(aims.shape[0]):
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
        if count == 1:
            swing_matrix_into(v[one], u[one], turn)
        else:  # the aimable children's unit directions, weighted by length (and pins)
            n, total = 0, 0.0
            for m in range(lo, hi):
                if nv[m] > 1e-9 * max(1.0, top) and nu[m] > 1e-12:
                    for r in range(3):
                        sv[n, r] = v[m, r] / nv[m]
                        su[n, r] = u[m, r] / nu[m]
                    sw[n] = nv[m] * weigh[kids[m]]
                    total += sw[n]
                    n += 1
            for m in range(n):
                sw[m] = sw[m] / total
            best_rotation_into(sv, su, sw, n, turn)
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


def matrix_quats(m: F64) -> F64:
    """:func:`matrix_quats_into` of ``m [..., 3, 3]`` into a new ``[..., 4]``."""
    flat = np.require(np.reshape(m, (-1, 3, 3)), np.float64, ["C", "W"])
    out = np.empty((flat.shape[0], 4))
    matrix_quats_into(flat, out)
    return out.reshape(*np.shape(m)[:-2], 4)


def best_rotation(v: F64, u: F64, weights: F64) -> F64:
    """:func:`best_rotation_into` of ``v``, ``u`` ``[K, 3]`` and ``weights`` ``[K]`` into a new
    ``[3, 3]``."""
    out = np.empty((3, 3))
    best_rotation_into(
        np.require(v, np.float64, ["C", "W"]), np.require(u, np.float64, ["C", "W"]),
        np.require(weights, np.float64, ["C", "W"]), len(v), out,
    )  # fmt: skip
    return out


def warm() -> None:
    """Compile (or load from the cache) this module's kernels, with the signatures the
    callers use."""
    parents = np.array([-1, 0], dtype=np.int64)
    rotations = np.repeat(np.eye(3)[None], 2, axis=0)
    translations = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    forward_kinematics(parents, rotations, translations)
    ints = np.array([0], dtype=np.int64)
    aim_pass_into(
        parents, rotations.copy(), translations, rotations, ints, np.array([0, 1], np.int64),
        ints, np.array([1], np.int64), np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]]), -1,
        np.ones(1), np.empty((2, 3, 3)), np.empty((2, 3)), np.zeros(1, np.uint8),
    )  # fmt: skip
    best_rotation(np.eye(3), np.eye(3), np.ones(3))
    matrix_quats(np.eye(3)[None])
