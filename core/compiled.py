"""Compiled geometry of a solve: canonical frame, body size, the within-reach targets,
the bone pass and the way back to the world, over whole batches in one call each.

These kernels compute what :mod:`core.geometry`, :mod:`core.kinematics` (``bone_pass``)
and the numpy glue of ``service.engine`` compute, item by item in machine code (numba,
:mod:`core.jit`): the same formulas in the same order, so they agree with the numpy
reference to rounding (tests/core/test_compiled.py holds them to 1e-12) and give
bit-identical answers run to run and batch vs single (every item is computed alone).
The numpy modules stay the reference implementation and the readable specification.

Layout: poses ``[B, 21, 3]`` in joint order, lengths ``[B, 20]`` in ``BONES`` order,
float64 (the network inputs float32). Inside, a pose is walked in depth order (ranks,
:data:`ORDER`), parents before children.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.compiled_limbs import carry_item, ends_item, floor_group, floor_item, unit_into
from core.ends import CHAINS as _CHAINS
from core.jit import jit
from core.rest import REST_DIRS
from core.rigid import keep_pairs_item
from core.skeleton import (
    BONE_CHILDREN,
    BONE_PARENTS,
    BONES,
    DEPTH,
    FACING_PAIRS,
    JOINT_INDEX,
    MIRROR_COLUMNS,
    MIRROR_SIGNS,
    NUM_JOINTS,
    PARENTS,
)

F64 = npt.NDArray[np.float64]
F32 = npt.NDArray[np.float32]
I64 = npt.NDArray[np.int64]
Bool = npt.NDArray[np.bool_]
#: :func:`unscale`'s ``pairs`` where ``serving.keep_pairs`` is off
NO_PAIRS: F64 = np.empty((0, NUM_JOINTS, 3))

#: Joints in depth order (stable), and its inverse.
ORDER: I64 = np.argsort(np.asarray(DEPTH), kind="stable").astype(np.int64)
RANK: I64 = np.argsort(ORDER, kind="stable").astype(np.int64)
#: Rank of the parent of each rank (-1 for the root).
PARENT_RANK: I64 = np.asarray(
    [-1 if PARENTS[int(j)] < 0 else int(RANK[PARENTS[int(j)]]) for j in ORDER], dtype=np.int64
)
_BONE_OF = {int(c): b for b, c in enumerate(BONE_CHILDREN)}
#: Bone (``lengths`` axis) ending at each rank 1..20.
LEN_ORDER: I64 = np.asarray([_BONE_OF[int(j)] for j in ORDER[1:]], dtype=np.int64)
#: Rest-pose unit bone directions per rank 1..20, ``[20, 3]``.
REST_DIRS_RANK: F64 = np.ascontiguousarray(REST_DIRS[ORDER[1:]], dtype=np.float64)
_CHILDREN: I64 = BONE_CHILDREN.astype(np.int64)
_PARENTS: I64 = BONE_PARENTS.astype(np.int64)
_LEFT: I64 = np.asarray([JOINT_INDEX[a] for a, _ in FACING_PAIRS], dtype=np.int64)
_RIGHT: I64 = np.asarray([JOINT_INDEX[b] for _, b in FACING_PAIRS], dtype=np.int64)
_PELVIS = JOINT_INDEX["pelvis"]

_LEG = JOINT_INDEX["left_ankle"]


def _chain_matrix() -> F64:
    """``[21, 20]``: 1 where a bone lies on the path from the pelvis to a joint."""
    out = np.zeros((NUM_JOINTS, len(BONES)))
    bone_of = {child: b for b, (child, _) in enumerate(BONES)}
    for joint in range(NUM_JOINTS):
        j = joint
        while j in bone_of:
            out[joint, bone_of[j]] = 1.0
            j = BONES[bone_of[j]][1]
    return out


#: Pelvis-to-joint bone membership, shared with ``service.engine``.
CHAIN: F64 = _chain_matrix()


# --------------------------------------------------------------------------------------
# Scalar helpers (compiled inline into the kernels)
# --------------------------------------------------------------------------------------
@jit
def _sum_pairwise(a: F64) -> float:  # pragma: no cover - compiled
    """numpy's pairwise sum for n < 128 (8 interleaved partial sums), so a total over
    20 bones rounds exactly like ``np.sum`` does."""
    n = a.shape[0]
    if n < 8:
        t = 0.0
        for i in range(n):
            t += a[i]
        return t
    r = np.empty(8)
    for j in range(8):
        r[j] = a[j]
    i = 8
    while i + 8 <= n:
        for j in range(8):
            r[j] += a[i + j]
        i += 8
    s: float = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        s += a[i]
        i += 1
    return s


@jit
def norm3(x: float, y: float, z: float) -> float:  # pragma: no cover - compiled
    """The length of the vector (x, y, z)."""
    return float(np.sqrt(x * x + y * y + z * z))


@jit
def chain_length(lens: F64, j: int) -> float:  # pragma: no cover - compiled
    """The bones ``lens [20]`` (``BONES`` order) from the pelvis to joint ``j``, summed in
    bone order: how far ``j`` reaches from the pelvis at full stretch."""
    acc = 0.0
    for i in range(NUM_JOINTS - 1):
        acc += lens[i] * CHAIN[j, i]
    return acc


@jit
def bone_lengths_item(pose: F64, out: F64) -> None:  # pragma: no cover - compiled
    """``out[20]`` = lengths of ``pose [21, 3]`` in ``BONES`` order."""
    for b in range(_CHILDREN.shape[0]):
        c, p = _CHILDREN[b], _PARENTS[b]
        out[b] = norm3(pose[c, 0] - pose[p, 0], pose[c, 1] - pose[p, 1], pose[c, 2] - pose[p, 2])


@jit
def shortest_bones(poses: F64) -> F64:  # pragma: no cover - compiled
    """The shortest bone of each pose ``[B, 21, 3]``: ``[B]`` (a request's check for a
    degenerate pose, ``service.validation.check_bones``: ~18 us in numpy on the hot path)."""
    out = np.empty(poses.shape[0])
    lengths = np.empty(NUM_JOINTS - 1)
    for b in range(poses.shape[0]):
        bone_lengths_item(poses[b], lengths)
        out[b] = lengths.min()
    return out


# --------------------------------------------------------------------------------------
# Bone pass
# --------------------------------------------------------------------------------------
@jit
def bone_pass_rank(x: F64, lens: F64) -> bool:  # pragma: no cover - compiled
    """In-place bone pass on a rank-ordered pose ``x [21, 3]`` (``lens [20]`` rank order,
    row r - 1 for rank r): ``parent + d * (length / |d|)``. False if a direction was
    undefined (then ``x`` holds non-finite values and the caller takes the safe path)."""
    ok = True
    for r in range(1, x.shape[0]):
        p = PARENT_RANK[r]
        dx, dy, dz = x[r, 0] - x[p, 0], x[r, 1] - x[p, 1], x[r, 2] - x[p, 2]
        f = lens[r - 1] / np.sqrt(dx * dx + dy * dy + dz * dz)
        x[r, 0] = x[p, 0] + dx * f
        x[r, 1] = x[p, 1] + dy * f
        x[r, 2] = x[p, 2] + dz * f
        if not (np.isfinite(x[r, 0]) and np.isfinite(x[r, 1]) and np.isfinite(x[r, 2])):
            ok = False
    return ok


@jit
def bone_pass_rank_safe(
    src: F64, lens: F64, ref: F64, has_ref: bool, out: F64
) -> None:  # pragma: no cover - compiled
    """Bone pass with per-bone fallbacks (``kinematics._bone_pass_safe``): a direction
    that is undefined falls back to the bone's direction in ``ref`` (if ``has_ref`` and
    defined there), else to the rest pose's."""
    v = np.empty(3)
    u = np.empty(3)
    out[0, :] = src[0, :]
    for r in range(1, src.shape[0]):
        p = PARENT_RANK[r]
        for i in range(3):
            v[i] = src[r, i] - out[p, i]
        if not unit_into(v, u):
            done = False
            if has_ref:
                for i in range(3):
                    v[i] = ref[r, i] - ref[p, i]
                done = unit_into(v, u)
            if not done:
                for i in range(3):
                    u[i] = REST_DIRS_RANK[r - 1, i]
        for i in range(3):
            out[r, i] = out[p, i] + u[i] * lens[r - 1]


