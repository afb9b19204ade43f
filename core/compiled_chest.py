"""The chest of a FABRIK solve as one rigid body, and a cone on each clavicle, compiled
(numba, :mod:`core.jit`): :mod:`core.chest` (the numpy reference, which says why) for one
pose in rank order ``[21, 3]``, the same formulas in the same order.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.chest import (
    CLAVICLE_CONE,
    FIT,
    FIT_WEIGHT,
    L_COLLAR,
    L_SHOULDER,
    R_COLLAR,
    R_SHOULDER,
    SPAN,
    SPINE1,
    SPINE2,
    TILT,
    WIDTH,
)
from core.jit import jit
from core.shells import TINY

F64 = npt.NDArray[np.float64]
Bool = npt.NDArray[np.bool_]

__all__ = [
    "L_COLLAR", "L_SHOULDER", "R_COLLAR", "R_SHOULDER", "SPINE2", "applies", "cone", "place",
    "turn",
]  # fmt: skip


@jit
def _swing(a: F64, b: F64, limit: float, out: F64) -> None:  # pragma: no cover - compiled
    """The minimal rotation taking direction ``a`` to ``b`` into ``out [3, 3]``, by at most
    ``limit`` radians (``np.pi``: none); the identity where they are equal or degenerate."""
    na = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    nb = np.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    for i in range(3):
        for j in range(3):
            out[i, j] = 1.0 if i == j else 0.0
    if (a[0] == b[0] and a[1] == b[1] and a[2] == b[2]) or na <= TINY or nb <= TINY:
        return
    a0, a1, a2 = a[0] / na, a[1] / na, a[2] / na
    b0, b1, b2 = b[0] / nb, b[1] / nb, b[2] / nb
    cs = a0 * b0 + a1 * b1 + a2 * b2
    w0, w1, w2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    sn = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    if limit < np.pi and np.arctan2(sn, cs) > limit:  # by ``limit`` about the same axis
        if sn <= TINY:
            return
        cs, s = np.cos(limit), np.sin(limit)
        w0, w1, w2 = s * w0 / sn, s * w1 / sn, s * w2 / sn
    d = max(1.0 + cs, 1e-12)  # c I + [w]x + w w^T / (1 + c)
    out[0, 0], out[0, 1], out[0, 2] = cs + w0 * w0 / d, -w2 + w0 * w1 / d, w1 + w0 * w2 / d
    out[1, 0], out[1, 1], out[1, 2] = w2 + w1 * w0 / d, cs + w1 * w1 / d, -w0 + w1 * w2 / d
    out[2, 0], out[2, 1], out[2, 2] = -w1 + w2 * w0 / d, w0 + w2 * w1 / d, cs + w2 * w2 / d


@jit
def _times(t: F64, rot: F64) -> None:  # pragma: no cover - compiled
    """``rot = t @ rot`` (3 x 3, summed left to right)."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = (t[i, 0] * rot[0, j] + t[i, 1] * rot[1, j]) + t[i, 2] * rot[2, j]
    rot[:, :] = out


