"""The chest of a FABRIK solve as one rigid body, and a cone on each clavicle.

Textbook FABRIK turns every bone on its own. A wrist reached far across the body then
swings its collar's bone and its clavicle across the chest while the other shoulder is
carried where it was: over 240 one-wrist reaches of 0.4-1.0 m from 120 real poses the
shoulders ended below 80 % of their width in 84-88 answers, 25-36 of them below 60 %
(neural soft, exact and FABRIK alike, with and without pinned ankles). Real motion never
does that: over 174,996 pairs of TRAIN frames 0.2-1 s apart the collar-to-collar distance
changed by 1.5e-6 of itself at most and the shoulders came no nearer than 0.929 of the
first frame's width (both tables: ``python -m bench.chest``, docs/kinematics.md).

So, in FABRIK's backward pass, both collars are placed as one rigid body with ``spine2``
(:func:`place`): the start's offsets turned by the swing of the spine bone (``spine1`` to
``spine2``), then about that bone by the twist, and by a tilt of at most :data:`TILT`, that
best turn the moving collars towards their proposals, each weighted as in the chest's
centroid (a pinned chain's alone; :func:`turn`, :func:`weights`). The forward pass moves
the chest's proposal with its collars as it stands, as it does a rigid hip. The neck stays
a free bone (:data:`KIDS`). A chest the polish's trunk-locked stage holds stays as it is.
Joints the iteration leaves alone below the chest (the neck and head, an arm) turn with it
(:func:`carried`).

Each clavicle (collar to shoulder) stays within :data:`CLAVICLE_CONE` of the chest's
across axis (collar from collar, turned with the chest), or within its start's angle to it
where that is wider (:func:`cone`), in both passes. ``serving.keep_collar``'s turn of a
kept wrist's collar is held to the same cone (``core.ends``).

A target or pin on a collar or a shoulder turns all of this off for its solve
(:func:`applies`). Pins come first: where this chest lets a pin go (a collar dragged above
a pinned shoulder, a chest dragged over a pinned wrist: the pins' shells assume free
bones), the same solve
with textbook bones is kept if it holds the pins better. Where it stops short of a target
(a constrained fixed point: a polish 2-12 mm short of wrists textbook FABRIK met in 2-3
iterations), the textbook answer is kept where it meets every target and pin and
:func:`kept` the chest (``kinematics._held``, the compiled ``solve_batch``): a target out
of either's reach keeps the natural answer.

Internal layout of :mod:`core.kinematics` (``[21, 3, N]``, rank order); the compiled
kernels (:mod:`core.compiled_chest`) compute the same in the same order, held equal in
tests/core/test_chest.py.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from core.layout import _RANK
from core.shells import TINY
from core.skeleton import JOINT_INDEX, NUM_JOINTS

F64 = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

#: Most a clavicle turns from the chest's across axis, radians: in TRAIN it strays from its
#: mean direction in the chest 37 degrees at the 99.9th percentile, 46 at most
#: (``python -m bench.chest``).
CLAVICLE_CONE = float(np.radians(40.0))
#: Most the chest tilts, besides the swing of the spine bone and a twist about it, to turn
#: its collars towards their proposals, radians (TRAIN: the collars turn against the spine
#: bone 13 degrees at the 99th percentile, 20 at the 99.9th; ``python -m bench.chest``).
TILT = float(np.radians(20.0))

SPINE1 = int(_RANK[JOINT_INDEX["spine1"]])
SPINE2 = int(_RANK[JOINT_INDEX["spine2"]])
L_COLLAR = int(_RANK[JOINT_INDEX["left_collar"]])
R_COLLAR = int(_RANK[JOINT_INDEX["right_collar"]])
L_SHOULDER = int(_RANK[JOINT_INDEX["left_shoulder"]])
R_SHOULDER = int(_RANK[JOINT_INDEX["right_shoulder"]])
#: A textbook answer kept where the natural chest missed a target keeps the collars within
#: this share of their distance and the shoulders at least this share of their width apart.
#: Its extra reach is the collars moved apart (6-18 % on four polishes of real edits on
#: other bodies that the natural chest left 2-12 mm short; a /tmp check, 2026-12-07); a
#: fold brings the shoulders together (TRAIN: never nearer than 0.929 of their width,
#: ``python -m bench.chest``).
SPAN, WIDTH = 0.25, 0.9
#: The chest's rigid children (ranks, ascending): both collars. The neck stays a free bone:
#: held to the chest's turn it would lose the spine's bend at ``spine2`` (a neck pinned
#: 25 cm off a moved start missed its pin by 14-30 cm).
KIDS: npt.NDArray[np.int64] = np.sort(np.asarray([L_COLLAR, R_COLLAR], dtype=np.int64))
#: What the chest's turn fits (ranks): its collars, and the shoulders as the chest holds
#: them, so that a chest whose collars sit near the spine (a child's, 4 cm apart) still
#: turns where the arms pull (its collars alone left both of its wrists 12 cm short).
FIT: npt.NDArray[np.int64] = np.asarray([L_COLLAR, R_COLLAR, L_SHOULDER, R_SHOULDER])
#: Per rank of :data:`FIT`, the collar whose weight it takes
FIT_WEIGHT: npt.NDArray[np.int64] = np.asarray([L_COLLAR, R_COLLAR, L_COLLAR, R_COLLAR])


def _mat_vec(rot: F64, v: Any) -> list[Any]:
    """``rot [N, 3, 3]`` times ``v`` (three ``[N]`` components), summed left to right."""
    return [(rot[:, c, 0] * v[0] + rot[:, c, 1] * v[1]) + rot[:, c, 2] * v[2] for c in range(3)]


def _swing(a: list[Any], b: list[Any], limit: float) -> tuple[F64, BoolArray]:
    """Per item ``[N, 3, 3]`` the minimal rotation taking direction ``a`` to ``b`` (three
    ``[N]`` components each), by at most ``limit`` radians (``np.pi``: none); and where it
    is not the identity (equal or degenerate directions)."""
    na = np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    nb = np.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2])
    same = (a[0] == b[0]) & (a[1] == b[1]) & (a[2] == b[2])
    on = ~same & (na > TINY) & (nb > TINY)
    with np.errstate(divide="ignore", invalid="ignore"):
        au = [a[c] / na for c in range(3)]
        bu = [b[c] / nb for c in range(3)]
        cs = au[0] * bu[0] + au[1] * bu[1] + au[2] * bu[2]
        w = [au[1] * bu[2] - au[2] * bu[1], au[2] * bu[0] - au[0] * bu[2],
             au[0] * bu[1] - au[1] * bu[0]]  # fmt: skip
        sn = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
        if limit < np.pi:  # by ``limit`` about the same axis
            over = np.arctan2(sn, cs) > limit
            on &= ~(over & (sn <= TINY))
            cs = np.where(over, np.cos(limit), cs)
            w = [np.where(over, np.sin(limit) * w[c] / sn, w[c]) for c in range(3)]
        d = np.maximum(1.0 + cs, 1e-12)
        m = [
            [cs + w[0] * w[0] / d, -w[2] + w[0] * w[1] / d, w[1] + w[0] * w[2] / d],
            [w[2] + w[1] * w[0] / d, cs + w[1] * w[1] / d, -w[0] + w[1] * w[2] / d],
            [-w[1] + w[2] * w[0] / d, w[0] + w[2] * w[1] / d, cs + w[2] * w[2] / d],
        ]
    out = np.broadcast_to(np.eye(3), (len(na), 3, 3)).copy()
    for i in range(3):
        for j in range(3):
            out[:, i, j] = np.where(on, m[i][j], out[:, i, j])
    return out, on


def _times(t: Any, rot: F64) -> F64:
    """``t @ rot`` per item (``t`` ``[N, 3, 3]`` or nested lists of ``[N]``), summed left
    to right."""
    out = np.empty_like(rot)
    for i in range(3):
        for j in range(3):
            out[:, i, j] = (t[i][0] * rot[:, 0, j] + t[i][1] * rot[:, 1, j]) + t[i][2] * rot[
                :, 2, j
            ]
    return out


def turn(x0: F64, y: F64, pts: F64, w: F64, free: bool) -> F64:
    """The chest's rotation since ``x0`` ``[N, 3, 3]``: the swing of the spine bone from
    ``x0`` to ``y``; then (``free``) the twist about that bone, and a tilt of at most
    :data:`TILT`, that best turn the collars (weights ``w [21]`` by rank) towards ``pts``
    around ``y``'s ``spine2`` (their forward proposals). Arrays ``[21, 3, N]``."""
    a1 = [y[SPINE2, c] - y[SPINE1, c] for c in range(3)]
    rot, _ = _swing([x0[SPINE2, c] - x0[SPINE1, c] for c in range(3)], a1, np.pi)
    kids = [
        (int(k), float(w[c]))
        for k, c in zip(FIT, FIT_WEIGHT, strict=True)
        if w[k] > 0.0 and w[c] > 0.0
    ]
    if not free or not kids:
        return rot
    n1 = np.sqrt(a1[0] * a1[0] + a1[1] * a1[1] + a1[2] * a1[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        k0, k1, k2 = (a1[c] / n1 for c in range(3))
    n = len(n1)
    num, den = np.zeros(n), np.zeros(n)
    for k, wk in kids:
        u = _mat_vec(rot, [x0[k, c] - x0[SPINE2, c] for c in range(3)])
        dd = [pts[k, c] - y[SPINE2, c] for c in range(3)]
        au = k0 * u[0] + k1 * u[1] + k2 * u[2]
        ad = k0 * dd[0] + k1 * dd[1] + k2 * dd[2]
        num = num + wk * (
            k0 * (u[1] * dd[2] - u[2] * dd[1])
            + k1 * (u[2] * dd[0] - u[0] * dd[2])
            + k2 * (u[0] * dd[1] - u[1] * dd[0])
        )
        den = den + wk * ((u[0] * dd[0] + u[1] * dd[1] + u[2] * dd[2]) - au * ad)
    twist = (n1 > TINY) & (num != 0.0)
    phi = np.arctan2(num, den)
    s, c1 = np.sin(phi), 1.0 - np.cos(phi)
    t = [
        [1.0 - c1 * (k1 * k1 + k2 * k2), -s * k2 + c1 * k0 * k1, s * k1 + c1 * k0 * k2],
        [s * k2 + c1 * k1 * k0, 1.0 - c1 * (k0 * k0 + k2 * k2), -s * k0 + c1 * k1 * k2],
        [-s * k1 + c1 * k2 * k0, s * k0 + c1 * k2 * k1, 1.0 - c1 * (k0 * k0 + k1 * k1)],
    ]
    rot = np.where(twist[:, None, None], _times(t, rot), rot)
    co, cd = [np.zeros(n) for _ in range(3)], [np.zeros(n) for _ in range(3)]
    for k, wk in kids:
        u = _mat_vec(rot, [x0[k, c] - x0[SPINE2, c] for c in range(3)])
        for c in range(3):
            co[c] = co[c] + wk * u[c]
            cd[c] = cd[c] + wk * (pts[k, c] - y[SPINE2, c])
    tilt, on = _swing(co, cd, TILT)
    tilted = _times([[tilt[:, i, j] for j in range(3)] for i in range(3)], rot)
    out: F64 = np.where((on & (n1 > TINY))[:, None, None], tilted, rot)
    return out


def place(x0: F64, y: F64, kid: int, rot: F64) -> F64:
    """Chest child ``kid``'s place ``[3, N]``: ``y[spine2] + rot (x0[kid] - x0[spine2])``."""
    o = [x0[kid, c] - x0[SPINE2, c] for c in range(3)]
    r = _mat_vec(rot, o)
    return np.stack([y[SPINE2, c] + r[c] for c in range(3)])


def cone(x0: F64, kid: int, rot: F64, u: F64) -> tuple[F64, BoolArray]:
    """The unit clavicle direction ``u [3, N]`` of shoulder ``kid`` (rank) kept within
    :data:`CLAVICLE_CONE` (or the start's own angle, if wider) of the chest's across axis
    turned by ``rot``; and where it changed."""
    side = 1.0 if kid == L_SHOULDER else -1.0
    col = L_COLLAR if kid == L_SHOULDER else R_COLLAR
    e = [side * (x0[L_COLLAR, c] - x0[R_COLLAR, c]) for c in range(3)]
    ne = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    cv = [x0[kid, c] - x0[col, c] for c in range(3)]
    nc = np.sqrt(cv[0] * cv[0] + cv[1] * cv[1] + cv[2] * cv[2])
    valid = nc > TINY
    across = ne > TINY
    with np.errstate(divide="ignore", invalid="ignore"):
        own = (e[0] * cv[0] + e[1] * cv[1] + e[2] * cv[2]) / (ne * nc)
        limit = np.where(across, np.minimum(np.cos(CLAVICLE_CONE), own), np.cos(CLAVICLE_CONE))
        axis = [np.where(across, e[c] / ne, cv[c] / nc) for c in range(3)]
    m = _mat_vec(rot, axis)
    cu = m[0] * u[0] + m[1] * u[1] + m[2] * u[2]
    out = valid & ~(cu >= limit)
    if not out.any():
        return u, out
    p = [u[c] - cu * m[c] for c in range(3)]
    n = np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    back = n <= TINY  # straight back along the axis: towards the start's clavicle
    if back.any():
        q = _mat_vec(rot, cv)
        cq = m[0] * q[0] + m[1] * q[1] + m[2] * q[2]
        p = [np.where(back, q[c] - cq * m[c], p[c]) for c in range(3)]
        n = np.where(back, np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]), n)
    sn = np.sqrt(np.maximum(1.0 - limit * limit, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        new = [np.where(n <= TINY, m[c], limit * m[c] + sn * p[c] / n) for c in range(3)]
    return np.stack([np.where(out, new[c], u[c]) for c in range(3)]), out


def weights(forward: Any, backward: Any) -> F64:
    """Per rank ``[21]``, a moving collar's weight in the chest's turn: its chain's in the
    chest's centroid (``kinematics._Plan.forward``; 1 where the chest takes none), -1
    where it does not move; at ``spine2`` 1 where the chest moves, 0 where not."""
    w = np.full(NUM_JOINTS, -1.0)
    for kids, _, _ in backward:
        w[kids] = 1.0
    w[SPINE2] = 1.0 if w[SPINE2] > 0.0 else 0.0
    for fw in forward:
        rows = fw.rows.tolist()
        for col, (kid, par) in enumerate(zip(fw.kids.tolist(), fw.parents.tolist(), strict=True)):
            if kid in (L_COLLAR, R_COLLAR):
                w[kid] = 1.0 if fw.mix is None else float(fw.mix[rows.index(par), col])
    return w


def applies(target_ranks: npt.ArrayLike) -> bool:
    """Whether a target set (ranks) gets the natural chest: none of its targets or pins is
    on a collar or a shoulder (those say where they go: a completion of all 21 key points
    came back 5 mm off its own collars, the start's chest another shape)."""
    return not bool(np.isin(np.asarray(target_ranks), FIT).any())


def kept(x0: F64, x: F64) -> BoolArray:
    """``[N]`` whether answers ``x`` kept the chest of their starts ``x0`` (``[21, 3, N]``):
    the collars within :data:`SPAN` of their distance, the shoulders at least :data:`WIDTH`
    of theirs apart (the textbook retry of a target the natural chest missed, ``_held``)."""

    def gap(p: F64, a: int, b: int) -> F64:
        d = [p[a, c] - p[b, c] for c in range(3)]
        out: F64 = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        return out

    span0, span = gap(x0, L_COLLAR, R_COLLAR), gap(x, L_COLLAR, R_COLLAR)
    ok: BoolArray = (np.abs(span - span0) <= SPAN * span0) & (
        gap(x, L_SHOULDER, R_SHOULDER) >= WIDTH * gap(x0, L_SHOULDER, R_SHOULDER)
    )
    return ok


def turns(w: F64) -> bool:
    """Whether a plan's chest turns (weights ``w``: :func:`weights`): it moves and so does
    a collar."""
    return bool(w[SPINE2] > 0.0 and max(w[L_COLLAR], w[R_COLLAR]) >= 0.0)


def forward(
    x0: F64, x: F64, proposal: F64, kids: npt.NDArray[np.intp], q: F64, lens: F64, rot: F64
) -> None:
    """FABRIK's forward step for ``kids`` (ranks; their parents' proposals ``q [k, 3, N]``,
    in place): a shoulder's clavicle within its :func:`cone` of the chest turned by ``rot``
    (its turn in ``x``), the chest moved with its collars as it stands."""
    for i, kid in enumerate(kids.tolist()):
        if kid in (L_SHOULDER, R_SHOULDER):
            ln = lens[kid - 1]
            with np.errstate(divide="ignore", invalid="ignore"):
                u = (proposal[kid] - q[i]) / ln
            u, changed = cone(x0, kid, rot, u)
            q[i] = np.where(changed & (ln > 0.0), proposal[kid] - u * ln, q[i])
        elif kid in (L_COLLAR, R_COLLAR):
            q[i] = proposal[kid] - (x[kid] - x[SPINE2])


def backward(
    x0: F64, y: F64, proposal: F64, kids: npt.NDArray[np.intp], lens: F64, w: F64,
    rot: F64 | None,
) -> F64 | None:  # fmt: skip
    """FABRIK's backward step for ``kids`` (ranks) after ``y`` got them, in place: the
    collars placed as one body turned by :func:`turn` (weights ``w``: :func:`weights`),
    returned for the next level (or ``rot`` as it came), then each shoulder's clavicle
    within its :func:`cone`."""
    ks = kids.tolist()
    collars = [k for k in ks if k in (L_COLLAR, R_COLLAR)]
    if collars:
        rot = turn(x0, y, proposal, w, bool(w[SPINE2] > 0.0))
        for k in collars:
            y[k] = place(x0, y, k, rot)
    for k in ks:
        if k not in (L_SHOULDER, R_SHOULDER) or rot is None:
            continue
        par, ln = (L_COLLAR if k == L_SHOULDER else R_COLLAR), lens[k - 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (y[k] - y[par]) / ln
        u, changed = cone(x0, k, rot, u)
        y[k] = np.where(changed & (ln > 0.0), y[par] + u * ln, y[k])
    return rot


def carried(x0: F64, x: F64, kid: int, anchor: int, rot: F64) -> F64:
    """``[3, N]`` where a joint the iteration left alone hanging from the chest goes."""
    r = _mat_vec(rot, [x0[kid, c] - x0[anchor, c] for c in range(3)])
    return np.stack([x[anchor, c] + r[c] for c in range(3)])
