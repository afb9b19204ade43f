"""The damped least-squares steps of :mod:`core.reach`, compiled (numba, :mod:`core.jit`).

:func:`core.reach.polish` moves a character's joints by Levenberg-Marquardt steps, each one
forward kinematics of the character's own skeleton; in numpy a step cost ~0.3 ms (the
kernel calls, the small arrays, the linear solve), and a polish up to 90 steps. Here one
step is the same arithmetic written out in loops: the Jacobian of the canonical points,
the damped normal equations on the smaller side (``(J Jᵀ + λI) y = e, x = Jᵀ y`` or
``(JᵀJ + λI) x = Jᵀ e``: the same step), solved by Cholesky (no BLAS or LAPACK: numba's
need SciPy, which the service does not install). A pivot that is not positive is common:
JᵀJ of a rank-deficient J (a twist about a bone) once the damping has fallen below its
rounding; the step is then solved again with ten times the damping, as numpy's LU on the
other side never needed (a review: refusing the step instead wasted up to 11 of a phase's
30 steps and broke a pin numpy held). A step is cut to the largest turn (``max_turn``);
where targets and pins pull together and the cut bites, the step of a damping raised until
it fits is tried beside it and the better kept (a far wrist's swing of the arm had shrunk
the spine's turn that brings a pinned neck back: ``python -m bench.pins --characters``, 48
edits with a pin over 2 mm off, up to 91.5 mm, before; none after). A step taken divides
the damping by 3 (by 10, every other step was refused and the damping put back). A refused
step counts as a try, not a step: a phase takes up to ``steps`` steps in ``3 x steps`` tries
(a soft neck edit on ReActIdle ended 0.83 mm off the canonical answer's miss with its budget
spent on refusals, 0.72 mm now). The turns by Rodrigues' formula, each built about its
axis taken into the parent's frame, so that a local rotation stays a rotation however deep
(:func:`_turn_into`: ``Pᵀ T P`` drifted, pins 5-104 mm off on a long spine), forward
kinematics (:func:`core.compiled_characters.forward_kinematics_into`). Products in source order, no
fused multiply-add: the same request gives the same bits.
"""

from __future__ import annotations

import numpy as np

from core.compiled_characters import F64, I64, forward_kinematics_into, mul33_into
from core.jit import jit

#: Tries per step of the budget: a refused step (the damping raised) counts as a try, not a
#: step, so ``steps`` of them are not spent on refusals alone.
_TRIES = 3


@jit
def points_into(
    g_rot: F64, g_pos: F64, anchor: I64, offset: F64, out: F64
) -> None:  # pragma: no cover - compiled
    """The canonical points ``out [K, 3]``: joint ``anchor[i]``'s origin plus its rotation
    times ``offset[i]``."""
    for i in range(anchor.shape[0]):
        a = anchor[i]
        for r in range(3):
            out[i, r] = g_pos[a, r] + (
                g_rot[a, r, 0] * offset[i, 0]
                + g_rot[a, r, 1] * offset[i, 1]
                + g_rot[a, r, 2] * offset[i, 2]
            )


@jit
def _misses_into(points: F64, goals: F64, out: F64) -> None:  # pragma: no cover - compiled
    for i in range(points.shape[0]):
        d0 = points[i, 0] - goals[i, 0]
        d1 = points[i, 1] - goals[i, 1]
        d2 = points[i, 2] - goals[i, 2]
        out[i] = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@jit
def _cost(misses: F64, weight: F64) -> float:  # pragma: no cover - compiled
    total = 0.0
    for i in range(misses.shape[0]):
        w = misses[i] * weight[i]
        total += w * w
    return total


@jit
def _gram_into(a: F64, damping: float, out: F64) -> None:  # pragma: no cover - compiled
    """``out = a aᵀ + damping I`` (``a [n, m]``; ``a`` may be a transposed view)."""
    for i in range(a.shape[0]):
        for j in range(i + 1):
            s = 0.0
            for c in range(a.shape[1]):
                s += a[i, c] * a[j, c]
            out[i, j] = s
            out[j, i] = s
        out[i, i] += damping


@jit
def _product_into(a: F64, x: F64, out: F64) -> None:  # pragma: no cover - compiled
    """``out = a x`` (``a [n, m]``, ``x [m]``; ``a`` may be a transposed view)."""
    for i in range(a.shape[0]):
        s = 0.0
        for c in range(a.shape[1]):
            s += a[i, c] * x[c]
        out[i] = s