@jit
def turn(x0: F64, y: F64, pts: F64, w: F64, free: bool, rot: F64) -> None:  # pragma: no cover
    """The chest's rotation since ``x0`` into ``rot [3, 3]``: the swing of the spine bone
    from ``x0`` to ``y``; then (``free``) the twist about that bone, and a tilt of at most
    :data:`TILT`, that best turn the collars (ranks, weights ``w``) towards ``pts`` around
    ``y``'s ``spine2`` (their forward proposals)."""
    a0, a1, t = np.empty(3), np.empty(3), np.empty((3, 3))
    for c in range(3):
        a0[c] = x0[SPINE2, c] - x0[SPINE1, c]
        a1[c] = y[SPINE2, c] - y[SPINE1, c]
    _swing(a0, a1, np.pi, rot)
    n1 = np.sqrt(a1[0] * a1[0] + a1[1] * a1[1] + a1[2] * a1[2])
    if not free or n1 <= TINY:
        return
    k0, k1, k2 = a1[0] / n1, a1[1] / n1, a1[2] / n1
    num, den = 0.0, 0.0
    for i in range(FIT.shape[0]):
        k, wk = FIT[i], w[FIT_WEIGHT[i]]
        if not (w[k] > 0.0 and wk > 0.0):
            continue
        o0, o1, o2 = x0[k, 0] - x0[SPINE2, 0], x0[k, 1] - x0[SPINE2, 1], x0[k, 2] - x0[SPINE2, 2]
        u0 = (rot[0, 0] * o0 + rot[0, 1] * o1) + rot[0, 2] * o2
        u1 = (rot[1, 0] * o0 + rot[1, 1] * o1) + rot[1, 2] * o2
        u2 = (rot[2, 0] * o0 + rot[2, 1] * o1) + rot[2, 2] * o2
        d0, d1, d2 = pts[k, 0] - y[SPINE2, 0], pts[k, 1] - y[SPINE2, 1], pts[k, 2] - y[SPINE2, 2]
        au = k0 * u0 + k1 * u1 + k2 * u2
        ad = k0 * d0 + k1 * d1 + k2 * d2
        num += wk * (k0 * (u1 * d2 - u2 * d1) + k1 * (u2 * d0 - u0 * d2) + k2 * (u0 * d1 - u1 * d0))
        den += wk * ((u0 * d0 + u1 * d1 + u2 * d2) - au * ad)
    if num != 0.0:  # Rodrigues: I + s [k]x + (1 - cos) [k]x^2
        phi = np.arctan2(num, den)
        s, c1 = np.sin(phi), 1.0 - np.cos(phi)
        t[0, 0], t[0, 1], t[0, 2] = (
            1.0 - c1 * (k1 * k1 + k2 * k2),
            -s * k2 + c1 * k0 * k1,
            s * k1 + c1 * k0 * k2,
        )
        t[1, 0], t[1, 1], t[1, 2] = (
            s * k2 + c1 * k1 * k0,
            1.0 - c1 * (k0 * k0 + k2 * k2),
            -s * k0 + c1 * k1 * k2,
        )
        t[2, 0], t[2, 1], t[2, 2] = (
            -s * k1 + c1 * k2 * k0,
            s * k0 + c1 * k2 * k1,
            1.0 - c1 * (k0 * k0 + k1 * k1),
        )
        _times(t, rot)
    co, cd = np.zeros(3), np.zeros(3)
    for i in range(FIT.shape[0]):
        k, wk = FIT[i], w[FIT_WEIGHT[i]]
        if not (w[k] > 0.0 and wk > 0.0):
            continue
        o0, o1, o2 = x0[k, 0] - x0[SPINE2, 0], x0[k, 1] - x0[SPINE2, 1], x0[k, 2] - x0[SPINE2, 2]
        for c in range(3):
            co[c] += wk * ((rot[c, 0] * o0 + rot[c, 1] * o1) + rot[c, 2] * o2)
            cd[c] += wk * (pts[k, c] - y[SPINE2, c])
    _swing(co, cd, TILT, t)
    _times(t, rot)


@jit
def place(x0: F64, y: F64, kid: int, rot: F64) -> None:  # pragma: no cover - compiled
    """``y[kid] = y[spine2] + rot (x0[kid] - x0[spine2])`` (a chest child, rigid)."""
    o0, o1, o2 = x0[kid, 0] - x0[SPINE2, 0], x0[kid, 1] - x0[SPINE2, 1], x0[kid, 2] - x0[SPINE2, 2]
    for c in range(3):
        y[kid, c] = y[SPINE2, c] + ((rot[c, 0] * o0 + rot[c, 1] * o1) + rot[c, 2] * o2)