@jit
def bone_pass_item(
    pose: F64, lengths: F64, ref: F64, has_ref: bool, out: F64, xr: F64, lr: F64, rr: F64
) -> None:  # pragma: no cover - compiled
    """``out [21, 3]`` = ``kinematics.bone_pass(pose, lengths, reference=ref)`` for one
    pose in joint order; ``xr``, ``lr``, ``rr`` are scratch (``[21, 3]``, ``[20]``,
    ``[21, 3]``)."""
    for r in range(NUM_JOINTS):
        j = ORDER[r]
        for i in range(3):
            xr[r, i] = pose[j, i]
    for r in range(1, NUM_JOINTS):
        lr[r - 1] = lengths[LEN_ORDER[r - 1]]
    if not bone_pass_rank(xr, lr):
        for r in range(NUM_JOINTS):
            j = ORDER[r]
            for i in range(3):
                xr[r, i] = pose[j, i]
                rr[r, i] = ref[j, i] if has_ref else 0.0
        src = xr.copy()
        bone_pass_rank_safe(src, lr, rr, has_ref, xr)
    for r in range(NUM_JOINTS):
        j = ORDER[r]
        for i in range(3):
            out[j, i] = xr[r, i]


@jit
def bone_pass_batch(
    poses: F64, lengths: F64, refs: F64, has_ref: bool
) -> F64:  # pragma: no cover - compiled
    """``kinematics.bone_pass`` over ``poses [B, 21, 3]``, ``lengths [B, 20]`` (and
    ``refs [B, 21, 3]`` when ``has_ref``), each pose alone."""
    out = np.empty_like(poses)
    xr, rr, lr = np.empty((NUM_JOINTS, 3)), np.empty((NUM_JOINTS, 3)), np.empty(NUM_JOINTS - 1)
    for b in range(poses.shape[0]):
        bone_pass_item(poses[b], lengths[b], refs[b if has_ref else 0], has_ref, out[b], xr, lr, rr)
    return out