@jit
def _cholesky_solve(a: F64, b: F64) -> bool:  # pragma: no cover - compiled
    """Solve ``a x = b`` in place (``b`` becomes ``x``; ``a`` its Cholesky factor) for a
    symmetric ``a``; False where a pivot is not positive (not positive definite in
    floating point)."""
    n = a.shape[0]
    for j in range(n):
        s = a[j, j]
        for q in range(j):
            s -= a[j, q] * a[j, q]
        if not s > 0.0:
            return False
        d = np.sqrt(s)
        a[j, j] = d
        for i in range(j + 1, n):
            t = a[i, j]
            for q in range(j):
                t -= a[i, q] * a[j, q]
            a[i, j] = t / d
    for i in range(n):  # L z = b
        t = b[i]
        for q in range(i):
            t -= a[i, q] * b[q]
        b[i] = t / a[i, i]
    for i in range(n - 1, -1, -1):  # Lᵀ x = z
        t = b[i]
        for q in range(i + 1, n):
            t -= a[q, i] * b[q]
        b[i] = t / a[i, i]
    return True


@jit
def descend_into(
    parents: I64,
    rotations: F64,
    translations: F64,
    anchor: I64,
    offset: F64,
    goals: F64,
    weight: F64,
    movable: I64,
    above: F64,
    root: int,
    scale: float,
    hold: float,
    n: int,
    k: int,
    tolerance: float,
    steps: int,
    max_turn: float,
    stall: int,
    gain: float,
    misses: F64,
) -> int:  # pragma: no cover - compiled
    """Levenberg-Marquardt on the ``weight``-ed squares of the points' misses from
    ``goals`` (points: ``anchor``, ``offset``; the first ``n`` met: ``k`` targets, then
    pins), by world turns of the ``movable`` joints (``above [M, K]``: 1 where point ``i``
    hangs from joint ``m``) and a move of ``root`` (-1: none) priced at ``scale``; a step
    that takes a pin farther than ``hold`` is refused. ``rotations``, ``translations`` and
    ``misses`` (in: the start's) are updated in place; returns the steps taken."""
    nj, npts, nm = parents.shape[0], anchor.shape[0], movable.shape[0]
    ncol = 3 * nm + (3 if root >= 0 else 0)
    nrow = 3 * npts
    g_rot, g_pos = np.empty((nj, 3, 3)), np.empty((nj, 3))
    n_rot, n_pos = np.empty((nj, 3, 3)), np.empty((nj, 3))
    new_rot, new_tr = np.empty((nj, 3, 3)), np.empty((nj, 3))
    pts, n_pts, now = np.empty((npts, 3)), np.empty((npts, 3)), np.empty(npts)
    jac, err = np.zeros((nrow, ncol)), np.empty(nrow)
    small = min(nrow, ncol)
    normal, rhs, step = np.empty((small, small)), np.empty(small), np.empty(ncol)
    part, a_rot, a_tr = np.empty(ncol), np.empty((nj, 3, 3)), np.empty((nj, 3))
    a_grot, a_gpos, a_pts, a_now = (np.empty((nj, 3, 3)), np.empty((nj, 3)),
                                    np.empty((npts, 3)), np.empty(npts))  # fmt: skip
    forward_kinematics_into(parents, rotations, translations, g_rot, g_pos)
    points_into(g_rot, g_pos, anchor, offset, pts)
    cost = _cost(misses, weight)
    damping = 0.01 * scale * scale
    seen = np.empty(steps + 1)
    seen[0] = cost
    taken, tries = 0, 0
    while taken < steps and tries < _TRIES * steps:  # a refused step is a try, not a step
        tries += 1
        worst = 0.0
        for i in range(n):
            if weight[i] > 0.0 and misses[i] > worst:
                worst = misses[i]
        if worst <= tolerance * 0.1:
            break
        if taken + 1 > stall and cost > (1.0 - gain) * seen[taken - stall]:
            break  # the last steps taken gained too little to go on
        for i in range(npts):  # the Jacobian, weighted: -[lever]x per joint, scale per move
            w = weight[i]
            for m in range(nm):
                h = above[m, i] * w
                b = movable[m]
                l0 = (pts[i, 0] - g_pos[b, 0]) * h
                l1 = (pts[i, 1] - g_pos[b, 1]) * h
                l2 = (pts[i, 2] - g_pos[b, 2]) * h
                c = 3 * m
                jac[3 * i, c], jac[3 * i, c + 1], jac[3 * i, c + 2] = 0.0, l2, -l1
                jac[3 * i + 1, c], jac[3 * i + 1, c + 1], jac[3 * i + 1, c + 2] = -l2, 0.0, l0
                jac[3 * i + 2, c], jac[3 * i + 2, c + 1], jac[3 * i + 2, c + 2] = l1, -l0, 0.0
            if root >= 0:
                for r in range(3):
                    for c in range(3):
                        jac[3 * i + r, 3 * nm + c] = scale * w if r == c else 0.0
            for r in range(3):
                err[3 * i + r] = (goals[i, r] - pts[i, r]) * w
        ok = False  # a pivot not positive (J rank-deficient, the damping below rounding):
        while not ok and damping <= 1e8 * scale * scale:  # more damping, the same step
            ok = _damped_into(jac, err, damping, normal, rhs, step)
            if not ok:
                damping *= 10.0
        if not ok:
            break  # no damping the cap allows makes it positive definite
        big = _largest(step)
        for c in range(ncol):
            part[c] = step[c] * min(1.0, max_turn / max(big, 1e-300))
        new = _scored(part, parents, movable, root, scale, g_rot, rotations, translations,
                      anchor, offset, goals, weight, hold, n, k, new_rot, new_tr, n_rot, n_pos,
                      n_pts, now)  # fmt: skip
        if 0 < k < n and big > max_turn:
            # Cut short where targets and pins pull together: a far target's swing of an
            # arm can be the largest turn, and the whole step cut to it shrinks the turns
            # that bring a pin back. Also tried: the step of a damping raised until it fits
            # (a trust region), which favours the moves that gain most for their size; the
            # better of the two is taken, and its damping kept.
            raised, fits = damping, False
            while not fits and raised <= 1e8 * scale * scale:
                raised *= 10.0
                if _damped_into(jac, err, raised, normal, rhs, part):
                    fits = _largest(part) <= max_turn
            alt = np.inf
            if fits:
                alt = _scored(part, parents, movable, root, scale, g_rot, rotations,
                              translations, anchor, offset, goals, weight, hold, n, k, a_rot,
                              a_tr, a_grot, a_gpos, a_pts, a_now)  # fmt: skip
            if alt < new:  # (the scratch buffers swapped: the other's are the new ones)
                new, damping = alt, raised
                new_rot, a_rot, new_tr, a_tr = a_rot, new_rot, a_tr, new_tr
                n_rot, a_grot, n_pos, a_gpos = a_grot, n_rot, a_gpos, n_pos
                n_pts, a_pts, now, a_now = a_pts, n_pts, a_now, now
        if new < cost:
            cost = new
            rotations[:] = new_rot
            translations[:] = new_tr
            g_rot[:] = n_rot
            g_pos[:] = n_pos
            pts[:] = n_pts
            misses[:] = now
            damping = max(damping / 3.0, (1e-6 * scale) ** 2)
            taken += 1
            seen[taken] = cost
        else:
            damping *= 10.0
            if damping > 1e8 * scale * scale:  # no step, however short, helps
                break
    return taken