@jit
def cone(x0: F64, kid: int, rot: F64, u: F64) -> bool:  # pragma: no cover - compiled
    """The unit clavicle direction ``u`` of shoulder ``kid`` (rank) kept within
    :data:`CLAVICLE_CONE` (or the start's own angle, if wider) of the chest's across axis,
    in place; False where it was (``u`` untouched)."""
    side = 1.0 if kid == L_SHOULDER else -1.0
    col = L_COLLAR if kid == L_SHOULDER else R_COLLAR
    e0 = side * (x0[L_COLLAR, 0] - x0[R_COLLAR, 0])
    e1 = side * (x0[L_COLLAR, 1] - x0[R_COLLAR, 1])
    e2 = side * (x0[L_COLLAR, 2] - x0[R_COLLAR, 2])
    ne = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    c0, c1, c2 = x0[kid, 0] - x0[col, 0], x0[kid, 1] - x0[col, 1], x0[kid, 2] - x0[col, 2]
    nc = np.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    if nc <= TINY:
        return False
    limit = np.cos(CLAVICLE_CONE)
    if ne > TINY:  # the start's own angle, where wider
        limit = min(limit, (e0 * c0 + e1 * c1 + e2 * c2) / (ne * nc))
        e0, e1, e2 = e0 / ne, e1 / ne, e2 / ne
    else:  # collars on one point: the start's clavicle is the axis
        e0, e1, e2 = c0 / nc, c1 / nc, c2 / nc
    m0 = (rot[0, 0] * e0 + rot[0, 1] * e1) + rot[0, 2] * e2
    m1 = (rot[1, 0] * e0 + rot[1, 1] * e1) + rot[1, 2] * e2
    m2 = (rot[2, 0] * e0 + rot[2, 1] * e1) + rot[2, 2] * e2
    cu = m0 * u[0] + m1 * u[1] + m2 * u[2]
    if cu >= limit:
        return False
    p0, p1, p2 = u[0] - cu * m0, u[1] - cu * m1, u[2] - cu * m2
    n = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    if n <= TINY:  # straight back along the axis: towards the start's clavicle
        q0 = (rot[0, 0] * c0 + rot[0, 1] * c1) + rot[0, 2] * c2
        q1 = (rot[1, 0] * c0 + rot[1, 1] * c1) + rot[1, 2] * c2
        q2 = (rot[2, 0] * c0 + rot[2, 1] * c1) + rot[2, 2] * c2
        cq = m0 * q0 + m1 * q1 + m2 * q2
        p0, p1, p2 = q0 - cq * m0, q1 - cq * m1, q2 - cq * m2
        n = np.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        if n <= TINY:
            u[0], u[1], u[2] = m0, m1, m2
            return True
    sn = np.sqrt(max(1.0 - limit * limit, 0.0))
    u[0] = limit * m0 + sn * p0 / n
    u[1] = limit * m1 + sn * p1 / n
    u[2] = limit * m2 + sn * p2 / n
    return True


@jit
def applies(ranks: npt.NDArray[np.int64]) -> bool:  # pragma: no cover - compiled
    """:func:`core.chest.applies` of a target set's ranks."""
    for r in ranks:
        for k in FIT:
            if r == k:
                return False
    return True


@jit
def _gap(p: F64, a: int, b: int) -> float:  # pragma: no cover - compiled
    d0, d1, d2 = p[a, 0] - p[b, 0], p[a, 1] - p[b, 1], p[a, 2] - p[b, 2]
    out: float = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return out


@jit
def kept(x0: F64, x: F64) -> bool:  # pragma: no cover - compiled
    """:func:`core.chest.kept` for one answer ``x`` of ``x0`` (``[21, 3]``, ranks)."""
    span0, span = _gap(x0, L_COLLAR, R_COLLAR), _gap(x, L_COLLAR, R_COLLAR)
    width0, width = _gap(x0, L_SHOULDER, R_SHOULDER), _gap(x, L_SHOULDER, R_SHOULDER)
    return bool(abs(span - span0) <= SPAN * span0) and bool(width >= WIDTH * width0)