# --------------------------------------------------------------------------------------
# A solve's way in and out
# --------------------------------------------------------------------------------------
#: What :func:`prepare` gives: canonical poses, facing, translation, bone lengths,
#: scales, canonical targets, network inputs and the targets' canvas.
Prepared = tuple[F64, F64, F64, F64, F64, F64, F32, F32]


@jit
def scale_item(
    lengths: F64, shapes: F64, shape_totals: F64, total_length: bool, reference_total: float
) -> float:  # pragma: no cover - compiled
    """How much bigger a body of bone ``lengths [20]`` is than the networks' body size
    (``Engine.scales_of``): its total over the reference total (``total_length``), or over
    the total of the training skeleton whose proportions (``shapes``) are nearest."""
    total = _sum_pairwise(lengths)
    if total_length:
        return float(total / reference_total)
    best, best_d = 0, np.inf
    for c in range(shapes.shape[0]):
        d = 0.0
        for i in range(NUM_JOINTS - 1):
            e = lengths[i] / total - shapes[c, i]
            d += e * e
        d = np.sqrt(d)
        if d < best_d:
            best, best_d = c, d
    return float(total / shape_totals[best])


@jit
def body_scales(
    poses: F64, shapes: F64, shape_totals: F64, total_length: bool, reference_total: float
) -> F64:  # pragma: no cover - compiled
    """:func:`scale_item` of each pose ``[B, 21, 3]``: ``[B]`` (``Engine.scales_of`` of
    their bone lengths, ~1 us where numpy takes ~15)."""
    out = np.empty(poses.shape[0])
    lengths = np.empty(NUM_JOINTS - 1)
    for b in range(poses.shape[0]):
        bone_lengths_item(poses[b], lengths)
        out[b] = scale_item(lengths, shapes, shape_totals, total_length, reference_total)
    return out


@jit
def target_motion(
    poses: F64, tidx: I64, tpos: F64, n_t: I64, rows: I64
) -> F64:  # pragma: no cover - compiled
    """How far across (x, z) the targets of each item of ``rows`` lie from the joints of
    its start ``poses[i]`` (``[len(rows), 21, 3]``, in the order of ``rows``) they are
    for, on average over its own ``n_t`` targets (``tidx``, ``tpos``: all items'):
    ``service.turns.target_motion``, summed as numpy sums a row (~1 us where numpy took ~13
    for one edit)."""
    out = np.empty(rows.shape[0])
    gaps = np.empty(tidx.shape[1])
    for i in range(rows.shape[0]):
        r, k = rows[i], n_t[rows[i]]
        for c in range(k):
            j = tidx[r, c]
            gaps[c] = np.hypot(tpos[r, c, 0] - poses[i, j, 0], tpos[r, c, 2] - poses[i, j, 2])
        out[i] = _sum_pairwise(gaps[:k]) / k
    return out


@jit
def retry_reaches(
    poses: F64, soft: F64, reach: float, shapes: F64, shape_totals: F64, total_length: bool,
    reference_total: float, errors: F64, out: F64,
) -> bool:  # pragma: no cover - compiled  # fmt: skip
    """Each pose's ``[B, 21, 3]`` retry threshold into ``out [B]``: ``reach`` times its
    :func:`scale_item` (as :func:`prepare` has it), plus ``soft [B]`` / e; and whether
    every one of ``errors [B, K]`` is within the least of them (``errors.max() <= least``,
    NaN as numpy's: no item to retry). Written into ``out``, not returned: a returned
    array costs numba a boxed one."""
    lengths = np.empty(NUM_JOINTS - 1)
    least = np.inf
    for b in range(poses.shape[0]):
        bone_lengths_item(poses[b], lengths)
        s = scale_item(lengths, shapes, shape_totals, total_length, reference_total)
        out[b] = reach * s + soft[b] / np.e
        least = min(least, out[b])
    return bool(errors.max() <= least)