@jit
def _damped_into(
    jac: F64, err: F64, damping: float, normal: F64, rhs: F64, step: F64
) -> bool:  # pragma: no cover - compiled
    """The damped least-squares step ``step`` of ``jac``, ``err`` on the smaller side;
    False where a Cholesky pivot is not positive."""
    if jac.shape[0] <= jac.shape[1]:  # (J Jᵀ + λI) y = e, step = Jᵀ y
        _gram_into(jac, damping, normal)
        rhs[:] = err
        ok = _cholesky_solve(normal, rhs)
        _product_into(jac.T, rhs, step)
        return ok
    _gram_into(jac.T, damping, normal)  # (JᵀJ + λI) step = Jᵀ e
    _product_into(jac.T, err, rhs)
    ok = _cholesky_solve(normal, rhs)
    step[:] = rhs
    return ok


@jit
def _largest(step: F64) -> float:  # pragma: no cover - compiled
    big = 0.0
    for c in range(step.shape[0]):
        big = max(big, abs(step[c]))
    return big


@jit
def _scored(
    part: F64, parents: I64, movable: I64, root: int, scale: float, g_rot: F64,
    rotations: F64, translations: F64, anchor: I64, offset: F64, goals: F64, weight: F64,
    hold: float, n: int, k: int,
    new_rot: F64, new_tr: F64, n_rot: F64, n_pos: F64, n_pts: F64, now: F64,
) -> float:  # pragma: no cover - compiled  # fmt: skip
    """The pose the step ``part`` leads to, into ``new_rot``, ``new_tr`` (local) and
    ``n_rot``, ``n_pos``, ``n_pts``, ``now`` (world, the points, their misses), and its
    weighted cost (inf where a pin goes farther than ``hold``: refused)."""
    nm = movable.shape[0]
    new_rot[:] = rotations
    new_tr[:] = translations
    for m in range(nm):
        _turn_into(part, m, parents[movable[m]], movable[m], g_rot, rotations, new_rot)
    if root >= 0:
        p = parents[root]
        for r in range(3):
            shift = part[3 * nm + r] * scale
            if p >= 0:  # into the parent's frame: g_rot[p]ᵀ shift
                shift = (
                    g_rot[p, 0, r] * part[3 * nm] * scale
                    + g_rot[p, 1, r] * part[3 * nm + 1] * scale
                    + g_rot[p, 2, r] * part[3 * nm + 2] * scale
                )
            new_tr[root, r] = translations[root, r] + shift
    forward_kinematics_into(parents, new_rot, new_tr, n_rot, n_pos)
    points_into(n_rot, n_pos, anchor, offset, n_pts)
    _misses_into(n_pts, goals, now)
    cost = _cost(now, weight)
    for i in range(k, n):
        if not now[i] <= hold:
            cost = np.inf
    return cost


