"""Compiled limb kernels of a solve: unit vectors, bone swings, the branch carried below a
dragged joint (``serving.carry``) and the limb ends kept where the networks put them
(``serving.keep_ends``), for one pose at a time in machine code (numba, :mod:`core.jit`).

Each is the numpy function named in its docstring (:mod:`core.carry`, :mod:`core.ends`,
:mod:`core.kinematics`) computed in the same order, held to it in tests/core/test_carry.py
and tests/core/test_ends.py; :func:`core.compiled.unscale` runs them over a batch.
Layout as in :mod:`core.compiled`: a pose ``[21, 3]`` in joint order, float64.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.carry import BONE_OF
from core.ends import BELOW as _ENDS_BELOW
from core.ends import CHAINS as _CHAINS
from core.ends import CLAVICLE_CONE as _CONE
from core.ends import COLLARS as _ENDS_COLLARS
from core.ends import OTHER_COLLAR
from core.ends import PREFER as _PREFER
from core.ends import SOFT_IK_LIMB as _SOFT_IK_LIMB
from core.ends import TINY as _ENDS_TINY
from core.jit import jit
from core.skeleton import JOINT_INDEX, NUM_JOINTS, PARENTS

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
Bool = npt.NDArray[np.bool_]

_PELVIS = JOINT_INDEX["pelvis"]
#: Parent of each joint (joint order; the root's is itself).
PARENTS_J: I64 = np.asarray([max(p, 0) for p in PARENTS], dtype=np.int64)
#: Distance at or below which a direction is undefined (as in core.kinematics).
TINY = 1e-300


@jit
def unit_into(v: F64, out: F64) -> bool:  # pragma: no cover - compiled
    """``v [3]`` divided by its norm into ``out``; False (``out`` untouched) when it has none."""
    n = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if n > TINY:
        out[0], out[1], out[2] = v[0] / n, v[1] / n, v[2] / n
        return True
    return False


@jit
def unit_or(v: F64, f1: F64, f2: F64, out: F64, n_fallbacks: int) -> None:  # pragma: no cover
    """``kinematics._unit_or(v, f1, f2)`` for one 3-vector (``n_fallbacks`` of them used):
    the first vector with a direction, the last one divided by its norm or by 1."""
    for level in range(n_fallbacks + 1):
        a = v if level == 0 else (f1 if level == 1 else f2)
        n = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        if n > TINY or level == n_fallbacks:
            d = n if n > TINY else 1.0
            out[0], out[1], out[2] = a[0] / d, a[1] / d, a[2] / d
            return


@jit
def swing_into(a: F64, b: F64, v: F64, out: F64) -> None:  # pragma: no cover - compiled
    """``kinematics._swing`` for one vector: ``v`` turned by the rotation taking a to b."""
    au, bu, zero = np.empty(3), np.empty(3), np.zeros(3)
    unit_or(a, zero, zero, au, 1)
    unit_or(b, zero, zero, bu, 1)
    c = au[0] * bu[0] + au[1] * bu[1] + au[2] * bu[2]
    w0 = au[1] * bu[2] - au[2] * bu[1]
    w1 = au[2] * bu[0] - au[0] * bu[2]
    w2 = au[0] * bu[1] - au[1] * bu[0]
    scale = (w0 * v[0] + w1 * v[1] + w2 * v[2]) / max(1.0 + c, 1e-12)
    same = (a[0] == b[0] and a[1] == b[1] and a[2] == b[2]) or not (
        au[0] != 0.0 or au[1] != 0.0 or au[2] != 0.0
    ) or not (bu[0] != 0.0 or bu[1] != 0.0 or bu[2] != 0.0)  # fmt: skip
    if same:
        out[0], out[1], out[2] = v[0], v[1], v[2]
        return
    out[0] = (c * v[0] + (w1 * v[2] - w2 * v[1])) + w0 * scale
    out[1] = (c * v[1] + (w2 * v[0] - w0 * v[2])) + w1 * scale
    out[2] = (c * v[2] + (w0 * v[1] - w1 * v[0])) + w2 * scale


@jit
def carry_item(
    out: F64,
    start: F64,
    lengths: F64,
    tidx: I64,
    count: int,
    weight: float,
    scratch: F64,
    flags: I64,
    anchor: I64,
    vecs: F64,
) -> None:  # pragma: no cover - compiled
    """``core.carry.carry_below`` for one pose ``out [21, 3]`` (joint order, bone lengths
    exact), in place: every joint below a targeted joint (not the root) with no target
    below it turns, from ``start``, with its anchor's bone, by ``weight``. Scratch:
    ``scratch [21, 3]``, ``flags``, ``anchor`` ``[21]`` (int64), ``vecs [5, 3]``."""
    for j in range(NUM_JOINTS):
        flags[j] = 0  # 1 targeted, 2 has a target below
        anchor[j] = -1
    for q in range(count):
        flags[tidx[q]] = 1
    for j in range(NUM_JOINTS - 1, 0, -1):
        if flags[j] != 0:
            p = PARENTS_J[j]
            flags[p] = flags[p] | 2
    found = False
    for j in range(1, NUM_JOINTS):
        p = PARENTS_J[j]
        if flags[j] != 0:
            continue
        if flags[p] & 1 and p != _PELVIS:
            anchor[j] = p
            found = True
        elif anchor[p] >= 0:
            anchor[j] = anchor[p]
    if not found:
        return
    for j in range(NUM_JOINTS):
        for i in range(3):
            scratch[j, i] = out[j, i]
    a_s, a_o, v, u, d = vecs[0], vecs[1], vecs[2], vecs[3], vecs[4]
    for j in range(1, NUM_JOINTS):
        a = anchor[j]
        if a < 0:
            continue
        p, pa = PARENTS_J[j], PARENTS_J[a]
        for i in range(3):
            a_s[i] = start[a, i] - start[pa, i]
            a_o[i] = out[a, i] - out[pa, i]
            v[i] = start[j, i] - start[p, i]
            d[i] = scratch[j, i] - scratch[p, i]
        swing_into(a_s, a_o, v, u)  # the start's bone, turned with the anchor's
        carried, ok = unit_into(u, u), unit_into(d, d)
        if carried and ok:
            for i in range(3):
                u[i] = weight * u[i] + (1.0 - weight) * d[i]
            ok = unit_into(u, d)
        elif carried:
            ok = unit_into(u, d)
        b = BONE_OF[j]
        for i in range(3):
            if ok:
                out[j, i] = out[p, i] + d[i] * lengths[b]
            else:  # nothing to turn by or to: the joint keeps its place on its parent
                out[j, i] = out[p, i] + scratch[j, i] - scratch[p, i]


@jit
def ends_item(
    out: F64,
    network: F64,
    tidx: I64,
    count: int,
    chains: Bool,
    flags: I64,
    vecs: F64,
    ease: float,
    collar: bool,
    side: float,
    soft: float,
) -> None:  # pragma: no cover - compiled
    """``core.ends.keep_ends`` for one pose ``out [21, 3]`` (after the bone pass) and its
    network pose ``network [21, 3]``, in place, for the chains ``chains [C]`` marks
    (``core.ends.active``), eased over ``ease`` m, wrists reached by turning the collar
    with ``collar``, bent towards ``core.ends.PREFER`` by ``side``, into full stretch
    over ``soft`` m (``core.ends.soft_reach``); ``flags [21]`` (int64) and ``vecs [5, 3]``
    are scratch."""
    for j in range(NUM_JOINTS):
        flags[j] = 0
    for q in range(count):
        flags[tidx[q]] = 1
    s, e0, w0, u, v = vecs[0], vecs[1], vecs[2], vecs[3], vecs[4]
    for c in range(_CHAINS.shape[0]):
        top, mid, end = _CHAINS[c, 0], _CHAINS[c, 1], _CHAINS[c, 2]
        if not chains[c] or flags[end] == 0 or flags[mid] != 0 or flags[top] != 0:
            continue
        below = False
        for j in range(NUM_JOINTS):
            if _ENDS_BELOW[c, j] and flags[j] != 0:
                below = True
        if below:
            continue
        for i in range(3):
            s[i], e0[i], w0[i] = out[top, i], out[mid, i], out[end, i]
        a = np.sqrt((e0[0] - s[0]) ** 2 + (e0[1] - s[1]) ** 2 + (e0[2] - s[2]) ** 2)
        b = np.sqrt((w0[0] - e0[0]) ** 2 + (w0[1] - e0[1]) ** 2 + (w0[2] - e0[2]) ** 2)
        for i in range(3):  # the goal of the end, then the line to it from the top
            u[i] = network[end, i]
        if ease > 0.0:
            gap = np.sqrt(
                (network[end, 0] - w0[0]) ** 2
                + (network[end, 1] - w0[1]) ** 2
                + (network[end, 2] - w0[2]) ** 2
            )
            if gap < ease:
                for i in range(3):
                    u[i] = w0[i] + (gap / ease) * (network[end, i] - w0[i])
        k = _ENDS_COLLARS[c]
        if collar and k >= 0 and flags[k] == 0 and _collar_turn(out, k, c, top, mid, end, u, a + b):
            for i in range(3):
                s[i], e0[i], w0[i] = out[top, i], out[mid, i], out[end, i]
        for i in range(3):
            u[i] = u[i] - s[i]
        d0 = np.sqrt(u[0] ** 2 + u[1] ** 2 + u[2] ** 2)
        if not (d0 > _ENDS_TINY and a > _ENDS_TINY):
            continue
        for i in range(3):
            u[i] = u[i] / d0
        d = d0
        k = min(soft, _SOFT_IK_LIMB * (a + b))  # core.ends.soft_reach
        if k > 0.0 and d0 > a + b - k:
            d = (a + b) - k * np.exp(-(d0 - ((a + b) - k)) / k)
        d = min(max(d, abs(a - b)), a + b)
        along = (e0[0] - s[0]) * u[0] + (e0[1] - s[1]) * u[1] + (e0[2] - s[2]) * u[2]
        for i in range(3):
            v[i] = (e0[i] - s[i]) - along * u[i]
        cos = min(max((a * a + d * d - b * b) / (2.0 * a * d), -1.0), 1.0)
        sin = np.sqrt(max(0.0, 1.0 - cos * cos))
        if side > 0.0:  # towards PREFER where the networks' bend is short of what is needed
            need = a * sin
            nb = np.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
            w = 1.0 - nb / (side * need) if need > _ENDS_TINY else 0.0
            if w > 0.0:
                for i in range(3):  # e0 (done with) takes the side u @ PREFER[c, :3] + PREFER[c, 3]
                    e0[i] = (u[0] * _PREFER[c, 0, i] + u[1] * _PREFER[c, 1, i]
                             + u[2] * _PREFER[c, 2, i]) + _PREFER[c, 3, i]  # fmt: skip
                pa = e0[0] * u[0] + e0[1] * u[1] + e0[2] * u[2]
                for i in range(3):
                    v[i] = v[i] + (w * need) * (e0[i] - pa * u[i])
        nb = np.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
        if not nb > _ENDS_TINY:
            continue
        for i in range(3):
            v[i] = v[i] / nb
        place_limb(out, c, s, u, v, a, d, cos, sin, w0)


@jit
def place_limb(
    out: F64, c: int, s: F64, u: F64, v: F64, a: float, d: float, cos: float, sin: float,
    w0: F64,
) -> None:  # pragma: no cover - compiled  # fmt: skip
    """Chain ``c``'s two-bone answer in place: its middle joint ``a`` from its top ``s``,
    at the angle (``cos``, ``sin``) from the unit line ``u`` towards the unit side ``v``;
    its end ``d`` along ``u`` (from where it was, ``w0``), the joints below moved with it."""
    mid, end = _CHAINS[c, 1], _CHAINS[c, 2]
    for i in range(3):
        shift = (s[i] + d * u[i]) - w0[i]
        out[mid, i] = s[i] + a * (cos * u[i] + sin * v[i])
        out[end, i] = w0[i] + shift
        for j in range(NUM_JOINTS):
            if _ENDS_BELOW[c, j]:
                out[j, i] += shift


@jit
def _collar_turn(
    out: F64, k: int, c: int, top: int, mid: int, end: int, goal: F64, reach: float
) -> bool:  # pragma: no cover - compiled
    """``core.ends._collar_turn`` for one pose, in place: the shoulder ``top`` turned about
    the collar ``k`` towards ``goal [3]``, the arm (``mid``, ``end`` and chain ``c``'s
    joints below it) moved with it. Whether it moved."""
    cx, cy, cz = out[k, 0], out[k, 1], out[k, 2]
    px, py, pz = out[top, 0] - cx, out[top, 1] - cy, out[top, 2] - cz
    cl = np.sqrt(px * px + py * py + pz * pz)
    dx, dy, dz = goal[0] - out[top, 0], goal[1] - out[top, 1], goal[2] - out[top, 2]
    if not (dx * dx + dy * dy + dz * dz > reach * reach and cl > _ENDS_TINY):
        return False
    px, py, pz = px / cl, py / cl, pz / cl
    wx, wy, wz = goal[0] - cx, goal[1] - cy, goal[2] - cz
    wp = wx * px + wy * py + wz * pz
    qx, qy, qz = wx - wp * px, wy - wp * py, wz - wp * pz
    wq = np.sqrt(qx * qx + qy * qy + qz * qz)
    if not wq > _ENDS_TINY:
        return False
    qx, qy, qz = qx / wq, qy / wq, qz / wq
    rho = np.sqrt(wp * wp + wq * wq)
    kk = (wx * wx + wy * wy + wz * wz + cl * cl - reach * reach) / (2.0 * cl)
    phi = np.arctan2(wq, wp)
    th = phi - np.arccos(min(kk / rho, 1.0)) if kk < rho else phi
    th = max(th, 0.0)
    o = OTHER_COLLAR[k]  # within the clavicle's cone about the collars' line
    ax, ay, az = cx - out[o, 0], cy - out[o, 1], cz - out[o, 2]
    na = np.sqrt(ax * ax + ay * ay + az * az)
    sc = na if na > _ENDS_TINY else 1.0
    ax, ay, az = ax / sc, ay / sc, az / sc
    ca, cb = ax * px + ay * py + az * pz, ax * qx + ay * qy + az * qz
    lim = min(np.cos(_CONE), ca)
    r = np.sqrt(ca * ca + cb * cb)
    if na > _ENDS_TINY and r > _ENDS_TINY:
        th = min(th, np.arctan2(cb, ca) + np.arccos(min(max(lim / r, -1.0), 1.0)))
    ct, st = np.cos(th), np.sin(th)
    shift = (
        (cx + cl * (ct * px + st * qx)) - out[top, 0],
        (cy + cl * (ct * py + st * qy)) - out[top, 1],
        (cz + cl * (ct * pz + st * qz)) - out[top, 2],
    )
    for j in range(NUM_JOINTS):
        if j in (top, mid, end) or _ENDS_BELOW[c, j]:
            for i in range(3):
                out[j, i] = out[j, i] + shift[i]
    return True


#: the legs' chains (rows of ``core.ends.CHAINS``: hip, knee, ankle)
_LEG_CHAINS = np.asarray(
    [
        c
        for c, end in enumerate(_CHAINS[:, 2])
        if end in (JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"])
    ],
    dtype=np.int64,
)


@jit
def floor_item(
    out: F64, start: F64, tidx: I64, count: int, flags: I64, vecs: F64, plant: bool = False
) -> None:  # pragma: no cover - compiled
    """Feet kept over the floor, for one canonical pose ``out [21, 3]`` (the floor at y 0)
    of the start ``start [21, 3]``, in place (``serving.keep_feet``): a leg none of whose
    hip, knee, ankle and foot is among the targets and pins ``tidx[:count]``, whose ankle
    or foot ends below the floor (or below the lower of the two in the start, where that
    is lower), has its ankle and foot raised by what the lower sank, the hip where it is
    and the knee bent to fit in the plane it bends in (towards ``core.ends.PREFER`` where
    the leg is straight); as far as the leg folds. A pelvis dragged down crouches the body
    instead of sinking its feet (an audit, 2026-12-07: the docs' pose with its pelvis
    dragged from 0.93 m to 0.6 m had its ankles 8 cm under the floor). With ``plant``
    (``out`` a polish of ``start``, the networks' answer) such a leg's lowest joint goes back
    to the height it had in ``start``, raised or lowered, as far as the leg stretches: a
    polish that lifts the trunk to hold a pin does not lift the feet with it (the docs'
    pose, its pelvis dragged down with its head pinned, ended crouched with its feet 0.55 m
    in the air). A leg whose knee or ankle is a target or pin has what hangs below the
    lowest of them lifted over the floor by :func:`_flex_below` (a hip alone asked counts as
    none). ``flags [21]`` (int64) and ``vecs [5, 3]`` are scratch."""
    for j in range(NUM_JOINTS):
        flags[j] = 0
    for q in range(count):
        flags[tidx[q]] = 1
    s, w0, u, v = vecs[0], vecs[1], vecs[2], vecs[3]
    for c in _LEG_CHAINS:
        top, mid, end = _CHAINS[c, 0], _CHAINS[c, 1], _CHAINS[c, 2]
        asked = flags[top] + flags[mid] + flags[end]
        low, was = out[end, 1], start[end, 1]
        for j in range(NUM_JOINTS):
            if _ENDS_BELOW[c, j]:
                asked += flags[j]
                low, was = min(low, out[j, 1]), min(was, start[j, 1])
        lift = was - low if plant else min(0.0, was) - low
        if asked != 0 and asked == flags[top] and not plant:
            asked = 0  # (only the hip asked: it stays where it is all the same)
        if asked != 0:  # below a target or pin: bent further about it
            _flex_below(out, start, c, flags)
            continue
        if not (lift > 0.0 or (plant and lift < -_ENDS_TINY)):
            continue
        for i in range(3):
            s[i], w0[i] = out[top, i], out[end, i]
            u[i] = w0[i] - s[i]
        u[1] += lift
        a = np.sqrt(
            (out[mid, 0] - s[0]) ** 2 + (out[mid, 1] - s[1]) ** 2 + (out[mid, 2] - s[2]) ** 2
        )
        b = np.sqrt(
            (w0[0] - out[mid, 0]) ** 2 + (w0[1] - out[mid, 1]) ** 2 + (w0[2] - out[mid, 2]) ** 2
        )
        d0 = np.sqrt(u[0] ** 2 + u[1] ** 2 + u[2] ** 2)
        if not (d0 > _ENDS_TINY and a > _ENDS_TINY and b > _ENDS_TINY):
            continue
        for i in range(3):
            u[i] = u[i] / d0
        d = min(max(d0, abs(a - b)), a + b)
        along = (
            (out[mid, 0] - s[0]) * u[0] + (out[mid, 1] - s[1]) * u[1] + (out[mid, 2] - s[2]) * u[2]
        )
        for i in range(3):
            v[i] = (out[mid, i] - s[i]) - along * u[i]
        nb = np.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
        if not nb > 1e-6 * a:  # a straight leg: the side knees bend to
            for i in range(3):
                v[i] = (u[0] * _PREFER[c, 0, i] + u[1] * _PREFER[c, 1, i]
                        + u[2] * _PREFER[c, 2, i]) + _PREFER[c, 3, i]  # fmt: skip
            pa = v[0] * u[0] + v[1] * u[1] + v[2] * u[2]
            for i in range(3):
                v[i] = v[i] - pa * u[i]
            nb = np.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
            if not nb > _ENDS_TINY:
                continue
        for i in range(3):
            v[i] = v[i] / nb
        cos = min(max((a * a + d * d - b * b) / (2.0 * a * d), -1.0), 1.0)
        place_limb(out, c, s, u, v, a, d, cos, np.sqrt(max(0.0, 1.0 - cos * cos)), w0)


#: How far short of folding onto the bone above a leg's joint below a target or pin may be
#: bent further to lift what hangs from it over the floor (radians), and the halvings of
#: the search for the least bend that does.
_FLEX_SPARE, _FLEX_HALVINGS = np.radians(20.0), 40
#: How far under the floor (a share of the leg's length, hip to ankle: ~3 cm) a leg below a
#: target or pin may end before it is bent: a shin swung to lift its foot a few mm moves the
#: ankle centimetres across (bent at every small sink, the held-out ReActIdle knees' MPJPE
#: went 0.95 -> 1.17-1.23 cm: its takes stand below the floor the edits read)
FLEX_MARGIN = 0.035


@jit
def _bent_into(r: F64, p: F64, angle: float, out: F64) -> None:  # pragma: no cover
    """``out``: the unit vector ``angle`` (radians) from the unit ``r`` towards the unit
    ``p`` across it (the first bone below a leg's asked joint, bent further)."""
    ca, sa = np.cos(angle), np.sin(angle)
    out[0], out[1], out[2] = r[0] * ca + p[0] * sa, r[1] * ca + p[1] * sa, r[2] * ca + p[2] * sa


@jit
def _turned_low(
    out: F64, c: int, pivot: int, first: int, r: F64, p: F64, angle: float
) -> float:  # pragma: no cover
    """The height of the lowest of ``first`` and the joints below chain ``c``'s end once
    turned about ``pivot`` by ``angle`` from ``r`` towards ``p`` (:func:`_bent_into`;
    ``out [21, 3]``)."""
    d, turned = np.empty(3), np.empty(3)
    _bent_into(r, p, angle, d)
    m = np.inf
    for j in range(NUM_JOINTS):
        if j == first or _ENDS_BELOW[c, j]:
            swing_into(r, d, out[j] - out[pivot], turned)
            m = min(m, out[pivot, 1] + turned[1])
    return m


@jit
def _flex_below(out: F64, start: F64, c: int, flags: I64) -> None:  # pragma: no cover
    """:func:`floor_item` of a leg (chain ``c``: hip, knee, ankle; the foot below) some of
    whose joints are targets or pins (``flags``), in place: below the lowest of them (the
    knee or the ankle), what sinks under the floor by more than :data:`FLEX_MARGIN` (or
    under the lower of its joints in ``start``, where that is lower) is bent further about
    that joint, in the plane its two bones there bend in, by the least angle that lifts it
    over (at most to :data:`_FLEX_SPARE` short of folding onto the bone above, as far as
    that lifts it): a knee dragged down kneels, its shin swung back, and an ankle pinned in
    a crouch lifts its toes. The asked joints stay where they are. A knee lowered from 0.54
    to 0.15 m had put its foot 25 cm under the floor, and ankles pinned in a crouch their
    toes 2-5 cm (two API audits, 2026-12-07)."""
    hip, knee, ankle = _CHAINS[c, 0], _CHAINS[c, 1], _CHAINS[c, 2]
    if flags[ankle] != 0:
        pivot, above, first = ankle, knee, -1
        for j in range(NUM_JOINTS):
            if _ENDS_BELOW[c, j]:
                if flags[j] != 0:
                    return  # (the foot asked too: nothing below it to bend)
                if PARENTS[j] == ankle:
                    first = j
        if first < 0:
            return
    elif flags[knee] != 0:
        pivot, above, first = knee, hip, ankle
        for j in range(NUM_JOINTS):
            if _ENDS_BELOW[c, j] and flags[j] != 0:
                return  # (a foot asked below an unasked ankle: the polish's own)
    else:
        return
    low, was = np.inf, np.inf
    for j in range(NUM_JOINTS):
        if j == first or _ENDS_BELOW[c, j]:
            low, was = min(low, out[j, 1]), min(was, start[j, 1])
    leg = 0.0
    for a, z in ((hip, knee), (knee, ankle)):
        leg += np.sqrt(
            (out[z, 0] - out[a, 0]) ** 2 + (out[z, 1] - out[a, 1]) ** 2
            + (out[z, 2] - out[a, 2]) ** 2
        )  # fmt: skip
    level = min(-FLEX_MARGIN * leg, was)
    if not low < level:
        return
    r, p = np.empty(3), np.empty(3)  # the bone below, and across it towards the bone above
    if not unit_into(out[first] - out[pivot], r):
        return
    t = out[above] - out[pivot]
    along = t[0] * r[0] + t[1] * r[1] + t[2] * r[2]
    across = t - along * r
    lt = np.sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2])
    wide = np.sqrt(across[0] * across[0] + across[1] * across[1] + across[2] * across[2])
    if not (lt > _ENDS_TINY and wide > 1e-9 * lt and unit_into(across, p)):
        return  # (straight there: no plane to bend in)
    most = np.arccos(min(max(along / lt, -1.0), 1.0)) - _FLEX_SPARE
    if not most > 0.0:
        return
    if _turned_low(out, c, pivot, first, r, p, most) < level:  # as far as it lifts
        best, hi = -np.inf, 0.0
        for i in range(1, 65):
            h = _turned_low(out, c, pivot, first, r, p, most * i / 64)
            if h > best:
                best, hi = h, most * i / 64
    else:
        lo, hi = 0.0, most
        for _ in range(_FLEX_HALVINGS):
            mid = 0.5 * (lo + hi)
            if _turned_low(out, c, pivot, first, r, p, mid) >= level:
                hi = mid
            else:
                lo = mid
    d, turned = np.empty(3), np.empty(3)
    _bent_into(r, p, hi, d)
    for j in range(NUM_JOINTS):
        if j == first or _ENDS_BELOW[c, j]:
            swing_into(r, d, out[j] - out[pivot], turned)
            for i in range(3):
                out[j, i] = out[pivot, i] + turned[i]


@jit
def floor_group(
    out: F64, start: F64, idx: I64, plant: bool = False
) -> None:  # pragma: no cover - compiled
    """:func:`floor_item` of every pose of ``out [M, 21, 3]`` (of the starts ``start``),
    in place, their targets and pins the joints ``idx [K]`` (one target set)."""
    flags, vecs = np.empty(NUM_JOINTS, np.int64), np.empty((5, 3))
    for b in range(out.shape[0]):
        floor_item(out[b], start[b], idx, idx.shape[0], flags, vecs, plant)