@jit
def prepare(
    poses: F64,
    floors: F64,
    tidx: I64,
    tpos: F64,
    counts: I64,
    neural: Bool,
    shapes: F64,
    shape_totals: F64,
    total_length: bool,
    reference_total: float,
) -> Prepared:  # pragma: no cover - compiled
    """Everything before the networks, per item (``service.engine``'s numpy steps):

    the floor taken off, the canonical transform (``core.geometry.canonical_transform``:
    facing from the hips and shoulders, pelvis floor projection to the origin), the
    canonical pose and targets, bone lengths, the body scale (``Engine.scales_of``), and
    for ``neural`` items the network inputs: the pose over its scale (float32, ``[B, 63]``)
    and the within-reach targets over the scale on a ``[B, 21, 3]`` canvas (float32).

    Returns ``canon, facing [B, 2] (fx, fz), translation [B, 3], lengths [B, 20],
    scales [B], tcan [B, K, 3], x [B, 63], canvas [B, 21, 3]``. ``tpos`` comes in world
    space with the floor already taken off (padded rows beyond ``counts`` are ignored).
    """
    n, k_max = tidx.shape[0], tidx.shape[1]
    canon = np.empty((n, NUM_JOINTS, 3))
    facing = np.empty((n, 2))
    trans = np.empty((n, 3))
    lengths = np.empty((n, NUM_JOINTS - 1))
    scales = np.empty(n)
    tcan = np.zeros((n, k_max, 3))
    x = np.zeros((n, 3 * NUM_JOINTS), dtype=np.float32)
    canvas = np.zeros((n, NUM_JOINTS, 3), dtype=np.float32)
    local = np.empty(3)
    chain = np.empty(NUM_JOINTS)
    for b in range(n):
        pose = poses[b]
        up = floors[b]
        ax, az = 0.0, 0.0
        for q in range(_LEFT.shape[0]):
            ax += pose[_LEFT[q], 0] - pose[_RIGHT[q], 0]
            az += pose[_LEFT[q], 2] - pose[_RIGHT[q], 2]
        fx, fz = -az, ax
        norm = np.hypot(fx, fz)
        if norm < 1e-12:
            fx, fz = 0.0, 1.0
        else:
            fx, fz = fx / norm, fz / norm
        facing[b, 0], facing[b, 1] = fx, fz
        tx, tz = pose[_PELVIS, 0], pose[_PELVIS, 2]
        trans[b, 0], trans[b, 1], trans[b, 2] = tx, 0.0, tz
        # rotation R = [[fz, 0, fx], [0, 1, 0], [-fx, 0, fz]]; canonical = R^T (world - t)
        for j in range(NUM_JOINTS):
            local[0], local[1], local[2] = pose[j, 0] - tx, (pose[j, 1] - up) - 0.0, pose[j, 2] - tz
            canon[b, j, 0] = fz * local[0] + 0.0 * local[1] + -fx * local[2]
            canon[b, j, 1] = 0.0 * local[0] + 1.0 * local[1] + 0.0 * local[2]
            canon[b, j, 2] = fx * local[0] + 0.0 * local[1] + fz * local[2]
        for q in range(counts[b]):
            local[0] = tpos[b, q, 0] - tx
            local[1] = tpos[b, q, 1] - 0.0
            local[2] = tpos[b, q, 2] - tz
            tcan[b, q, 0] = fz * local[0] + 0.0 * local[1] + -fx * local[2]
            tcan[b, q, 1] = 0.0 * local[0] + 1.0 * local[1] + 0.0 * local[2]
            tcan[b, q, 2] = fx * local[0] + 0.0 * local[1] + fz * local[2]
        bone_lengths_item(pose, lengths[b])
        scales[b] = scale_item(lengths[b], shapes, shape_totals, total_length, reference_total)
        if not neural[b]:
            continue
        s = scales[b]
        for j in range(NUM_JOINTS):
            for i in range(3):
                x[b, 3 * j + i] = np.float32(canon[b, j, i] / s)
        # within reach: the pelvis-to-target chain plus a leg of root travel
        for j in range(NUM_JOINTS):
            chain[j] = chain_length(lengths[b], j)
        for q in range(counts[b]):
            j = tidx[b, q]
            radius = chain[j] + chain[_LEG]
            ox = tcan[b, q, 0] - canon[b, _PELVIS, 0]
            oy = tcan[b, q, 1] - canon[b, _PELVIS, 1]
            oz = tcan[b, q, 2] - canon[b, _PELVIS, 2]
            dist = norm3(ox, oy, oz)
            f = min(1.0, radius / max(dist, 1e-12))
            canvas[b, j, 0] = np.float32((canon[b, _PELVIS, 0] + ox * f) / s)
            canvas[b, j, 1] = np.float32((canon[b, _PELVIS, 1] + oy * f) / s)
            canvas[b, j, 2] = np.float32((canon[b, _PELVIS, 2] + oz * f) / s)
    return canon, facing, trans, lengths, scales, tcan, x, canvas


