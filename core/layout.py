"""The internal layout of :mod:`core.kinematics` and :mod:`core.chest`: poses joint-first
and depth-ordered, ``[21, 3, N]`` (N the flattened batch), and the conversions to and from
``[..., 21, 3]``. Every name is the kinematics module's own (it imports them).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from core.rest import REST_DIRS
from core.shells import TINY as _TINY
from core.shells import norm3 as _norm3
from core.skeleton import BONE_CHILDREN, DEPTH, NUM_JOINTS, PARENTS

F64 = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

_ROOT = PARENTS.index(-1)
_MAX_DEPTH = max(DEPTH)

#: Bone index (position in ``BONES`` / the ``lengths`` axis) of each non-root joint.
_BONE_OF: dict[int, int] = {int(c): b for b, c in enumerate(BONE_CHILDREN)}

# --------------------------------------------------------------------------------------
# Internal layout
# --------------------------------------------------------------------------------------
# Inside, poses are joint-first and depth-ordered: ``[21, 3, N]`` (N = flattened batch),
# rank r holding joint ``_ORDER[r]``. Every depth level is then a contiguous slice, the
# per-level work is a handful of ufunc calls on contiguous blocks, and the batch is the
# fastest axis. Lengths are ``[20, N]`` (or ``[20, 1]`` when shared), row ``r - 1``
# holding the bone that ends at rank ``r``.

#: Joints sorted by depth (stable): the internal order. ``_RANK`` is its inverse.
_ORDER: IntArray = np.argsort(np.asarray(DEPTH), kind="stable").astype(np.intp)
_RANK: IntArray = np.argsort(_ORDER, kind="stable").astype(np.intp)
_ROOT_RANK = int(_RANK[_ROOT])
if _ROOT_RANK != 0:  # pragma: no cover - PARENTS has exactly one root at depth 0
    raise RuntimeError("the root must be the only joint at depth 0")
#: Bone index (``lengths`` axis) of the bone ending at each rank 1..20.
_LEN_ORDER: IntArray = np.asarray([_BONE_OF[int(j)] for j in _ORDER[1:]], dtype=np.intp)
#: Rank of the parent of each rank (-1 for the root).
_PARENT_RANK: IntArray = np.asarray(
    [-1 if PARENTS[int(j)] < 0 else int(_RANK[PARENTS[int(j)]]) for j in _ORDER], dtype=np.intp
)


def _depth_slices() -> tuple[tuple[int, int, IntArray], ...]:
    out = []
    depth = np.asarray(DEPTH)[_ORDER]
    for d in range(1, _MAX_DEPTH + 1):
        ranks = np.flatnonzero(depth == d)
        start, stop = int(ranks[0]), int(ranks[-1]) + 1
        out.append((start, stop, _PARENT_RANK[start:stop].copy()))
    return tuple(out)


#: Per depth level 1..max: (first rank, end rank, parent ranks).
_SLICES = _depth_slices()
#: Rest-pose unit bone directions per rank 1..20, ``[20, 3, 1]``.
_REST_DIRS_I: F64 = np.ascontiguousarray(REST_DIRS[_ORDER[1:]][:, :, None])
_REST_DIRS_I.flags.writeable = False


def _as_float64(a: npt.ArrayLike) -> F64:
    return np.asarray(a, dtype=np.float64)


def _out_dtype(a: npt.ArrayLike) -> np.dtype[np.floating[Any]]:
    dt = np.asarray(a).dtype
    if np.issubdtype(dt, np.floating):
        return np.dtype(dt.type)
    return np.dtype(np.float64)


def _to_internal(a: F64, batch: tuple[int, ...]) -> F64:
    """``[*batch, J, 3]`` (broadcastable) -> ``[J, 3, N]`` in internal (rank) order,
    always a fresh array."""
    if a.ndim == 2 and not batch:
        return a.take(_ORDER, axis=0)[:, :, None]
    flat = np.broadcast_to(a, (*batch, NUM_JOINTS, 3)).reshape(-1, NUM_JOINTS, 3)
    if flat.shape[0] == 1:
        return np.ascontiguousarray(flat[0][_ORDER][:, :, None])
    if flat.shape[0] <= 64:
        return np.ascontiguousarray(flat.transpose(1, 2, 0)[_ORDER])
    # Large batches: one destination filled joint by joint (numpy's gathers from a
    # transposed view are an order of magnitude slower than these strided copies).
    out = np.empty((NUM_JOINTS, 3, flat.shape[0]))
    for rank, joint in enumerate(_ORDER.tolist()):
        np.copyto(out[rank], flat[:, joint, :].T)
    return out


def _from_internal(x: F64, batch: tuple[int, ...]) -> F64:
    """Inverse of :func:`_to_internal` (a view for batches: the batch axis is inside)."""
    y = x[_RANK]
    if y.shape[-1] == 1:
        return y.reshape(*batch, NUM_JOINTS, 3)
    return np.moveaxis(y, -1, 0).reshape(*batch, NUM_JOINTS, 3)


def _lengths_internal(lens: F64, batch: tuple[int, ...]) -> F64:
    """``[..., 20]`` -> ``[20, N]`` in rank order (``[20, 1]`` when shared)."""
    if lens.ndim == 1:
        return np.ascontiguousarray(lens[_LEN_ORDER][:, None])
    flat = np.broadcast_to(lens, (*batch, NUM_JOINTS - 1)).reshape(-1, NUM_JOINTS - 1)
    return np.ascontiguousarray(flat[:, _LEN_ORDER].T)


def _cross3(a: F64, b: F64) -> F64:
    ax, ay, az = a[:, 0], a[:, 1], a[:, 2]
    bx, by, bz = b[:, 0], b[:, 1], b[:, 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=1)


def _unit_or(v: F64, *fallbacks: F64) -> F64:
    """Unit ``v`` over axis 1; the first usable fallback where ``v`` has no direction
    (zero, or too short to invert). The last fallback must be unit (or zero)."""
    n = _norm3(v)
    ok = n > _TINY
    u: F64 = v / np.where(ok, n, 1.0)[:, None]
    if not fallbacks or bool(ok.all()):
        return u
    return np.where(ok[:, None], u, _unit_or(*fallbacks))
