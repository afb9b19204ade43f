"""Compiled full-body FABRIK and the exact-reach polish (numba, :mod:`core.jit`).

The same algorithm as :func:`core.kinematics.fabrik` and :func:`core.kinematics.polish`,
step for step: the topology of a solve is the numpy module's own plan
(``kinematics._make_plan``, cached per target set and packed into two flat arrays by
:func:`packed_plans`), and the iteration -- forward reaching to the sub-bases (weighted
centroids), the free root pulled back within reach of the pins, backward reaching, the
stall rule, the rigid carry of untargeted branches, the trunk-locked first stage of the
polish -- runs per item in machine code. Each item is solved alone, so an item's answer
does not depend on its batch (the numpy version runs a batch in lock step: same answers
for single items, which is how the engine called it).

The numpy module remains the reference: tests/core/test_compiled.py checks these kernels
against it on real poses to 1e-12.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import numpy.typing as npt

from core import kinematics
from core.compiled import LEN_ORDER, ORDER, PARENT_RANK, REST_DIRS_RANK, bone_pass_item
from core.compiled_limbs import TINY, swing_into, unit_or
from core.jit import jit
from core.skeleton import JOINT_INDEX, NUM_JOINTS

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
#: The service's iteration cap of FABRIK, the exact-reach polish and completion's polish
#: (``POSE_FABRIK_MAX_ITERATIONS``). At 64 a few 5-target polishes stopped up to 3.9 mm
#: short of targets within reach (`make bench` B3, 0.2 % of them); at 256 every reachable
#: target is within the 1 mm tolerance, and the stall rule still ends hopeless solves early.
#: Completion's polish (then numpy) ended nearer its key points at 256 (max 4.25 -> 3.28 mm
#: over 200 in-studio poses, a /tmp timing) and cost 1.6 -> 2.2 ms per 6-point completion;
#: it now runs this compiled polish: 0.59 ms per completion, the same poses to 2e-15 m.
MAX_ITERATIONS = 256
Bool = npt.NDArray[np.bool_]
_RIGID: Bool = kinematics._RIGID

_NB = NUM_JOINTS - 1
# header slots of a packed plan (ints)
_K, _T, _ROOT_MOVES, _ROOT_FREE, _LF, _LB, _C = range(7)
_O_TR, _O_TGT, _O_FWP, _O_FWK, _O_FWPAR, _O_FWMIX, _O_BWP, _O_BWK, _O_BWPAR = range(7, 16)
_O_CAR, _O_ANC, _O_JT, _O_FWW, _O_PATH = range(16, 21)
_HEADER = 21


def pack_plan(plan: kinematics._Plan) -> tuple[I64, F64]:
    """A numpy FABRIK plan as (ints, floats) for the kernels (layout: the header slots)."""
    k, t = len(plan.target_ranks), len(plan.targeted)
    fw_ptr, fw_kids, fw_par, fw_mix, fw_w = [0], [], [], [], []
    for fw in plan.forward:
        fw_kids += fw.kids.tolist()
        fw_par += fw.parents.tolist()
        fw_mix.append(0 if fw.mix is None else 1)
        if fw.mix is None:
            fw_w += [1.0] * len(fw.kids)
        else:
            rows = fw.rows.tolist()
            fw_w += [float(fw.mix[rows.index(p), c]) for c, p in enumerate(fw.parents.tolist())]
        fw_ptr.append(len(fw_kids))
    bw_ptr, bw_kids, bw_par = [0], [], []
    for kids, parents, _ in plan.backward:
        bw_kids += kids.tolist()
        bw_par += parents.tolist()
        bw_ptr.append(len(bw_kids))
    sections: list[list[int]] = [
        plan.target_ranks.tolist(), plan.targeted.tolist(), fw_ptr, fw_kids, fw_par, fw_mix,
        bw_ptr, bw_kids, bw_par, plan.carried_joints.tolist(), plan.carried_anchors.tolist(),
    ]  # fmt: skip
    head = [k, t, int(plan.root_moves), int(plan.root_free), len(plan.forward),
            len(plan.backward), len(plan.carried_joints)]  # fmt: skip
    offsets, at = [], _HEADER
    for s in sections:
        offsets.append(at)
        at += len(s)
    floats = [plan.joint_targets.reshape(-1).tolist(), fw_w, plan.path.reshape(-1).tolist()]
    f_off, f_at = [], 0
    for f in floats:
        f_off.append(f_at)
        f_at += len(f)
    ints = np.asarray(head + offsets + f_off + [v for s in sections for v in s], dtype=np.int64)
    return ints, np.asarray([v for f in floats for v in f], dtype=np.float64)


@dataclass(frozen=True)
class Plans:
    """Packed plans of one target set: the polish's trunk-locked stage (if any) and the
    full-body plan (shared by FABRIK and the polish's second stage)."""

    local_ints: I64
    local_floats: F64
    has_local: bool
    ints: I64
    floats: F64


@lru_cache(maxsize=4096)
def _plans(idx: tuple[int, ...], weights: tuple[float, ...], pins: tuple[bool, ...]) -> Plans:
    target = np.asarray(idx, dtype=np.intp)
    w = np.asarray(weights, dtype=np.float64)
    pinned = np.asarray(pins, dtype=np.bool_)
    ints, floats = pack_plan(kinematics._make_plan(target, w, frozenset(), True, pinned))
    locks = kinematics._trunk_locks(target)
    if locks is None:
        return Plans(ints, floats, False, ints, floats)
    li, lf = pack_plan(kinematics._make_plan(target, w, locks, False))
    return Plans(li, lf, True, ints, floats)


def packed_plans(
    target_idx: npt.ArrayLike, weights: npt.ArrayLike, pinned: npt.ArrayLike | None = None
) -> Plans:
    """The packed plans of a target set (K joint indices, K positive weights, which of
    them are pins: ``kinematics._make_plan``), cached."""
    idx = tuple(np.asarray(target_idx, dtype=np.int64).reshape(-1).tolist())
    wa = np.asarray(weights, dtype=np.float64).reshape(-1)
    w = tuple(wa.tolist())
    asked = np.zeros(len(idx), dtype=np.bool_) if pinned is None else pinned
    pins = tuple(np.asarray(asked, dtype=np.bool_).reshape(-1).tolist())
    if len(w) != len(idx) or not bool(np.isfinite(wa).all()) or bool((wa <= 0).any()):
        raise ValueError("weights must be one positive finite number per target")
    if len(pins) != len(idx):
        raise ValueError("pinned must be one boolean per target")
    if any(i < 0 or i >= NUM_JOINTS for i in idx):
        raise ValueError(f"target indices must be integers in [0, {NUM_JOINTS})")
    return _plans(idx, w, pins)


# --------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------
@jit
def _clamp_root(
    p: F64, start: F64, tpos: F64, radii: F64, inner: F64, anchors: Bool
) -> None:  # pragma: no cover - compiled
    """``shells.clamp_root`` for one item, ``p`` in place."""
    d0, d1, d2 = p[0] - start[0], p[1] - start[1], p[2] - start[2]
    dd = (d0 * d0 + d1 * d1) + d2 * d2
    moving = dd > TINY * TINY
    smin = 1.0
    for k in range(tpos.shape[0]):
        e0, e1, e2 = start[0] - tpos[k, 0], start[1] - tpos[k, 1], start[2] - tpos[k, 2]
        ed = e0 * d0 + e1 * d1 + e2 * d2
        ee = e0 * e0 + e1 * e1 + e2 * e2
        disc = max(ed * ed - dd * (ee - radii[k] * radii[k]), 0.0)
        s = (np.sqrt(disc) - ed) / (dd if moving else 1.0)
        if not (anchors[k] and moving):
            s = 1.0
        elif not np.isnan(s):  # np.clip: NaN stays NaN
            s = min(max(s, 0.0), 1.0)
        if s < smin or np.isnan(s):
            smin = s
    p[0], p[1], p[2] = start[0] + d0 * smin, start[1] + d1 * smin, start[2] + d2 * smin
    _project_root(p, tpos, radii, inner, anchors)


@jit
def _project_root(
    p: F64, tpos: F64, radii: F64, inner: F64, anchors: Bool
) -> None:  # pragma: no cover - compiled
    """``shells.project_root`` for one item, ``p`` in place."""
    off = np.zeros(tpos.shape[0], dtype=np.bool_)
    for _ in range(32):
        anyoff = False
        for k in range(tpos.shape[0]):
            a0, a1, a2 = p[0] - tpos[k, 0], p[1] - tpos[k, 1], p[2] - tpos[k, 2]
            n = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
            off[k] = anchors[k] and (n > radii[k] * (1.0 + 1e-9) or n < inner[k] * (1.0 - 1e-9))
            anyoff = anyoff or off[k]
        if not anyoff:
            break
        for k in range(tpos.shape[0]):
            if not off[k]:
                continue
            a0, a1, a2 = p[0] - tpos[k, 0], p[1] - tpos[k, 1], p[2] - tpos[k, 2]
            nk = max(np.sqrt(a0 * a0 + a1 * a1 + a2 * a2), TINY)
            if anchors[k] and (nk > radii[k] * (1.0 + 1e-9) or nk < inner[k] * (1.0 - 1e-9)):
                f = min(max(nk, inner[k]), radii[k]) / nk
                p[0], p[1], p[2] = tpos[k, 0] + a0 * f, tpos[k, 1] + a1 * f, tpos[k, 2] + a2 * f


@jit
def _reach(path: F64, lens: F64, k: int, kt: int) -> tuple[float, float]:  # pragma: no cover
    """Full stretch and longest bone of target ``k``'s chain from the root (``kt`` -1), or
    from target ``kt``'s joint above it: ``path`` the plan's ``[K, 20]`` flat."""
    reach, longest = 0.0, 0.0
    for b in range(_NB):
        w = path[k * _NB + b] if kt < 0 else path[k * _NB + b] - path[kt * _NB + b]
        reach += w * lens[b]
        longest = max(longest, w * lens[b])
    return reach, longest


@jit
def _shells(
    x0: F64, lens: F64, tpos: F64, path: F64, hold: Bool, hold_any: bool, errors: F64,
    tol: float, radii: F64, inner: F64, anchors: Bool,
) -> None:  # pragma: no cover - compiled  # fmt: skip
    """``shells.shells`` for one item into ``radii``, ``inner`` and ``anchors``."""
    for k in range(tpos.shape[0]):
        reach, longest = _reach(path, lens, k, -1)
        d0, d1, d2 = x0[0, 0] - tpos[k, 0], x0[0, 1] - tpos[k, 1], x0[0, 2] - tpos[k, 2]
        dist = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        anchors[k] = errors[k] <= tol
        if hold_any:
            anchors[k] = hold[k] and reach > 0
            dist = min(dist, reach)
        inner[k] = max(2.0 * longest - reach, 0.0)
        radii[k] = max(max(0.99 * reach, dist), inner[k])


@jit
def _above_pins(pi: I64, pf: F64, hold: Bool) -> tuple[I64, Bool]:  # pragma: no cover
    """``shells.above_pins`` for one target set: per targeted joint its first target (-1
    where it holds nothing: the root, pinned, or no pin below) and the pins below it."""
    k_n, tr, targeted, path = pi[_K], pi[pi[_O_TR] :], pi[pi[_O_TGT] :], pf[pi[_O_PATH] :]
    kts, below = np.full(pi[_T], -1, dtype=np.int64), np.zeros((pi[_T], k_n), dtype=np.bool_)
    for t in range(pi[_T]):
        r, kt, pinned = targeted[t], -1, False
        for k in range(k_n):
            if tr[k] == r:
                kt = k if kt < 0 else kt
                pinned = pinned or hold[k]
        if r == 0 or pinned:
            continue
        for kp in range(k_n):
            under = hold[kp] and tr[kp] != r
            for b in range(_NB):
                under = under and path[kt * _NB + b] <= path[kp * _NB + b]
            below[t, kp] = under
            if under:
                kts[t] = kt
    return kts, below


@jit
def _hold_targets(
    proposal: F64, aim: F64, pi: I64, pf: F64, lens: F64, tpos: F64, root: F64, kts: I64,
    below: Bool,
) -> None:  # pragma: no cover - compiled  # fmt: skip
    """``shells.hold_targets`` for one item (``kts``, ``below``: :func:`_above_pins`),
    ``proposal`` in place."""
    k_n, targeted, path = pi[_K], pi[pi[_O_TGT] :], pf[pi[_O_PATH] :]
    centres, radii, inner = np.empty((k_n + 1, 3)), np.empty(k_n + 1), np.empty(k_n + 1)
    anchors, p = np.ones(k_n + 1, dtype=np.bool_), np.empty(3)
    for t in range(pi[_T]):
        kt = kts[t]
        if kt < 0:
            continue
        m = 0
        for kp in range(-1, k_n):  # the root (the chain above), then the pins below
            if kp >= 0 and not below[t, kp]:
                continue
            reach, longest = _reach(path, lens, kt, -1) if kp < 0 else _reach(path, lens, kp, kt)
            for c in range(3):
                centres[m, c] = tpos[kp, c] if kp >= 0 else root[c]
            d0, d1, d2 = (
                aim[t, 0] - centres[m, 0],
                aim[t, 1] - centres[m, 1],
                aim[t, 2] - centres[m, 2],
            )
            dist = min(np.sqrt(d0 * d0 + d1 * d1 + d2 * d2), reach)
            inner[m] = max(2.0 * longest - reach, 0.0)
            radii[m] = max(max(0.99 * reach, dist), inner[m])
            m += 1
        p[:] = proposal[targeted[t]]
        _project_root(p, centres[:m], radii[:m], inner[:m], anchors[:m])
        proposal[targeted[t], :] = p


@jit
def _iterate(
    x: F64, proposal: F64, y: F64, lens: F64, pi: I64, pf: F64, clamp: bool, start: F64,
    tpos: F64, radii: F64, inner: F64, anchors: Bool, rigid: Bool, safe: bool, frozen: bool,
) -> bool:  # pragma: no cover - compiled  # fmt: skip
    """One FABRIK iteration (``kinematics._iterate``) into ``y``; False if not finite."""
    v, f1, f2, u = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    fwp, fwk, fwpar = pi[pi[_O_FWP] :], pi[pi[_O_FWK] :], pi[pi[_O_FWPAR] :]
    fwmix, fww = pi[pi[_O_FWMIX] :], pf[pi[_O_FWW] :]
    for level in range(pi[_LF]):
        a, b = fwp[level], fwp[level + 1]
        mixed = fwmix[level] == 1
        if mixed:
            for i in range(a, b):
                proposal[fwpar[i], 0] = 0.0
                proposal[fwpar[i], 1] = 0.0
                proposal[fwpar[i], 2] = 0.0
        for i in range(a, b):
            kid, par = fwk[i], fwpar[i]
            ln = lens[kid - 1]
            for c in range(3):
                v[c] = x[par, c] - proposal[kid, c]
            if safe:
                for c in range(3):
                    f1[c] = x[par, c] - x[kid, c]
                    f2[c] = -REST_DIRS_RANK[kid - 1, c]
                unit_or(v, f1, f2, u, 2)
                q0 = proposal[kid, 0] + u[0] * ln
                q1 = proposal[kid, 1] + u[1] * ln
                q2 = proposal[kid, 2] + u[2] * ln
            else:
                f = ln / np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
                q0 = proposal[kid, 0] + v[0] * f
                q1 = proposal[kid, 1] + v[1] * f
                q2 = proposal[kid, 2] + v[2] * f
            if rigid[kid]:  # kinematics._iterate: a rigid hip, the root where it puts it
                q0 = proposal[kid, 0] - (x[kid, 0] - x[0, 0])
                q1 = proposal[kid, 1] - (x[kid, 1] - x[0, 1])
                q2 = proposal[kid, 2] - (x[kid, 2] - x[0, 2])
            if mixed:
                w = fww[i]
                proposal[par, 0] += w * q0
                proposal[par, 1] += w * q1
                proposal[par, 2] += w * q2
            else:
                proposal[par, 0], proposal[par, 1], proposal[par, 2] = q0, q1, q2
    if clamp:
        _clamp_root(proposal[0], start, tpos, radii, inner, anchors)
    y[:, :] = x
    if pi[_ROOT_MOVES] == 1 and not frozen:
        y[0, :] = proposal[0, :]
    bwp, bwk, bwpar = pi[pi[_O_BWP] :], pi[pi[_O_BWK] :], pi[pi[_O_BWPAR] :]
    ok = True
    for level in range(pi[_LB]):
        for i in range(bwp[level], bwp[level + 1]):
            kid, par = bwk[i], bwpar[i]
            ln = lens[kid - 1]
            for c in range(3):
                v[c] = proposal[kid, c] - y[par, c]
            if safe:
                for c in range(3):
                    f1[c] = x[kid, c] - x[par, c]
                    f2[c] = REST_DIRS_RANK[kid - 1, c]
                unit_or(v, f1, f2, u, 2)
                for c in range(3):
                    y[kid, c] = y[par, c] + u[c] * ln
            else:
                f = ln / np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
                for c in range(3):
                    y[kid, c] = y[par, c] + v[c] * f
            if rigid[kid]:  # kinematics._iterate: a rigid hip, moved with the root
                for c in range(3):
                    y[kid, c] = y[0, c] + (x[kid, c] - x[0, c])
            for c in range(3):
                ok = ok and np.isfinite(y[kid, c])
    return ok and np.isfinite(y[0, 0]) and np.isfinite(y[0, 1]) and np.isfinite(y[0, 2])


@jit
def _carry(x0: F64, x: F64, pi: I64) -> None:  # pragma: no cover - compiled
    """``kinematics._carry`` in place on ``x``: untargeted branches carried rigidly."""
    kids, anchors = pi[pi[_O_CAR] :], pi[pi[_O_ANC] :]
    a0, a1, off, out = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    placed = np.empty((pi[_C], 3))
    for i in range(pi[_C]):
        kid, anc = kids[i], anchors[i]
        ap = 0 if anc == 0 else PARENT_RANK[anc]
        for c in range(3):
            a0[c] = x0[anc, c] - x0[ap, c]
            a1[c] = x[anc, c] - x[ap, c]
            off[c] = x0[kid, c] - x0[anc, c]
        keep = True
        for c in range(3):
            keep = keep and a0[c] == a1[c] and x[anc, c] == x0[anc, c]
        if keep:
            placed[i, :] = x0[kid, :]
        else:
            swing_into(a0, a1, off, out)
            for c in range(3):
                placed[i, c] = x[anc, c] + out[c]
    for i in range(pi[_C]):
        x[kids[i], :] = placed[i, :]


@jit
def _errors(x: F64, tpos: F64, pi: I64, out: F64) -> None:  # pragma: no cover - compiled
    tr = pi[pi[_O_TR] :]
    for k in range(pi[_K]):
        r = tr[k]
        d0, d1, d2 = x[r, 0] - tpos[k, 0], x[r, 1] - tpos[k, 1], x[r, 2] - tpos[k, 2]
        out[k] = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@jit
def _solve(
    x0: F64, lens: F64, tpos: F64, pi: I64, pf: F64, tol: float, max_it: int,
    hold: Bool, hold_any: bool, kts: I64, below: Bool, x: F64, errors: F64, rigid_hips: bool,
) -> tuple[int, bool]:  # pragma: no cover - compiled  # fmt: skip
    """``kinematics._solve`` for one item (rank order); ``x``/``errors`` receive the answer.
    ``hold_any``: some target is pinned (``hold``); ``kts``, ``below``: the plan's targets
    above pins (:func:`_above_pins`, the same for every item of a batch); ``rigid_hips``:
    ``kinematics._make_plan``'s."""
    k_n, t_n = pi[_K], pi[_T]
    stall = tol * 1e-3
    radii, inner, anchors = np.empty(k_n), np.empty(k_n), np.zeros(k_n, dtype=np.bool_)
    start, path, centres = x0[0].copy(), pf[pi[_O_PATH] :], tpos
    targeted = pi[pi[_O_TGT] :]
    rigid = np.zeros(NUM_JOINTS, dtype=np.bool_)  # kinematics._Plan.rigid
    if rigid_hips:  # (kinematics._Plan.shell_top, shell_path: the shells' centres)
        rigid[:] = _RIGID
        for t in range(pi[_T]):
            rigid[targeted[t]] = False
        path, centres = path.copy(), tpos.copy()
        for k in range(k_n):
            for r in range(1, NUM_JOINTS):
                if rigid[r] and path[k * _NB + r - 1] > 0:
                    path[k * _NB + r - 1] = 0.0
                    for c in range(3):
                        centres[k, c] = tpos[k, c] - (x0[r, c] - x0[0, c])
    if hold_any and pi[_ROOT_MOVES] == 0:  # shells.onto_pins, x0 moved in place
        _shells(x0, lens, centres, path, hold, True, errors, tol, radii, inner, anchors)
        _project_root(start, centres, radii, inner, anchors)
        shift = start - x0[0]
        for r in range(NUM_JOINTS):
            for c in range(3):
                x0[r, c] = x0[r, c] + shift[c]
        start[:] = x0[0]
    x[:, :] = x0
    _errors(x, tpos, pi, errors)
    done = True
    for k in range(k_n):
        done = done and errors[k] <= tol
    converged = done
    proposal = x0.copy()
    jt = pf[pi[_O_JT] :]
    for t in range(t_n):
        for c in range(3):
            s = 0.0
            for k in range(k_n):
                s += jt[t * k_n + k] * tpos[k, c]
            proposal[targeted[t], c] = s
    aim = np.empty((t_n, 3))
    for t in range(t_n):
        aim[t, :] = proposal[targeted[t], :]
    clamp = pi[_ROOT_FREE] == 1 or (hold_any and pi[_ROOT_MOVES] == 1)
    if clamp:
        _shells(x0, lens, centres, path, hold, hold_any, errors, tol, radii, inner, anchors)
    new_errors = np.empty(k_n)
    y = np.empty_like(x)
    holding = bool((kts >= 0).any())
    strikes, its, frozen = 0, 0, False
    while its < max_it and not done:
        its += 1
        if holding:  # kinematics._solve: a target above a pin, as far as the pin allows
            _hold_targets(proposal, aim, pi, pf, lens, tpos, x[0], kts, below)
        args = (x, proposal, y, lens, pi, pf, clamp, start, centres, radii, inner, anchors, rigid)
        if not _iterate(*args, False, frozen):
            _iterate(*args, True, frozen)
        x[:, :] = y
        _errors(x, tpos, pi, new_errors)
        progress, pin_progress, newly, all_ok = 0.0, 0.0, False, True
        for k in range(k_n):
            if new_errors[k] > tol:
                progress += errors[k] - new_errors[k]
                if hold_any and hold[k]:
                    pin_progress += errors[k] - new_errors[k]
                all_ok = False
            elif errors[k] > tol:
                newly = True
        strikes = 0 if (newly or max(progress, pin_progress) >= stall) else strikes + 1
        finished = all_ok or strikes >= 3
        if finished and not all_ok and hold_any and pi[_ROOT_MOVES] == 1 and not frozen:
            for k in range(k_n):  # kinematics._solve: the root held, the limbs go on
                frozen = frozen or (hold[k] and new_errors[k] > tol)
            if frozen:
                strikes, finished = 0, False
        converged = converged or finished
        errors[:] = new_errors
        done = finished
    if its:
        _carry(x0, x, pi)
        _errors(x, tpos, pi, errors)
    return its, converged


@jit
def solve_batch(
    polish: bool, starts: F64, lengths: F64, goals: F64, tols: F64, max_it: int,
    li: I64, lf: F64, has_local: bool, gi: I64, gf: F64, hold: Bool, has_hold: bool,
    rigid_hips: bool,
) -> tuple[F64, I64, F64, Bool]:  # pragma: no cover - compiled  # fmt: skip
    """``kinematics.fabrik`` (``polish`` False) or ``kinematics.polish`` of every item
    (``rigid_hips`` as there):
    ``starts [M, 21, 3]``, ``lengths [M, 20]``, ``goals [M, K, 3]``, ``tols [M]``; one
    target set (its packed plans) and pin mask ``hold [K]`` for all. Returns poses
    ``[M, 21, 3]``, iterations ``[M]``, errors ``[M, K]``, converged ``[M]``."""
    m, k_n = starts.shape[0], goals.shape[1]
    out = np.empty_like(starts)
    its = np.zeros(m, dtype=np.int64)
    errs = np.empty((m, k_n))
    conv = np.zeros(m, dtype=np.bool_)
    pose, xr, rr, lr = (np.empty((NUM_JOINTS, 3)), np.empty((NUM_JOINTS, 3)),
                        np.empty((NUM_JOINTS, 3)), np.empty(_NB))  # fmt: skip
    x0, x = np.empty((NUM_JOINTS, 3)), np.empty((NUM_JOINTS, 3))
    lens, tp = np.empty(_NB), np.empty((k_n, 3))
    hold_any, free = has_hold and bool(hold.any()), np.zeros(k_n, dtype=np.bool_)
    l_kts, l_below = _above_pins(li, lf, free)  # (the trunk-locked stage holds no pins)
    g_kts, g_below = _above_pins(gi, gf, hold if hold_any else free)
    for b in range(m):
        bone_pass_item(starts[b], lengths[b], starts[b], False, pose, xr, lr, rr)
        for r in range(NUM_JOINTS):
            x0[r, :] = pose[ORDER[r], :]
        for r in range(_NB):
            lens[r] = lengths[b, LEN_ORDER[r]]
        tp[:, :] = goals[b]
        tol = tols[b]
        n_it = 0
        solved = False
        if polish and has_local:
            n_it, c = _solve(x0, lens, tp, li, lf, tol, max_it, hold, False, l_kts, l_below, x,
                             errs[b], rigid_hips)  # fmt: skip
            solved = True
            for k in range(k_n):
                solved = solved and errs[b, k] <= tol
            conv[b] = c
            if not solved:
                x0[:, :] = x
        if not solved:
            g_it, c = _solve(x0, lens, tp, gi, gf, tol, max_it, hold, hold_any, g_kts, g_below,
                             x, errs[b], rigid_hips)  # fmt: skip
            n_it += g_it
            conv[b] = c
        its[b] = n_it
        for r in range(NUM_JOINTS):
            out[b, ORDER[r], :] = x[r, :]
    return out, its, errs, conv


def warm() -> None:
    """Compile (or load from the cache) the kernels on a tiny problem."""
    from core.rest import rest_lengths, rest_pose

    pose = rest_pose()[None].astype(np.float64)
    lens = rest_lengths()[None].astype(np.float64)
    idx = np.asarray([JOINT_INDEX["left_wrist"], JOINT_INDEX["left_ankle"]], dtype=np.intp)
    plans = packed_plans(idx, np.ones(2))
    goals = pose[:, idx] + 0.05
    hold = np.asarray([False, True])
    for polish in (False, True):  # (every argument given, rigid_hips too: an omitted one
        solve_batch(  # would be another signature, compiled ~20 s at its first call)
            polish, pose, lens, goals, np.full(1, 1e-3), 8, plans.local_ints,
            plans.local_floats, plans.has_local, plans.ints, plans.floats, hold, True, False,
        )  # fmt: skip
