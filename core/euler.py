"""Intrinsic Euler rotations, as BVH channels list them: matrices from angles
(:func:`euler_matrices`, any sequence of axes) and back (:func:`euler_angles`, three axes).
Moved out of ``core.bvh`` unchanged (numpy only, like it)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

_AXIS = {"X": 0, "Y": 1, "Z": 2}


def axis_rotations(axis: str, radians: FloatArray) -> FloatArray:
    """Rotation matrices ``[..., 3, 3]`` about ``axis`` ("X", "Y" or "Z") by ``radians``:
    1 at ``[i, i]`` for the axis ``i``, ``c -s / s c`` in the other two rows and columns,
    in cyclic order (filled in place: a character solve builds hundreds of these one by
    one, and stacking nine arrays cost more than the trigonometry)."""
    if axis not in _AXIS:
        raise ValueError(f"unknown rotation axis {axis!r}")
    i = _AXIS[axis]
    j, k = (i + 1) % 3, (i + 2) % 3
    c, s = np.cos(radians), np.sin(radians)
    out = np.zeros((*np.shape(c), 3, 3), dtype=np.result_type(c))
    out[..., i, i] = 1.0
    out[..., j, j] = c
    out[..., j, k] = -s
    out[..., k, j] = s
    out[..., k, k] = c
    return out


def euler_matrices(seq: str, radians: FloatArray) -> FloatArray:
    """Intrinsic Euler rotations ``R = R_seq[0] @ R_seq[1] @ ...`` as ``[..., 3, 3]``.

    ``radians[..., k]`` is the angle about axis ``seq[k]`` (any length, repeats allowed: the
    BVH channel order as written).
    """
    if radians.shape[-1] != len(seq):
        raise ValueError(f"{len(seq)} angles expected for {seq!r}, got {radians.shape[-1]}")
    out = axis_rotations(seq[0], radians[..., 0])
    for k in range(1, len(seq)):
        out = np.matmul(out, axis_rotations(seq[k], radians[..., k]))
    return out


def invertible_order(seq: str) -> bool:
    """Whether :func:`euler_angles` inverts ``seq``: three axes, none twice in a row (a
    BVH joint whose rotation channels repeat an axis in a row, ``Xrotation Xrotation
    Yrotation``, has no unique angles to write back)."""
    return len(seq) == 3 and seq[0] != seq[1] and seq[1] != seq[2] and set(seq) <= set(_AXIS)


def euler_angles(seq: str, matrices: FloatArray) -> FloatArray:
    """The inverse of :func:`euler_matrices` for three axes: ``[..., 3, 3]`` -> radians
    ``[..., 3]`` with ``R = R_seq[0](a) @ R_seq[1](b) @ R_seq[2](c)``.

    ``seq`` is Tait-Bryan (``"ZXY"``: three different axes, ``b`` in [-90, 90] degrees) or
    proper Euler (``"ZXZ"``, ``b`` in [0, 180]); ``a`` and ``c`` lie in [-180, 180]. In
    gimbal lock (``b`` at a bound) only ``a + c`` or ``a - c`` is defined: ``c`` is 0 then.
    """
    if not invertible_order(seq):
        raise ValueError(f"an Euler sequence of three axes, none twice in a row, expected: {seq!r}")
    m = np.asarray(matrices, dtype=np.float64)
    i, j = _AXIS[seq[0]], _AXIS[seq[1]]
    k = 3 - i - j  # the axis not in (i, j)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # +1 when (i, j, k) is a cyclic order of (X, Y, Z)
    if seq[0] != seq[2]:  # Tait-Bryan: R[i, k] = s sin b
        cos_b = np.hypot(m[..., i, i], m[..., i, j])
        b = np.arctan2(s * m[..., i, k], cos_b)
        a = np.arctan2(-s * m[..., j, k], m[..., k, k])
        c = np.arctan2(-s * m[..., i, j], m[..., i, i])
        locked = cos_b < 1e-7
    else:  # proper: R[i, i] = cos b
        sin_b = np.hypot(m[..., i, j], m[..., i, k])
        b = np.arctan2(sin_b, m[..., i, i])
        a = np.arctan2(m[..., j, i], -s * m[..., k, i])
        c = np.arctan2(m[..., i, j], s * m[..., i, k])
        locked = sin_b < 1e-7
    # Column j of R is R_i(a) e_j whatever b is: with c = 0 it alone gives a.
    a = np.where(locked, np.arctan2(s * m[..., k, j], m[..., j, j]), a)
    c = np.where(locked, 0.0, c)
    return np.stack([a, b, c], axis=-1)