@jit
def hold_pelvis(pose: F64, start: F64, r: float) -> None:  # pragma: no cover - compiled
    """``serving.keep_pelvis``, in place on one pose ``[21, 3]``: the pelvis's move away
    from ``start``'s loses ``r`` of its length (a move shorter than ``r`` is dropped), so
    the bone pass lays the body out from there: ``start + d · max(0, 1 − r / |d|)``."""
    dx = pose[_PELVIS, 0] - start[_PELVIS, 0]
    dy = pose[_PELVIS, 1] - start[_PELVIS, 1]
    dz = pose[_PELVIS, 2] - start[_PELVIS, 2]
    n = np.sqrt(dx * dx + dy * dy + dz * dz)
    f = (n - r) / n if n > r else 0.0
    pose[_PELVIS, 0] = start[_PELVIS, 0] + dx * f
    pose[_PELVIS, 1] = start[_PELVIS, 1] + dy * f
    pose[_PELVIS, 2] = start[_PELVIS, 2] + dz * f


@jit
def travel(
    poses: F64, tidx: I64, tpos: F64, cnt: I64, n_t: I64, fab: Bool, pelvis: bool, reach: bool,
    few: int,
) -> tuple[F64, bool]:  # pragma: no cover - compiled  # fmt: skip
    """The starts ``poses [B, 21, 3]`` moved across as ``_Items.travelled`` says, and
    whether any moved; only neural items with no pins (``fab``, ``cnt`` = ``n_t``) move.
    ``pelvis`` (``serving.pelvis_travel``): an item with a target on the pelvis moves
    horizontally (x, z) by its first such target's offset from the start's pelvis. Then
    ``reach`` (``serving.reach_travel``), for items of fewer than ``few`` targets: by the
    excess of the target farthest across (x, z) beyond its chain's reach (the start's
    bones from the pelvis to the joint, summed in bone order), towards it, if any."""
    out = poses.copy()
    lens = np.empty(NUM_JOINTS - 1)
    moved = False
    for b in range(poses.shape[0]):
        if fab[b] or cnt[b] != n_t[b]:
            continue
        pose = out[b]
        for q in range(n_t[b] if pelvis else 0):
            if tidx[b, q] == _PELVIS:
                sx, sz = tpos[b, q, 0] - pose[_PELVIS, 0], tpos[b, q, 2] - pose[_PELVIS, 2]
                _shift(pose, sx, sz)
                moved = True
                break
        if not reach or n_t[b] >= few:
            continue
        bone_lengths_item(pose, lens)
        best, sx, sz = 0.0, 0.0, 0.0
        for q in range(n_t[b]):
            ax = tpos[b, q, 0] - pose[_PELVIS, 0]
            az = tpos[b, q, 2] - pose[_PELVIS, 2]
            d = np.sqrt(ax * ax + az * az)
            over = d - chain_length(lens, tidx[b, q])
            if over > best:
                best, sx, sz = over, ax * (over / d), az * (over / d)
        if sx != 0.0 or sz != 0.0:
            _shift(pose, sx, sz)
            moved = True
    return out, moved


@jit
def _shift(pose: F64, sx: float, sz: float) -> None:  # pragma: no cover - compiled
    """``pose [21, 3] += (sx, 0, sz)`` in place, every joint (y gains 0.0: as numpy adds)."""
    for j in range(NUM_JOINTS):
        pose[j, 0] += sx
        pose[j, 1] += 0.0
        pose[j, 2] += sz


@jit
def unscale(
    decoded: F32,
    scales: F64,
    canon: F64,
    lengths: F64,
    bone: Bool,
    tidx: I64,
    counts: I64,
    carry: F64,
    chains: Bool,
    ease: float,
    collar: Bool,
    hold: F64,
    pairs: F64,
    side: float,
    soft: F64,
    feet: bool,
) -> F64:  # pragma: no cover - compiled
    """Network answers ``[M, 63]`` (float32, at the networks' size) back to the body's
    size (float64), with the bone pass (reference: the start pose) where ``bone``, and
    there, with ``pairs`` (the callers' starts ``[M, 21, 3]``; ``[0, 21, 3]``: none),
    :func:`core.rigid.keep_pairs_item` (the hips and the collars at the callers' angles),
    then, where ``carry[b]`` > 0, :func:`carry_item` below the item's targets
    ``tidx[b, :counts[b]]`` by that weight, then :func:`ends_item` of the
    chains ``chains`` marks (the limb ends back where the network put them; a limb the
    networks drew too straight bent towards ``core.ends.PREFER`` by ``side``; easing into
    full stretch over ``soft[b]`` m: ``core.ends.soft_reach``), then with ``feet``
    :func:`core.compiled_limbs.floor_item` (legs sunk below the floor raised back).
    Where ``hold[b]`` > 0 the bone pass starts from a pelvis held near the start's
    (:func:`hold_pelvis`)."""
    m = decoded.shape[0]
    out = np.empty((m, NUM_JOINTS, 3))
    pose = np.empty((NUM_JOINTS, 3))
    xr, rr, lr = np.empty((NUM_JOINTS, 3)), np.empty((NUM_JOINTS, 3)), np.empty(NUM_JOINTS - 1)
    flags, anchor, vecs = (
        np.empty(NUM_JOINTS, np.int64),
        np.empty(NUM_JOINTS, np.int64),
        np.empty((5, 3)),
    )
    ends = chains.any()
    for b in range(m):
        s = scales[b]
        for j in range(NUM_JOINTS):
            for i in range(3):
                pose[j, i] = np.float64(decoded[b, 3 * j + i]) * s
        if bone[b]:
            if hold[b] > 0.0:
                hold_pelvis(pose, canon[b], hold[b])
            bone_pass_item(pose, lengths[b], canon[b], True, out[b], xr, lr, rr)
            if pairs.shape[0]:
                keep_pairs_item(out[b], pairs[b])
            if carry[b] > 0.0:
                carry_item(out[b], canon[b], lengths[b], tidx[b], counts[b], carry[b], rr,
                           flags, anchor, vecs)  # fmt: skip
            if ends:
                ends_item(out[b], pose, tidx[b], counts[b], chains, flags, vecs, ease, collar[b],
                          side, soft[b])  # fmt: skip
            if feet:
                floor_item(out[b], canon[b], tidx[b], counts[b], flags, vecs)
        else:
            out[b] = pose
    return out