@jit
def _turn_into(
    step: F64, m: int, p: int, b: int, g_rot: F64, rotations: F64, new_rot: F64
) -> None:  # pragma: no cover - compiled
    """Joint ``b``'s new local rotation: the world turn ``step[3m:3m+3]`` (a rotation
    vector) taken into its parent ``p``'s frame, its axis ``Pᵀ a`` made a unit vector, the
    turn built there (Rodrigues) and applied to ``R``: ``Pᵀ T P R`` for an orthonormal
    ``P``, but a rotation whatever ``P``'s rounding. Written ``Pᵀ T P`` itself, a product
    whose ``Pᵀ`` is no exact inverse, the local rotation took up twice its parent's drift
    from orthonormality at every step, and its children twice theirs: the drift grew with
    the depth and the steps (a spine of 10 joints from pelvis to chest: matrices 1.5 off a
    rotation after one polish, their Euler angles as written put pinned wrists 7 mm off)."""
    x, y, z = step[3 * m], step[3 * m + 1], step[3 * m + 2]
    angle = np.sqrt(x * x + y * y + z * z)
    if not angle > 0.0:
        new_rot[b] = rotations[b]
        return
    x, y, z = x / angle, y / angle, z / angle
    if p >= 0:  # the axis in the parent's frame: Pᵀ a
        x, y, z = (
            g_rot[p, 0, 0] * x + g_rot[p, 1, 0] * y + g_rot[p, 2, 0] * z,
            g_rot[p, 0, 1] * x + g_rot[p, 1, 1] * y + g_rot[p, 2, 1] * z,
            g_rot[p, 0, 2] * x + g_rot[p, 1, 2] * y + g_rot[p, 2, 2] * z,
        )
        norm = np.sqrt(x * x + y * y + z * z)
        x, y, z = x / norm, y / norm, z / norm
    s, c = np.sin(angle), 1.0 - np.cos(angle)
    kx = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    turn = np.eye(3)
    for r in range(3):
        for q in range(3):
            kk = kx[r, 0] * kx[0, q] + kx[r, 1] * kx[1, q] + kx[r, 2] * kx[2, q]
            turn[r, q] += s * kx[r, q] + c * kk
    mul33_into(turn, rotations[b], new_rot[b])


def warm() -> None:
    """Compile (or load from the cache) the kernel with the signature the caller uses."""
    parents = np.array([-1, 0], dtype=np.int64)
    rotations = np.repeat(np.eye(3)[None], 2, axis=0)
    translations = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    descend_into(
        parents, rotations, translations, np.array([1], np.int64), np.zeros((1, 3)),
        np.array([[1.0, 0.0, 0.0]]), np.ones(1), np.array([0], np.int64), np.ones((1, 1)),
        0, 1.0, 1.0, 1, 1, 1e-3, 2, 0.1, 5, 0.01, np.ones(1),
    )  # fmt: skip
