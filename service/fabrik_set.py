"""The compiled FABRIK of one target set, as the engine runs it: the textbook algorithm,
and where its answer folds the hips, the same with the hips rigid.

The textbook algorithm places each child of the pelvis on its own: its backward pass turns
each hip bone towards its own knee. With both feet pinned and the pelvis dragged past a hip,
both knees lie on one side of the pelvis and so do both hips: an audit (2026-12-07) dragged
a real pose's pelvis 10 cm sideways over pinned ankles and got the hips 0.028 m apart
(0.129 in the start; a character's hips turned 93 degrees), every target "reached". FABRIK
with rigid hips everywhere cannot turn the pelvis and loses reach (docs/kinematics.md), so
an answer whose hips ended nearer each other than :data:`FOLDED` of the start's is solved
again with ``rigid_hips`` and kept where that reaches as well (:data:`SLACK`). A polish
measures the hips against the caller's start (``reference``), and its retry starts from
the answer with the pairs it squeezed put back. A pelvis target the translated pelvis
cannot reach over its pinned legs is tried once more from the start moved there and
turned to fit the legs (:func:`tilted`); where no turn fits, the rigid answer from the
pelvis nearest its goal that both legs reach is kept however far it stops
(:func:`within_reach`): a valid body before reach. So for any target over a pinned leg
or pelvis: a wrist dragged 0.5-1 m over pinned ankles folded the hips of 22 of 74 real
poses, the fold buying reach (an API audit, 2026-12-07).

A trunk joint (the chest, the neck, the head) dragged over pinned limbs is first tried
again from the start moved onto its goal where the answer missed or folded the hips or
shoulders (:func:`onto_trunk`); over pinned legs the rigid answer is then kept wherever it
holds the pins, however far it stops from the dragged joint's goal, as for the pelvis:
there the folded answer's extra reach is the fold's own (docs/kinematics.md, "A dragged
trunk").
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from core import compiled_fabrik
from core.geometry import perpendicular, rotation_about
from core.rigid import SQUEEZED, keep_pairs_item
from core.skeleton import JOINT_INDEX, NUM_JOINTS, PARENTS, SUBTREE

F64 = npt.NDArray[np.floating[Any]]
#: An answer whose hips are nearer each other than this share of the start's distance has
#: folded them onto one side of the pelvis (as ``serving.keep_pairs`` calls a pair squeezed).
FOLDED = SQUEEZED
#: The rigid answer is kept where it reaches every target the folded one reached and the
#: others no more than this farther (metres, canonical): a valid body before a few mm.
SLACK = 0.01
_HIPS = (JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"])
_SHOULDERS = (JOINT_INDEX["left_shoulder"], JOINT_INDEX["right_shoulder"])
#: The trunk's joints above the pelvis: dragged over pinned limbs, FABRIK stalls
#: (:func:`onto_trunk`)
_TRUNK = np.isin(
    np.arange(NUM_JOINTS), [JOINT_INDEX[n] for n in ("spine1", "spine2", "neck", "head")]
)
#: The joints of the legs: only a target or pin on one moves a hip (the others carry them)
_LEGS = SUBTREE[_HIPS[0]] | SUBTREE[_HIPS[1]]
#: :func:`nearest_within`'s rounds at most, and the move of a round (metres) below which it
#: has converged (looked at every 8 rounds; two legs' balls: ~20-60 rounds)
ROUNDS, STILL = 300, 1e-13
#: The most a dragged pelvis is turned to fit its legs (radians), and how far within a
#: leg's reach the turn brings the goal or pin on it (metres: FABRIK's rigid hips then
#: converge onto it)
MAX_TILT = np.radians(45.0)
FIT = 0.002


def fabrik_set(
    polish: bool, starts: F64, lengths: F64, goals: F64, tols: F64,
    idx: npt.NDArray[np.int64], weights: F64, hold: npt.NDArray[np.bool_], max_iterations: int,
    reference: F64 | None = None,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.float64]]:  # fmt: skip
    """The compiled FABRIK (``polish``: the exact-reach polish) of canonical ``starts``
    ``[B, 21, 3]`` onto ``goals`` ``[B, K, 3]`` for one target set (joints ``idx``,
    ``weights``, pins ``hold``): poses, iterations (a rigid retry's added) and each target's
    error. The columns are solved in joint order, so the answer is the set's whatever order
    a request listed its targets and pins in (the polish's sweeps follow the columns: an
    API audit, 2026-12-06, saw both ankles pinned as ``[right, left]`` move an unasked wrist
    44 cm from ``[left, right]``). ``reference`` ``[B, 21, 3]``: the caller's own start
    where ``starts`` are a solve's answer to polish (its hips' width the body's: a pinned
    edit's passes each polish, and each pass narrowed the hips a little more, 0.58 of the
    body's width after four); by default ``starts``."""
    order = np.argsort(idx, kind="stable")
    plans = compiled_fabrik.packed_plans(idx[order], weights[order], hold[order])

    def run(sel: npt.NDArray[np.intp] | slice, rigid: bool, froms: F64) -> tuple[Any, ...]:
        return compiled_fabrik.solve_batch(
            polish, np.ascontiguousarray(froms), np.ascontiguousarray(lengths[sel]),
            np.ascontiguousarray(goals[sel][:, order]), np.ascontiguousarray(tols[sel]),
            max_iterations, plans.local_ints, plans.local_floats, plans.has_local, plans.ints,
            plans.floats, np.ascontiguousarray(hold[order]), True, rigid,
        )  # fmt: skip

    def again(
        sel: npt.NDArray[np.intp], froms: F64, loose: npt.NDArray[np.bool_] | None = None
    ) -> npt.NDArray[np.intp]:
        """The items ``sel`` solved again with the hips rigid from ``froms``, kept where
        that reaches as well (the columns ``loose``: by any distance); returns those not
        kept."""
        r_pose, r_its, r_errs, _ = run(sel, True, froms)
        was, tol = errs[sel], tols[sel, None]
        ok = np.where(was <= tol, r_errs <= tol, r_errs <= was + SLACK)
        near = np.all(ok if loose is None else ok | loose, axis=1)
        kept = sel[near]
        pose[kept], its[kept], errs[kept] = r_pose[near], its[kept] + r_its[near], r_errs[near]
        out: npt.NDArray[np.intp] = sel[~near]
        return out

    def again_from(
        sel: npt.NDArray[np.intp], made: list[F64 | None],
        loose: npt.NDArray[np.bool_] | None = None,
    ) -> npt.NDArray[np.intp]:  # fmt: skip
        """:func:`again` of the items ``sel`` from each its start ``made`` (None: none
        made, not tried); returns those not kept."""
        fits = np.array([m is not None for m in made], dtype=bool)
        if not fits.any():
            return sel
        rest = again(sel[fits], np.stack([m for m in made if m is not None]), loose)
        out: npt.NDArray[np.intp] = np.sort(np.concatenate([rest, sel[~fits]]))
        return out

    pose, its, errs, _ = run(slice(None), False, starts)
    ref = starts if reference is None else reference
    bases = starts
    trunk = _TRUNK[idx] & ~hold
    if trunk.any() and hold.any():  # a trunk joint dragged over pinned limbs
        bases = onto_trunk(pose, its, errs, starts, goals, tols, idx, trunk, ref, run)
    # anything dragged over a pinned leg or pelvis: a valid body before any reach, at last
    over_legs = (hold & (_LEGS[idx] | (idx == 0))).any()
    loose = ~hold[order] if over_legs else None
    if not _LEGS[idx].any():  # no hip moved: none folded
        folded = np.empty(0, dtype=np.intp)
    else:
        folded = np.flatnonzero(width2(pose) < FOLDED * FOLDED * width2(ref))
    if folded.size:  # again with the hips rigid, kept where it reaches as well
        froms = np.array(bases[folded], dtype=np.float64)
        if reference is not None:  # the hips (and collars) the passes squeezed put back
            for i, b in enumerate(folded.tolist()):
                keep_pairs_item(froms[i], np.ascontiguousarray(reference[b], dtype=np.float64))
        left = again(folded, froms)
        if left.size and (idx == 0).any():  # a dragged pelvis: turned to fit the legs
            at = np.searchsorted(folded, left)
            turned = [tilted(froms[i], lengths[b], goals[b], idx, hold)
                      for i, b in zip(at.tolist(), left.tolist(), strict=True)]  # fmt: skip
            left = again_from(left, turned)
        if left.size and loose is not None:  # a valid body before reach, at last: from
            # the pelvis nearest its goal (or, a trunk joint dragged, its start's) that the
            # legs reach, and from the start as it was; a dragged pelvis tries the first
            # first (from its start rigid FABRIK stalls short, pulled back by both legs),
            # a trunk the second (from the first a pin let go: the arms' too)
            dragged = bool((idx[~hold] == 0).any())
            for near in (dragged, not dragged):
                if not left.size:
                    break
                at = np.searchsorted(folded, left)
                made = (within_reach(froms[at], lengths[left], goals[left], idx) if near
                        else list(froms[at]))  # fmt: skip
                left = again_from(left, made, loose)
    back = np.empty_like(errs)
    back[:, order] = errs
    return pose, its, back


def width2(poses: F64, pair: tuple[int, int] = _HIPS) -> npt.NDArray[np.float64]:
    """The squared distance between the hips (or another ``pair``) of each pose
    ``[B, 21, 3]``."""
    d = poses[:, pair[0]] - poses[:, pair[1]]
    out: npt.NDArray[np.float64] = np.einsum("ij,ij->i", d, d)
    return out


def onto_trunk(
    pose: F64, its: npt.NDArray[np.int64], errs: F64, starts: F64, goals: F64, tols: F64,
    idx: npt.NDArray[np.int64], trunk: npt.NDArray[np.bool_], ref: F64, run: Any,
) -> F64:  # fmt: skip
    """A trunk joint dragged over pinned limbs (``trunk``: its columns): each answer
    (``pose``, ``its``, ``errs`` in joint order, in place) that missed a target or folded the
    hips or shoulders solved again from its start moved as one body onto the trunk
    targets' goals, kept where that is better (:func:`_worse`). Returns the starts each
    answer came from (the rigid retry's, :func:`fabrik_set`).

    FABRIK's sub-base (the chest for arms, the pelvis for legs) is pulled between the
    dragged joint and the pinned chains and stalls where they pull apart: the chest
    dragged 5-20 cm over pinned wrists ended 4.28 cm from its goal on average, and FABRIK
    folded the shoulders below 80 % of their width in 69 of ``python -m bench.trunk``'s 200;
    from the start moved there, the arms bend to their pins and the chest stays."""
    j = idx[trunk]
    tried = np.flatnonzero(np.any(errs > tols[:, None], axis=1) | _folded(pose, ref))
    bases: F64 = starts
    if not tried.size:
        return bases
    shift = goals[tried][:, trunk].mean(axis=1) - starts[tried][:, j].mean(axis=1)
    froms = starts[tried] + shift[:, None, :]
    r_pose, r_its, r_errs, _ = run(tried, False, froms)
    better = _worse(pose[tried], errs[tried], tols[tried], ref[tried]) > _worse(
        r_pose, r_errs, tols[tried], ref[tried]
    )
    kept = tried[better]
    pose[kept], its[kept], errs[kept] = r_pose[better], its[kept] + r_its[better], r_errs[better]
    bases = starts.copy()
    bases[kept] = froms[better]
    return bases


def _folded(pose: F64, ref: F64) -> npt.NDArray[np.bool_]:
    """Whether each pose holds the hips or the shoulders nearer each other than
    :data:`FOLDED` of their distance in ``ref``."""
    out: npt.NDArray[np.bool_] = (width2(pose) < FOLDED * FOLDED * width2(ref)) | (
        width2(pose, _SHOULDERS) < FOLDED * FOLDED * width2(ref, _SHOULDERS)
    )
    return out


def _worse(pose: F64, errs: F64, tols: F64, ref: F64) -> npt.NDArray[np.float64]:
    """A score to compare two answers of the same edits by: a body folded (:func:`_folded`)
    before any reach, then the sum of each target's miss beyond its tolerance (metres)."""
    miss = np.maximum(errs - tols[:, None], 0.0).sum(axis=1)
    out: npt.NDArray[np.float64] = _folded(pose, ref) * 1e6 + miss
    return out


def _legs(lengths: F64, goals: F64, idx: npt.NDArray[np.int64]) -> list[tuple[int, F64, Any]]:
    """(hip, the goal or pin on its leg, the chain's reach from the hip less :data:`FIT`)
    of each column on a leg; ``lengths`` ``[..., 20]`` and ``goals`` ``[..., K, 3]`` give
    goals ``[..., 3]`` and reaches ``[...]``."""
    legs = []
    for k in np.flatnonzero(_LEGS[idx]).tolist():
        j = int(idx[k])
        hip = next(h for h in _HIPS if SUBTREE[h, j])
        reach: Any = 0.0
        a = j
        while a != hip:
            reach = reach + lengths[..., a - 1]
            a = PARENTS[a]
        legs.append((hip, goals[..., k, :], reach - FIT))
    return legs


def within_reach(
    starts: F64, lengths: F64, goals: F64, idx: npt.NDArray[np.int64]
) -> list[F64 | None]:
    """Each start ``[B, 21, 3]`` moved, unturned, onto the point nearest its pelvis's goal
    (or, none asked, its own pelvis) from which every goal and pin on a leg lies within the
    leg's reach of its hip (the hips rigid); None where no point is. A pelvis dragged beyond
    its pinned legs' reach, no turn fitting (:func:`tilted`), stops there: FABRIK with rigid
    hips, from the start as it was, stalled up to 18 cm from the goal, pulled back by both
    legs."""
    on = np.flatnonzero(idx == 0)
    pelvis = goals[:, int(on[0])] if on.size else starts[:, 0]
    legs = _legs(lengths, goals, idx)
    centres: list[F64] = [g - (starts[:, h] - starts[:, 0]) for h, g, _ in legs]
    near, inside = nearest_within(pelvis, centres, [r for _, _, r in legs])
    moved = starts + (near - starts[:, 0])[:, None, :]
    return [m if ok else None for m, ok in zip(moved, inside.tolist(), strict=True)]


def nearest_within(
    x: F64, centres: list[F64], radii: list[Any]
) -> tuple[F64, npt.NDArray[np.bool_]]:
    """Per row of ``centres`` (each ``[T, 3]``, one per ball of radius ``radii[i]``: a
    number or ``[T]``): the point of the balls' intersection nearest ``x`` (``[3]`` or
    ``[T, 3]``; Dykstra's alternating projections, :data:`ROUNDS` at most), and whether they
    meet there."""
    p = np.broadcast_to(x, centres[0].shape).copy()
    rs = [np.broadcast_to(np.asarray(r, dtype=np.float64), p.shape[:1])[:, None] for r in radii]
    apart = np.zeros(p.shape[0], dtype=bool)  # two balls that do not meet: none nearest
    for i in range(len(centres)):
        for j in range(i):
            gap = np.linalg.norm(centres[i] - centres[j], axis=1)
            apart |= gap > rs[i][:, 0] + rs[j][:, 0]
    if apart.all():
        return p, ~apart
    if len(centres) == 2:  # (two legs, the common case: in closed form)
        return _nearest_of_two(p, centres, rs, apart)
    fixes = [np.zeros_like(p) for _ in centres]
    for k in range(ROUNDS):
        was = p
        for i, (c, r) in enumerate(zip(centres, rs, strict=True)):
            y = p + fixes[i]
            n = np.linalg.norm(y - c, axis=1, keepdims=True)
            q = np.where(n > r, c + (y - c) * (r / np.maximum(n, 1e-12)), y)
            fixes[i], p = y - q, q
        if k % 8 == 7 and not np.abs(p - was)[~apart].max(initial=0.0) > STILL:  # (NaN: on)
            break
    inside = np.all(
        [np.linalg.norm(p - c, axis=1) <= r[:, 0] + 1e-6 for c, r in zip(centres, rs, strict=True)],
        axis=0,
    )
    return p, inside & ~apart


def _nearest_of_two(
    x: F64, centres: list[F64], rs: list[Any], apart: npt.NDArray[np.bool_]
) -> tuple[F64, npt.NDArray[np.bool_]]:
    """:func:`nearest_within` of two balls per row (radii ``rs`` ``[T, 1]``), in closed
    form: ``x`` where it lies in both, else its projection onto one ball where that lies
    in the other (the nearer of two), else the point of the circle where the two spheres
    meet nearest it."""
    (c1, c2), (r1, r2) = centres, rs

    def onto(c: F64, r: F64) -> F64:
        v = x - c
        n = np.linalg.norm(v, axis=1, keepdims=True)
        out: F64 = np.where(n > r, c + v * (r / np.maximum(n, 1e-12)), x)
        return out

    def within(q: F64, c: F64, r: F64) -> npt.NDArray[np.bool_]:
        out: npt.NDArray[np.bool_] = np.linalg.norm(q - c, axis=1) <= r[:, 0] + 1e-9
        return out

    p1, p2 = onto(c1, r1), onto(c2, r2)
    ok1, ok2 = within(p1, c2, r2), within(p2, c1, r1)
    d1, d2 = np.linalg.norm(p1 - x, axis=1), np.linalg.norm(p2 - x, axis=1)
    one = np.where((ok1 & (~ok2 | (d1 <= d2)))[:, None], p1, p2)
    gap = np.linalg.norm(c2 - c1, axis=1, keepdims=True)
    n = (c2 - c1) / np.maximum(gap, 1e-12)
    a = (gap * gap + r1 * r1 - r2 * r2) / (2.0 * np.maximum(gap, 1e-12))
    mid = c1 + a * n
    rho = np.sqrt(np.maximum(r1 * r1 - a * a, 0.0))
    w = x - mid
    w = w - np.sum(w * n, axis=1, keepdims=True) * n
    lw = np.linalg.norm(w, axis=1, keepdims=True)
    w = np.where(lw > 1e-12, w, perpendicular(n))  # (x on the axis: any point of it)
    ring = mid + rho * w / np.linalg.norm(w, axis=1, keepdims=True)
    out: F64 = np.where((ok1 | ok2)[:, None], one, ring)
    return out, ~apart


def tilted(
    start: F64, lengths: F64, goals: F64, idx: npt.NDArray[np.int64], hold: npt.NDArray[np.bool_]
) -> F64 | None:
    """``start`` ``[21, 3]`` moved onto the pelvis's goal (``goals[k]`` where ``idx[k]`` is
    0), turned about its pelvis where that is what brings every goal and pin on a leg within
    the leg's reach of its hip, the hips rigid (``lengths`` ``[20]``: bone ``j - 1`` ends at
    joint ``j``); None where no turn of at most :data:`MAX_TILT` does.

    A pelvis dragged sideways over pinned feet, the legs near straight, lies beyond one
    leg's reach unless the pelvis tilts (the far hip towards its foot), as a body's does:
    the textbook answer folds both hips onto one side instead, and the rigid one, from the
    start as it was, stops short of the goal (3-13 cm on real in-studio poses): FABRIK's
    root, pulled by two legs, stalls. From the pose moved there, each leg reaches on its own.
    The turn is the least about one axis that brings the leg that falls short within
    :data:`FIT` of its reach; the other legs must then still reach."""
    pelvis = goals[int(np.flatnonzero(idx == 0)[0])]
    legs = _legs(lengths, goals, idx)

    def short(turn: F64) -> list[float]:
        return [
            float(np.linalg.norm(pelvis + turn @ (start[h] - start[0]) - g)) - r for h, g, r in legs
        ]

    over = short(np.eye(3))
    if max(over, default=0.0) <= 0.0:  # within reach unturned: only moved
        moved: F64 = start + (pelvis - start[0])
        return moved
    leg = int(np.argmax(over))
    h, g, _ = legs[leg]
    offset, to = start[h] - start[0], g - pelvis
    axis = np.cross(offset, to)
    if not np.linalg.norm(axis) > 1e-9:
        return None
    axis /= np.linalg.norm(axis)
    lo, hi = 0.0, min(MAX_TILT, float(np.arccos(np.clip(
        offset @ to / (np.linalg.norm(offset) * np.linalg.norm(to)), -1.0, 1.0))))  # fmt: skip
    if short(rotation_about(axis, hi))[leg] > 0.0:
        return None
    for _ in range(40):  # the least turn that fits (the leg's miss shrinks as it turns)
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if short(rotation_about(axis, mid))[leg] <= 0.0 else (mid, hi)
    turn = rotation_about(axis, hi)
    if max(short(turn)) > 0.0:  # another leg now falls short
        return None
    out: F64 = pelvis + (start - start[0]) @ turn.T
    return out