@jit
def finish(
    canon_out: F64,
    facing: F64,
    trans: F64,
    floors: F64,
    tidx: I64,
    tpos: F64,
    counts: I64,
    lengths: F64,
) -> tuple[F64, F64, F64]:  # pragma: no cover - compiled
    """Back to the world: ``world [B, 21, 3]`` (floor added back), the distance of each
    targeted joint to its target ``[B, K]`` (0 beyond ``counts``) and the largest relative
    bone-length error against ``lengths`` ``[B]``. ``tpos`` as given to :func:`prepare`."""
    n, k_max = tidx.shape[0], tidx.shape[1]
    world = np.empty_like(canon_out)
    errors = np.zeros((n, k_max))
    bone_err = np.empty(n)
    now = np.empty(NUM_JOINTS - 1)
    for b in range(n):
        fx, fz = facing[b, 0], facing[b, 1]
        tx, ty, tz = trans[b, 0], trans[b, 1], trans[b, 2]
        c = canon_out[b]
        for j in range(NUM_JOINTS):
            world[b, j, 0] = (fz * c[j, 0] + 0.0 * c[j, 1] + fx * c[j, 2]) + tx
            world[b, j, 1] = (0.0 * c[j, 0] + 1.0 * c[j, 1] + 0.0 * c[j, 2]) + ty
            world[b, j, 2] = (-fx * c[j, 0] + 0.0 * c[j, 1] + fz * c[j, 2]) + tz
        for q in range(counts[b]):
            j = tidx[b, q]
            errors[b, q] = norm3(
                world[b, j, 0] - tpos[b, q, 0],
                world[b, j, 1] - tpos[b, q, 1],
                world[b, j, 2] - tpos[b, q, 2],
            )
        for j in range(NUM_JOINTS):
            world[b, j, 1] = world[b, j, 1] + floors[b]
        bone_lengths_item(world[b], now)
        worst = 0.0
        for i in range(NUM_JOINTS - 1):
            e = abs(now[i] / lengths[b, i] - 1.0)
            if e > worst or np.isnan(e):
                worst = e
        bone_err[b] = worst
    return world, errors, bone_err


@jit
def settle(
    decoded: F32,
    scales: F64,
    canon: F64,
    lengths: F64,
    facing: F64,
    trans: F64,
    floors: F64,
    tidx: I64,
    tpos: F64,
    counts: I64,
    carry: F64,
    chains: Bool,
    ease: float,
    collar: Bool,
    hold: F64,
    pairs: F64,
    side: float,
    soft: F64,
    feet: bool,
) -> tuple[F64, F64, F64]:  # pragma: no cover - compiled
    """:func:`unscale` with the bone pass for every item, then :func:`finish`, in one call
    (the lean path of ``service.lean``): the same arithmetic in the same order."""
    bone = np.ones(decoded.shape[0], dtype=np.bool_)
    out = unscale(
        decoded, scales, canon, lengths, bone, tidx, counts, carry, chains, ease, collar, hold,
        pairs, side, soft, feet,
    )  # fmt: skip
    return finish(out, facing, trans, floors, tidx, tpos, counts, lengths)


# --------------------------------------------------------------------------------------
# One edit's soft passes in place (service.lean.solve_one): the same kernels as above,
# their answers written into arrays the caller holds (onnxruntime's bound input buffers
# and a per-thread workspace) instead of returned, which costs numba a boxed array each
# (~0.6 us; prepare's eight were most of its call). The arithmetic is the same.
# --------------------------------------------------------------------------------------
@jit
def _floor_off(tpos: F64, floors: F64) -> F64:  # pragma: no cover - compiled
    """``tpos [B, K, 3]`` with each item's floor taken off y (``Engine._prepare``'s)."""
    out = tpos.copy()
    for b in range(out.shape[0]):
        for q in range(out.shape[1]):
            out[b, q, 1] -= floors[b]
    return out


