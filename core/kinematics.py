"""Exact bone lengths and full-body FABRIK over ``[..., 21, 3]`` joint positions.

Everything here is numpy-only, batched over leading axes, float64 inside, stateless and
deterministic (same input, bit-identical output). The skeleton topology comes from
:mod:`core.skeleton` only: chains, sub-bases and depth levels are derived from
``PARENTS``; no joint index is hard-coded.

* :func:`bone_pass` -- the FABRIK backward step over the whole tree, root outwards:
  restores exact bone lengths while keeping every bone's direction as seen from its
  (already corrected) parent.
* :func:`fabrik` -- full-body multi-end-effector FABRIK (Aristidou & Lasenby 2011;
  Aristidou, Chrysanthou & Lasenby 2016): targets on any joints, sub-bases at the
  centroid of their chains' proposals, untargeted branches carried rigidly.
* :func:`polish` -- the "exact reach" mode: FABRIK from a good pose that first only
  lets the chains below the nearest branching joints move, and unlocks the trunk only
  when that is not enough.
* :func:`rest_pose` -- a canonical T-pose (metres), the fallback for degenerate bones.

See ``docs/kinematics.md`` for the algorithms and policies.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from core.rest import REST_DIRS
from core.rigid import PAIRS
from core.shells import TINY as _TINY
from core.shells import Shells, above_pins, clamp_root, hold_targets, onto_pins, pin_mask, shells
from core.shells import dot3 as _dot3
from core.shells import norm3 as _norm3
from core.skeleton import BONE_CHILDREN, DEPTH, NUM_JOINTS, PARENTS, TRUNK

F64 = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]

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

#: Ranks of the hips (``core.rigid.PAIRS``), children of the root: with ``rigid_hips`` the
#: ones no target is on move with the pelvis, translated (``_Plan.rigid``; docs/kinematics.md).
_RIGID: BoolArray = np.isin(np.arange(NUM_JOINTS), _RANK[PAIRS[0, 1:]])


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


# --------------------------------------------------------------------------------------
# Bone pass
# --------------------------------------------------------------------------------------


def bone_pass(
    positions: npt.ArrayLike,
    lengths: npt.ArrayLike,
    *,
    reference: npt.ArrayLike | None = None,
) -> npt.NDArray[np.floating[Any]]:
    """Give every bone its exact length: the FABRIK backward step, root outwards.

    ``positions`` ``[..., 21, 3]``; ``lengths`` ``[..., 20]`` in ``BONES`` order
    (broadcastable, e.g. ``[20]``). The root keeps its position. Then, one depth level
    at a time (parents before children, all bones of a level at once), each joint is put
    at ``parent_new + length * unit(child_old - parent_new)``: the direction from the
    parent's *new* position to the child's current position, exactly FABRIK's backward
    (root-to-leaves) reaching step. A pose whose lengths are already right comes back
    unchanged up to rounding.

    A degenerate direction (the child exactly on its new parent) falls back to the
    bone's direction in ``reference`` (a pose broadcastable to ``positions``) if
    given and non-degenerate there, else to its direction in :func:`rest_pose`, so the
    output is finite for finite input.

    Computed in float64; returned in the input's floating dtype (float64 for integer
    input). For batched input the result may be a non-contiguous view.
    """
    given = np.asarray(positions)
    out_dtype = given.dtype if given.dtype.kind == "f" else np.dtype(np.float64)
    src = given.astype(np.float64, copy=False)
    lens = np.asarray(lengths, dtype=np.float64)
    if src.ndim < 2 or src.shape[-2:] != (NUM_JOINTS, 3):
        raise ValueError(f"positions must be [..., {NUM_JOINTS}, 3], got {src.shape}")
    if lens.ndim < 1 or lens.shape[-1] != NUM_JOINTS - 1:
        raise ValueError(f"lengths must be [..., {NUM_JOINTS - 1}], got {lens.shape}")
    if reference is None and src.ndim == 2 and lens.ndim == 1:  # one pose: shortest path
        x = src.take(_ORDER, axis=0)[:, :, None]
        if not _bone_pass_fast(x, lens[_LEN_ORDER][:, None]):
            x = _bone_pass_safe(
                src.take(_ORDER, axis=0)[:, :, None], lens[_LEN_ORDER][:, None], None
            )
        return x.take(_RANK, axis=0).reshape(NUM_JOINTS, 3).astype(out_dtype, copy=False)
    ref = None if reference is None else _as_float64(reference)
    shapes = [src.shape[:-2], lens.shape[:-1]] + ([] if ref is None else [ref.shape[:-2]])
    batch = () if len(shapes) == 2 and src.ndim == 2 and lens.ndim == 1 else None
    batch = np.broadcast_shapes(*shapes) if batch is None else batch
    x = _bone_pass_internal(
        _to_internal(src, batch),
        _lengths_internal(lens, batch),
        lambda: _to_internal(src, batch),
        lambda: None if ref is None else _to_internal(ref, batch),
    )
    return _from_internal(x, batch).astype(out_dtype, copy=False)


_WIDEST = max(stop - start for start, stop, _ in _SLICES)


def _bone_pass_internal(
    src: F64, lens: F64, rebuild: Callable[[], F64], ref: Callable[[], F64 | None]
) -> F64:
    """Bone pass on internal arrays, root kept. ``src`` is consumed: the fast path works
    in place (each level reads its joints' old positions just before overwriting them),
    so large batches allocate little; if a direction was undefined, ``rebuild()`` gives
    ``src`` again for the safe path, with fallback directions from ``ref()``."""
    if _bone_pass_fast(src, lens):
        return src
    return _bone_pass_safe(rebuild(), lens, ref())


def _bone_pass_fast(x: F64, lens: F64) -> bool:
    """In-place bone pass without fallbacks; False if a direction was undefined."""
    lens3 = lens[:, None]
    n_pose = x.shape[-1]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if n_pose <= 64:  # few poses: fewest ufunc calls
            for start, stop, parents in _SLICES:
                par = x.take(parents, axis=0)
                d = x[start:stop] - par
                n = np.sqrt(np.add.reduce(d * d, axis=1, keepdims=True))
                x[start:stop] = par + d * (lens3[start - 1 : stop - 1] / n)
        else:  # large batches: scratch reused by every level, allocated (and faulted) once
            par_buf = np.empty((_WIDEST, 3, n_pose))
            sq_buf = np.empty((_WIDEST, 3, n_pose))
            len_buf = np.empty((_WIDEST, n_pose))
            for start, stop, parents in _SLICES:
                k = stop - start
                par = np.take(x, parents, axis=0, out=par_buf[:k])
                d = np.subtract(x[start:stop], par, out=x[start:stop])
                n = np.add.reduce(np.multiply(d, d, out=sq_buf[:k]), axis=1, out=len_buf[:k])
                scale = np.divide(lens[start - 1 : stop - 1], np.sqrt(n, out=n), out=n)
                np.add(par, np.multiply(d, scale[:, None], out=d), out=d)
    return bool(np.isfinite(np.add.reduce(x, axis=None)))


def _bone_pass_safe(src: F64, lens: F64, ref: F64 | None) -> F64:
    """Bone pass with per-bone fallbacks for undefined directions (not in place)."""
    x = np.empty_like(src)
    x[0] = src[0]
    fallback = _REST_DIRS_I
    if ref is not None:
        fallback = _unit_or(ref[1:] - ref[_PARENT_RANK[1:]], _REST_DIRS_I)
    for start, stop, parents in _SLICES:
        par = x[parents]
        u = _unit_or(src[start:stop] - par, fallback[start - 1 : stop - 1])
        x[start:stop] = par + u * lens[start - 1 : stop - 1, None]
    return x


# --------------------------------------------------------------------------------------
# FABRIK
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FabrikResult:
    """Outcome of :func:`fabrik` / :func:`polish` (batch shape ``[...]``, K targets).

    ``positions`` ``[..., 21, 3]`` with exact bone lengths (input floating dtype);
    ``iterations`` FABRIK iterations run (max over the batch); ``errors`` ``[..., K]``
    distance (m) of each targeted joint to its target; ``reached`` ``[..., K]``
    ``errors <= tolerance``; ``converged`` ``[...]`` the iteration settled before
    ``max_iterations`` (every target reached, or no more progress: the closest feasible
    stretch). ``converged`` with some ``reached`` False means "unreachable, best effort".
    """

    positions: npt.NDArray[np.floating[Any]]
    iterations: int
    errors: F64
    reached: BoolArray
    converged: BoolArray


@dataclass(frozen=True)
class _Forward:
    kids: IntArray  # ranks of active joints whose parent needs a proposal
    parents: IntArray
    rows: IntArray  # ranks of those parents (unique, sorted)
    mix: F64 | None  # [rows, kids] weighted-centroid matrix; None: one kid per row


@dataclass(frozen=True)
class _Plan:
    """Per-call topology of a solve, in ranks: which joints move and how."""

    target_ranks: IntArray  # [K]
    targeted: IntArray  # unique targeted ranks
    joint_targets: F64  # [len(targeted), K]: per joint, weighted mean of its targets
    root_moves: bool  # the root is targeted or free
    root_free: bool  # the root goes to the centroid of its branches
    forward: tuple[_Forward, ...]  # deepest first
    backward: tuple[tuple[IntArray, IntArray, slice | IntArray], ...]  # per depth, root
    # outwards: active ranks, their parents, and where to write them (a slice if a run)
    carried_joints: IntArray  # ranks the iteration leaves alone
    carried_anchors: IntArray  # the moving rank each one's branch hangs from (or 0)
    path: F64  # [K, 20] bones (rank - 1) between the root and each target
    rigid: BoolArray  # [21] with rigid_hips, the ranks of _RIGID no target or pin is on
    shell_top: IntArray  # [K] the rigid hip on each target's chain, or 0; its shell's chain:
    shell_path: F64  # [K, 20] ``path`` less that hip's bone (centred the hip's offset off)


def _make_plan(
    target_idx: IntArray,
    weights: F64,
    locked: frozenset[int],
    free_root: bool,
    pinned: BoolArray | None = None,
    rigid_hips: bool = False,
) -> _Plan:
    """``locked`` joints are held in place; callers lock whole ancestor lines only.

    ``pinned`` (K booleans): a sub-base other than the root with a pin on or below one of
    its moving chains takes the centroid of those chains alone, so a far target on a
    sibling chain cannot pull a pinned neck, head or arm off its pin (the root keeps the
    centroid of all its branches, kept within reach of the pins: :mod:`core.shells`).
    """
    k = len(target_idx)
    ranks = _RANK[target_idx]
    targeted = np.unique(ranks)
    joint_targets = np.zeros((len(targeted), k))
    joint_targets[np.searchsorted(targeted, ranks), np.arange(k)] = weights
    joint_targets /= joint_targets.sum(axis=1, keepdims=True)
    parent_of: list[int] = _PARENT_RANK.tolist()
    is_target = [False] * NUM_JOINTS
    for r in targeted.tolist():
        is_target[r] = True
    locked_ranks = {int(_RANK[j]) for j in locked}

    # A joint moves if a target on or below it reaches it without crossing a lock; its
    # weight in a sub-base centroid is the total weight of those targets.
    active = [False] * NUM_JOINTS
    weight = [0.0] * NUM_JOINTS
    pin_weight = [0.0] * NUM_JOINTS
    pins = [False] * k if pinned is None else pinned.tolist()
    path = np.zeros((k, NUM_JOINTS - 1))
    for t, (r0, w) in enumerate(zip(ranks.tolist(), weights.tolist(), strict=True)):
        r = r0
        while r != 0:
            path[t, r - 1] = 1.0
            r = parent_of[r]
        r = r0
        while r != 0 and (r == r0 or r not in locked_ranks):
            active[r] = True
            weight[r] += w
            pin_weight[r] += w if pins[t] else 0.0
            r = parent_of[r]

    root_targeted = is_target[0]
    branches = sum(1 for r in range(1, NUM_JOINTS) if parent_of[r] == 0 and active[r])
    root_free = free_root and not root_targeted and 0 not in locked_ranks and branches >= 2

    def needs_proposal(r: int) -> bool:
        return root_free if r == 0 else active[r] and not is_target[r]

    forward = []
    for start, stop, _ in reversed(_SLICES):
        kids = [r for r in range(start, stop) if active[r] and needs_proposal(parent_of[r])]
        if not kids:
            continue
        parents = [parent_of[r] for r in kids]
        rows = sorted(set(parents))
        mix = None
        if len(rows) < len(kids):  # a sub-base: weighted centroid of its chains
            held = {p for r, p in zip(kids, parents, strict=True) if p != 0 and pin_weight[r]}
            mix = np.zeros((len(rows), len(kids)))
            for col, (r, p) in enumerate(zip(kids, parents, strict=True)):
                mix[rows.index(p), col] = pin_weight[r] if p in held else weight[r]
            mix /= mix.sum(axis=1, keepdims=True)
        forward.append(
            _Forward(
                np.asarray(kids, dtype=np.intp),
                np.asarray(parents, dtype=np.intp),
                np.asarray(rows, dtype=np.intp),
                mix,
            )
        )

    backward: list[tuple[IntArray, IntArray, slice | IntArray]] = []
    for start, stop, _ in _SLICES:
        moving = [r for r in range(start, stop) if active[r]]
        if moving:
            kids_a = np.asarray(moving, dtype=np.intp)
            run = moving[-1] - moving[0] + 1 == len(moving)
            where: slice | IntArray = slice(moving[0], moving[-1] + 1) if run else kids_a
            backward.append((kids_a, _PARENT_RANK[kids_a], where))

    # Joints the iteration does not move are carried afterwards, each branch as a rigid
    # body hanging from the moving joint it is attached to (its anchor; the root for the
    # trunk and branches off the root).
    anchor = list(range(NUM_JOINTS))
    for r in range(1, NUM_JOINTS):
        p = parent_of[r]
        if not active[r]:
            anchor[r] = p if (active[p] or p == 0) else anchor[p]
    still = [r for r in range(1, NUM_JOINTS) if not active[r]]
    rigid = _RIGID & ~np.isin(np.arange(NUM_JOINTS), targeted) & rigid_hips
    tops = np.flatnonzero(rigid)
    on = path[:, tops - 1] > 0  # [K, len(tops)]: the target hangs from that rigid hip
    shell_path = path.copy()
    shell_path[:, tops - 1] = 0.0
    return _Plan(
        target_ranks=ranks,
        targeted=targeted,
        rigid=rigid,
        shell_top=(on * tops).sum(axis=1).astype(np.intp),
        shell_path=shell_path,
        joint_targets=joint_targets,
        root_moves=root_targeted or root_free,
        root_free=root_free,
        forward=tuple(forward),
        backward=tuple(backward),
        carried_joints=np.asarray(still, dtype=np.intp),
        carried_anchors=np.asarray([anchor[r] for r in still], dtype=np.intp),
        path=path,
    )


def _swing(a: F64, b: F64, v: F64) -> F64:
    """Rotate ``v`` by the minimal rotation taking direction ``a`` to ``b`` (axis 1).

    Identity where ``a`` and ``b`` are equal or degenerate.
    """
    zero = np.zeros((1, 3, 1))
    au = _unit_or(a, zero)
    bu = _unit_or(b, zero)
    c = _dot3(au, bu)
    w = _cross3(au, bu)
    scale = _dot3(w, v) / np.maximum(1.0 + c, 1e-12)
    rotated = c[:, None] * v + _cross3(w, v) + w * scale[:, None]
    same = np.all(a == b, axis=1) | ~np.any(au != 0.0, axis=1) | ~np.any(bu != 0.0, axis=1)
    return np.where(same[:, None], v, rotated)


def _iterate(
    x: F64,
    proposal: F64,
    plan: _Plan,
    lengths: _LevelLengths,
    clamp: Shells | None,
    safe: bool,
    frozen: BoolArray | None = None,
) -> F64:
    """One FABRIK iteration (forward then backward reaching); returns the new pose.

    ``proposal`` is scratch holding the fixed targets; the fast path lets undefined
    directions produce non-finite values, the caller then reruns with ``safe``.
    ``frozen`` ``[N]``: items whose moving root stays where it is.
    """
    # Forward reaching: from the targeted joints towards the (sub-)bases.
    for fw, length in zip(plan.forward, lengths.forward, strict=True):
        pc = proposal.take(fw.kids, axis=0)
        toward = x.take(fw.parents, axis=0) - pc
        if safe:
            back = x.take(fw.parents, axis=0) - x.take(fw.kids, axis=0)
            u = _unit_or(toward, back, -_REST_DIRS_I.take(fw.kids - 1, axis=0))
            q = pc + u * length
        else:
            q = pc + toward * (length / _norm3(toward)[:, None])
        rigid = plan.rigid[fw.kids]
        if rigid.any():  # a rigid hip: the root where its offset puts it
            q[rigid] = proposal[fw.kids[rigid]] - (x[fw.kids[rigid]] - x[0])
        if fw.mix is None:
            proposal[fw.parents] = q
        else:
            n = q.shape[-1]
            proposal[fw.rows] = (fw.mix @ q.reshape(len(fw.kids), -1)).reshape(-1, 3, n)
    if clamp is not None:  # the free root: centroid, kept within reach of the pins
        proposal[0] = clamp_root(proposal[0], clamp)
    # Backward reaching: from the root outwards, every active bone exact again.
    y = x.copy()
    if plan.root_moves:
        y[0] = proposal[0] if frozen is None else np.where(frozen[None], x[0], proposal[0])
    for (kids, parents, where), length in zip(plan.backward, lengths.backward, strict=True):
        par = y.take(parents, axis=0)
        toward = proposal.take(kids, axis=0) - par
        if safe:
            bone = x.take(kids, axis=0) - x.take(parents, axis=0)
            u = _unit_or(toward, bone, _REST_DIRS_I.take(kids - 1, axis=0))
            y[where] = par + u * length
        else:
            y[where] = par + toward * (length / _norm3(toward)[:, None])
        rigid = plan.rigid[kids]
        if rigid.any():  # a rigid hip: moved with the root
            y[kids[rigid]] = y[0] + (x[kids[rigid]] - x[0])
    return y


@dataclass(frozen=True)
class _LevelLengths:
    """Bone lengths gathered per plan level once per solve, ``[k, 1, N]`` each."""

    forward: tuple[F64, ...]
    backward: tuple[F64, ...]


def _level_lengths(lens: F64, plan: _Plan) -> _LevelLengths:
    return _LevelLengths(
        forward=tuple(lens.take(fw.kids - 1, axis=0)[:, None] for fw in plan.forward),
        backward=tuple(lens.take(k - 1, axis=0)[:, None] for k, _, _ in plan.backward),
    )


@dataclass(frozen=True)
class _Solved:
    x: F64  # internal [21, 3, N]
    iterations: int
    errors: F64  # [K, N]
    converged: BoolArray  # [N]


def _solve(
    x0: F64,
    lens: F64,
    tpos: F64,
    plan: _Plan,
    tolerance: float,
    max_iterations: int,
    pinned: BoolArray | None = None,
) -> _Solved:
    """Multi-end-effector FABRIK on internal arrays from ``x0`` (exact lengths)."""
    stall = tolerance * 1e-3
    hold = pinned if pinned is not None and bool(np.any(pinned)) else None
    # the pins wherever the start put them (chains of any length)
    pins = None if hold is None else hold[:, None] & (plan.path @ lens > 0)
    centres = tpos - (x0[plan.shell_top] - x0[0][None])  # less a rigid hip's offset
    if pins is not None and not plan.root_moves:
        x0 = onto_pins(x0, shells(plan.shell_path, lens, x0[0], centres, pins, True))
    x = x0
    errors = _norm3(x.take(plan.target_ranks, axis=0) - tpos)
    done = np.all(errors <= tolerance, axis=0)
    converged = done.copy()

    proposal = x0.copy()
    k = len(plan.target_ranks)
    joint_t = (plan.joint_targets @ tpos.reshape(k, -1)).reshape(len(plan.targeted), 3, -1)
    proposal[plan.targeted] = joint_t
    clamp = None
    if plan.root_free or (pins is not None and plan.root_moves):
        anchors = errors <= tolerance if pins is None else pins
        clamp = shells(plan.shell_path, lens, x0[0], centres, anchors, pins is not None)

    level_lengths = _level_lengths(lens, plan)
    strikes = np.zeros(x0.shape[-1], dtype=np.intp)
    frozen = (
        np.zeros(x0.shape[-1], dtype=np.bool_) if pins is not None and plan.root_moves else None
    )
    above = [] if hold is None else above_pins(plan.targeted, plan.target_ranks, plan.path, hold)
    iterations = 0
    while iterations < max_iterations and not bool(np.all(done)):
        iterations += 1
        if above:  # a target above a pin: as far as the pin allows
            hold_targets(proposal, joint_t, above, plan.path, lens, tpos, x[0])
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            y = _iterate(x, proposal, plan, level_lengths, clamp, False, frozen)
        if not np.isfinite(np.add.reduce(y, axis=None)):
            y = _iterate(x, proposal, plan, level_lengths, clamp, True, frozen)
        if done.any():  # finished poses of a batch keep their answer
            y = np.where(done[None, None], x, y)
        x = y
        new_errors = _norm3(x.take(plan.target_ranks, axis=0) - tpos)
        # Stall: no target newly reached and the ones still missing got closer by less
        # than ``stall`` in total (reached targets converging further do not count), and
        # the pins still missing too (a pin coming back while a far target recedes).
        missing = new_errors > tolerance
        gain = np.where(missing, errors - new_errors, 0.0)
        progress = gain.sum(axis=0)
        if hold is not None:
            progress = np.maximum(progress, gain[hold].sum(axis=0))
        newly_reached = np.any(~missing & (errors > tolerance), axis=0)
        strikes = np.where(newly_reached | (progress >= stall), 0, strikes + 1)
        finished = np.all(new_errors <= tolerance, axis=0) | (strikes >= 3)
        if frozen is not None and hold is not None:
            # a moving root that stopped with a pin still off is held where it is and the
            # limbs go on: a chain from a fixed base meets a pin within its reach
            again = finished & ~frozen & (new_errors[hold] > tolerance).any(axis=0)
            frozen, strikes, finished = (
                frozen | again,
                np.where(again, 0, strikes),
                finished & ~again,
            )
        converged = converged | (finished & ~done)
        errors = np.where(done[None], errors, new_errors)
        done = done | finished

    if iterations:
        x = _carry(x0, x, plan)
        errors = _norm3(x.take(plan.target_ranks, axis=0) - tpos)
    return _Solved(x=x, iterations=iterations, errors=errors, converged=converged)


def _carry(x0: F64, x: F64, plan: _Plan) -> F64:
    """Place the joints the iteration left alone: each untargeted branch is a rigid body
    hanging from its anchor, turned by the swing of the anchor's bone since ``x0``
    (translated only when the anchor is the root). Exactly in place if nothing moved."""
    kids, anchors = plan.carried_joints, plan.carried_anchors
    if len(kids) == 0:
        return x
    anchor_parents = np.where(anchors == 0, 0, _PARENT_RANK[anchors])
    a0 = x0.take(anchors, axis=0) - x0.take(anchor_parents, axis=0)
    a1 = x.take(anchors, axis=0) - x.take(anchor_parents, axis=0)
    off = x0.take(kids, axis=0) - x0.take(anchors, axis=0)
    base = x.take(anchors, axis=0)
    placed = base + _swing(a0, a1, off)
    keep = np.all(a0 == a1, axis=1) & np.all(base == x0.take(anchors, axis=0), axis=1)
    x = x.copy()
    x[kids] = np.where(keep[:, None], x0.take(kids, axis=0), placed)
    return x


@dataclass(frozen=True)
class _Problem:
    batch: tuple[int, ...]
    dtype: np.dtype[np.floating[Any]]
    x0: F64  # internal start pose, exact lengths
    lens: F64  # internal lengths
    idx: IntArray  # [K]
    tpos: F64  # internal targets [K, 3, N]
    weights: F64  # [K]


def _prepare(
    positions: npt.ArrayLike,
    lengths: npt.ArrayLike,
    target_idx: Sequence[int] | npt.ArrayLike,
    target_pos: npt.ArrayLike,
    weights: Sequence[float] | npt.ArrayLike | None,
) -> _Problem:
    dtype = _out_dtype(positions)
    pos = _as_float64(positions)
    lens = _as_float64(lengths)
    idx = np.asarray(target_idx).reshape(-1)
    tpos = _as_float64(target_pos)
    if pos.ndim < 2 or pos.shape[-2:] != (NUM_JOINTS, 3):
        raise ValueError(f"positions must be [..., {NUM_JOINTS}, 3], got {pos.shape}")
    if lens.ndim < 1 or lens.shape[-1] != NUM_JOINTS - 1:
        raise ValueError(f"lengths must be [..., {NUM_JOINTS - 1}], got {lens.shape}")
    if idx.size and (
        not np.issubdtype(idx.dtype, np.integer) or np.any((idx < 0) | (idx >= NUM_JOINTS))
    ):
        raise ValueError(f"target indices must be integers in [0, {NUM_JOINTS})")
    idx = idx.astype(np.intp)
    k = len(idx)
    if tpos.ndim < 2 or tpos.shape[-2:] != (k, 3):
        raise ValueError(f"target_pos must be [..., {k}, 3], got {tpos.shape}")
    w = np.ones(k) if weights is None else _as_float64(weights).reshape(-1)
    if w.shape != (k,) or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise ValueError("weights must be one positive finite number per target")
    batch = np.broadcast_shapes(pos.shape[:-2], lens.shape[:-1], tpos.shape[:-2])
    lens_i = _lengths_internal(lens, batch)
    x0 = _bone_pass_internal(
        _to_internal(pos, batch), lens_i, lambda: _to_internal(pos, batch), lambda: None
    )
    flat_t = np.broadcast_to(tpos, (*batch, k, 3)).reshape(x0.shape[-1], k, 3)
    tpos_i = np.ascontiguousarray(flat_t.transpose(1, 2, 0))
    return _Problem(batch, dtype, x0, lens_i, idx, tpos_i, w)


def _result(pb: _Problem, solved: _Solved, tolerance: float, iterations: int) -> FabrikResult:
    k = len(pb.idx)
    errors = np.ascontiguousarray(solved.errors.T).reshape(*pb.batch, k)
    return FabrikResult(
        positions=_from_internal(solved.x, pb.batch).astype(pb.dtype, copy=False),
        iterations=iterations,
        errors=errors,
        reached=errors <= tolerance,
        converged=solved.converged.reshape(pb.batch),
    )


def _no_targets(pb: _Problem) -> _Solved:
    n = pb.x0.shape[-1]
    return _Solved(pb.x0, 0, np.zeros((0, n)), np.ones(n, dtype=bool))


def fabrik(
    positions: npt.ArrayLike,
    lengths: npt.ArrayLike,
    target_idx: Sequence[int] | npt.ArrayLike,
    target_pos: npt.ArrayLike,
    *,
    weights: Sequence[float] | npt.ArrayLike | None = None,
    tolerance: float = 1e-3,
    max_iterations: int = 100,
    free_root: bool = True,
    pinned: Sequence[bool] | npt.ArrayLike | None = None,
    rigid_hips: bool = False,
) -> FabrikResult:
    """Full-body multi-end-effector FABRIK (Aristidou & Lasenby 2011, 2016).

    ``positions`` ``[..., 21, 3]`` start pose (its bone lengths are first made exact by
    :func:`bone_pass`); ``lengths`` ``[..., 20]`` in ``BONES`` order; ``target_idx`` K
    joint indices (any joints; a repeated joint gets the weighted mean of its targets);
    ``target_pos`` ``[..., K, 3]``; ``weights`` K positive numbers, each target's weight
    in the sub-base centroids (default 1). A pin is a target at the joint's current
    position. Leading axes broadcast.

    Each iteration: forward reaching from every targeted joint towards the root (a
    targeted joint sits on its target; a sub-base -- a joint with several moving child
    chains -- sits at the weighted centroid of the positions they propose), then
    backward reaching from the root outwards. Root policy: the pelvis goes to its target
    if targeted; otherwise, if ``free_root`` and at least two of its branches hold
    targets, it is free: the centroid of its branches' proposals, pulled back so every
    target already satisfied at the start (the pins) stays within 99% of its chain's
    reach; otherwise it stays fixed, so a lone drag bends the body instead of floating
    it. Branches without targets keep their shape and turn with the bone they hang from.

    Stops when every target is within ``tolerance`` (m); when progress stalls -- three
    iterations running in which no target became reached and the targets still missing
    got closer by less than ``tolerance / 1000`` in total, and so did the pins still
    missing (an unreachable target at its closest stretch); or after ``max_iterations``.
    Never raises for unreachable targets and returns finite poses for finite input;
    raises ``ValueError`` on malformed shapes, indices or weights.

    ``pinned`` (K booleans): hard targets. A moving root stays within reach of them from
    any start, a fixed one first moves the start whole into their reach if it has left
    it, and a sub-base with a pin below it follows its pinned chains alone, so a target
    beyond reach is approached only as far as the pins allow.
    ``rigid_hips``: the hips no target is on move with the pelvis, translated: they cannot
    fold onto one side of it, at the price of reach (docs/kinematics.md).
    """
    pb = _prepare(positions, lengths, target_idx, target_pos, weights)
    if len(pb.idx) == 0:
        return _result(pb, _no_targets(pb), tolerance, 0)
    pins = pin_mask(pinned, len(pb.idx))
    plan = _make_plan(pb.idx, pb.weights, frozenset(), free_root, pins, rigid_hips)
    solved = _solve(pb.x0, pb.lens, pb.tpos, plan, tolerance, max_iterations, pins)
    return _result(pb, solved, tolerance, solved.iterations)


def _trunk_locks(idx: IntArray) -> frozenset[int] | None:
    """:data:`core.skeleton.TRUNK`, which the local stage of :func:`polish` holds; ``None``
    when one of its joints is targeted."""
    return None if TRUNK & set(idx.tolist()) else TRUNK


def polish(
    positions: npt.ArrayLike,
    lengths: npt.ArrayLike,
    target_idx: Sequence[int] | npt.ArrayLike,
    target_pos: npt.ArrayLike,
    *,
    weights: Sequence[float] | npt.ArrayLike | None = None,
    tolerance: float = 1e-3,
    max_iterations: int = 100,
    free_root: bool = True,
    pinned: Sequence[bool] | npt.ArrayLike | None = None,
    rigid_hips: bool = False,
) -> FabrikResult:
    """Exact reach from a good pose: targeted joints onto their targets, the rest still.

    Same arguments and result as :func:`fabrik`. The start pose first gets exact bone
    lengths (:func:`bone_pass`); if every target is then within ``tolerance`` it is
    returned as is (0 iterations). Otherwise FABRIK runs from it in two stages:

    1. local: the trunk (every sub-base -- joint with several children -- and its
       ancestors) is held, so only the limbs/neck between it and the targets move: a
       wrist correction bends the arm, not the spine. Skipped when a trunk joint is
       targeted.
    2. global: :func:`fabrik` from the stage-1 result, for poses still missing a target
       (the trunk, and under the root policy the pelvis, may now move; targets reached
       in stage 1 are pins for the root).

    Untargeted branches are carried rigidly, so they do not wander. Unreachable targets
    end at the closest feasible stretch with ``reached`` False. ``iterations`` counts
    both stages. ``pinned`` and ``rigid_hips`` as in :func:`fabrik` (also when the start
    has left the pins).
    """
    pb = _prepare(positions, lengths, target_idx, target_pos, weights)
    if len(pb.idx) == 0:
        return _result(pb, _no_targets(pb), tolerance, 0)
    pins = pin_mask(pinned, len(pb.idx))
    x0, iterations = pb.x0, 0
    locks = _trunk_locks(pb.idx)
    if locks is not None:
        plan = _make_plan(pb.idx, pb.weights, locks, False, None, rigid_hips)
        local = _solve(x0, pb.lens, pb.tpos, plan, tolerance, max_iterations)
        if bool(np.all(local.errors <= tolerance)):
            return _result(pb, local, tolerance, local.iterations)
        x0, iterations = local.x, local.iterations
    plan = _make_plan(pb.idx, pb.weights, frozenset(), free_root, pins, rigid_hips)
    solved = _solve(x0, pb.lens, pb.tpos, plan, tolerance, max_iterations, pins)
    return _result(pb, solved, tolerance, iterations + solved.iterations)