#: ``core.skeleton.mirrored_flat``'s columns and signs (float32: the networks' type).
_MCOLS: I64 = MIRROR_COLUMNS.astype(np.int64)
_MSIGNS: F32 = MIRROR_SIGNS.astype(np.float32)


@jit
def prepare_into(
    poses: F64, floors: F64, tidx: I64, tpos: F64, counts: I64, shapes: F64,
    shape_totals: F64, total_length: bool, reference_total: float, cols: I64, other: I64,
    signs: F32, x_in: F32, t_in: F32, canon: F64, facing: F64, trans: F64, lengths: F64,
    scales: F64,
) -> None:  # pragma: no cover - compiled  # fmt: skip
    """:func:`prepare` of ``B`` neural items (``tpos`` in the world, the floor not yet
    taken off), written in place: the network input into ``x_in [B, 63]`` and the
    canvas's flat columns ``cols`` (a graph's target inputs, in its order) into ``t_in``,
    and what :func:`settle` needs into ``canon``, ``facing``, ``trans``, ``lengths`` and
    ``scales``. Where ``x_in`` has ``2B`` rows, rows ``B..`` are the mirror images
    (``service.networks.both_views``, one solver whose set is its own mirror image): the
    input mirrored (``core.skeleton.mirrored_flat``) and the canvas's columns ``other``
    times ``signs``; exact, as a permutation and a sign are."""
    n = poses.shape[0]
    c, f, t, lens, s, _tcan, x, canvas = prepare(
        poses, floors, tidx, _floor_off(tpos, floors), counts, np.ones(n, dtype=np.bool_),
        shapes, shape_totals, total_length, reference_total,
    )  # fmt: skip
    canon[:] = c
    facing[:] = f
    trans[:] = t
    lengths[:] = lens
    scales[:] = s
    x_in[:n] = x
    for b in range(n):
        for i in range(cols.shape[0]):
            t_in[b, i] = canvas[b, cols[i] // 3, cols[i] % 3]
    if x_in.shape[0] == n:
        return
    for b in range(n):  # the mirror images
        for i in range(3 * NUM_JOINTS):
            x_in[n + b, i] = x[b, _MCOLS[i]] * _MSIGNS[i]
        for i in range(other.shape[0]):
            t_in[n + b, i] = canvas[b, other[i] // 3, other[i] % 3] * signs[i]


@jit
def _views(decoded: F32, n: int) -> F32:  # pragma: no cover - compiled
    """The answer ``[n, 63]`` of a run of ``n`` rows, or of ``2n`` rows whose rows ``n..``
    answer the mirror images (:func:`prepare_into`): the mean of each row's answer and
    its mirror image's taken back, in float32 as ``service.networks.both_views``
    computes it: ``(own + mirrored_flat(other)) * 0.5``."""
    if decoded.shape[0] == n:
        return decoded
    out = np.empty((n, 3 * NUM_JOINTS), dtype=np.float32)
    half = np.float32(0.5)
    for b in range(n):
        for i in range(3 * NUM_JOINTS):
            back = decoded[n + b, _MCOLS[i]] * _MSIGNS[i]
            out[b, i] = (decoded[b, i] + back) * half
    return out


@jit
def settle_prepare(
    decoded: F32, scales: F64, canon: F64, lengths: F64, facing: F64, trans: F64,
    floors: F64, tidx: I64, tpos: F64, counts: I64, carry: F64, chains: Bool, ease: float,
    collar: Bool, hold: F64, pairs: F64, side: float, soft: F64, feet: bool, shapes: F64,
    shape_totals: F64, total_length: bool, reference_total: float, cols: I64, other: I64,
    signs: F32, x_in: F32, t_in: F32,
) -> None:  # pragma: no cover - compiled  # fmt: skip
    """:func:`settle` of one pass (``tpos`` in the world; ``decoded``: the run's rows, both
    views where :func:`prepare_into` made two, :func:`_views`), then :func:`prepare_into`
    of the next from its answer: a soft pass's end and the next one's start in one call."""
    pose, _errors, _bone = settle(
        _views(decoded, scales.shape[0]), scales, canon, lengths, facing, trans, floors, tidx,
        _floor_off(tpos, floors), counts, carry, chains, ease, collar, hold, pairs, side, soft,
        feet,
    )  # fmt: skip
    prepare_into(
        pose, floors, tidx, tpos, counts, shapes, shape_totals, total_length, reference_total,
        cols, other, signs, x_in, t_in, canon, facing, trans, lengths, scales,
    )  # fmt: skip


@jit
def settle_last(
    decoded: F32, scales: F64, canon: F64, lengths: F64, facing: F64, trans: F64,
    floors: F64, tidx: I64, tpos: F64, counts: I64, carry: F64, chains: Bool, ease: float,
    collar: Bool, hold: F64, pairs: F64, side: float, soft: F64, feet: bool, world: F64,
    errors: F64, bone_err: F64,
) -> None:  # pragma: no cover - compiled  # fmt: skip
    """:func:`settle` with ``tpos`` in the world (the floor taken off here; ``decoded``
    as :func:`settle_prepare` takes it), its answer written into ``world [B, 21, 3]``,
    ``errors [B, K]`` and ``bone_err [B]``."""
    w, e, b = settle(
        _views(decoded, scales.shape[0]), scales, canon, lengths, facing, trans, floors, tidx,
        _floor_off(tpos, floors), counts, carry, chains, ease, collar, hold, pairs, side, soft,
        feet,
    )  # fmt: skip
    world[:] = w
    errors[:] = e
    bone_err[:] = b


def warm() -> None:
    """Compile (or load from the cache) every kernel of this module on tiny inputs, and of
    :mod:`core.compiled_characters`, :mod:`core.compiled_chain`, :mod:`core.compiled_hinges`
    and :mod:`core.compiled_reach`."""
    from core import compiled_chain, compiled_characters, compiled_hinges, compiled_reach
    from core.rest import rest_pose

    compiled_characters.warm()
    compiled_chain.warm()
    compiled_hinges.warm()
    compiled_reach.warm()
    pose = rest_pose()[None].astype(np.float64)
    lens = np.ones((1, NUM_JOINTS - 1))
    bone_pass_batch(pose, lens, pose, True)
    bone_pass_batch(pose, lens, pose, False)
    tidx = np.zeros((1, 1), dtype=np.int64)
    tpos = np.zeros((1, 1, 3))
    counts = np.ones(1, dtype=np.int64)
    shapes = np.ones((1, NUM_JOINTS - 1)) / (NUM_JOINTS - 1)
    chains = np.ones(_CHAINS.shape[0], dtype=np.bool_)
    out = prepare(
        pose, np.zeros(1), tidx, tpos, counts, np.ones(1, dtype=np.bool_), shapes,
        np.ones(1), True, 1.0,
    )  # fmt: skip
    retry_reaches(pose, np.zeros(1), 0.005, shapes, np.ones(1), True, 1.0, tpos[0], np.empty(1))
    body_scales(pose, shapes, np.ones(1), True, 1.0)
    shortest_bones(pose)
    keep_pairs_item(pose[0].copy(), pose[0])  # (called alone too: service.fabrik_set)
    target_motion(pose, tidx, tpos, counts, np.zeros(1, dtype=np.int64))
    unscale(
        out[6], out[4], out[0], out[3], np.ones(1, dtype=np.bool_), tidx, counts, np.full(1, 0.5),
        chains, 0.0, np.ones(1, dtype=np.bool_), np.full(1, 0.02), pose, 0.5, np.full(1, 0.01),
        True,
    )  # fmt: skip
    finish(out[0], out[1], out[2], np.zeros(1), tidx, tpos, counts, out[3])
    floor_group(pose.copy(), pose, tidx[0], True)  # (plant as the engine gives it)
    one = np.ones(1, dtype=np.bool_)
    travel(pose, tidx, tpos, counts, counts, ~one, True, True, 5)
    settle(
        out[6], out[4], out[0], out[3], out[1], out[2], np.zeros(1), tidx, tpos, counts,
        np.full(1, 0.5), chains, 0.0, one, np.full(1, 0.02), pose, 0.5, np.full(1, 0.01), True,
    )  # fmt: skip
    cols, signs = np.arange(3, dtype=np.int64), np.ones(3, np.float32)
    state = (out[0].copy(), out[1].copy(), out[2].copy(), out[3].copy(), out[4].copy())
    rest = (np.zeros(1), tidx, tpos, counts, np.full(1, 0.5), chains, 0.0, one,
            np.full(1, 0.02), pose, 0.5, np.full(1, 0.01), True)  # fmt: skip
    for rows in (1, 2):  # one view, both views
        x_in = np.empty((rows, 3 * NUM_JOINTS), np.float32)
        t_in = np.empty((rows, 3), np.float32)
        prepare_into(pose, np.zeros(1), tidx, tpos, counts, shapes, np.ones(1), True, 1.0, cols,
                     cols, signs, x_in, t_in, *state)  # fmt: skip
        settle_prepare(x_in, state[4], state[0], state[3], state[1], state[2], *rest, shapes,
                       np.ones(1), True, 1.0, cols, cols, signs, x_in, t_in)  # fmt: skip
        settle_last(x_in, state[4], state[0], state[3], state[1], state[2], *rest, pose.copy(),
                    np.empty((1, 1)), np.empty(1))  # fmt: skip


def as_i64(a: npt.ArrayLike) -> I64:
    return np.ascontiguousarray(a, dtype=np.int64)


def as_f64(a: npt.ArrayLike) -> F64:
    return np.ascontiguousarray(a, dtype=np.float64)
