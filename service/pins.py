"""Pins hold: the last step of every solve (:meth:`service.engine.Engine.solve_arrays`).

The FABRIK stages hold pins (``core.kinematics``, ``pinned=``), but two pinned chains off
one sub-base converge slowly: with both wrists pinned and the head, the pelvis or an ankle
dragged far away, the chest must sit where both arms still reach, and FABRIK stopped at
its iteration cap or stalled with a wrist up to 26 mm off (15 of ``python -m bench.pins``'
11,808 edits). An item any of whose pins the answer leaves beyond its tolerance is
polished from its answer by damped least squares on its own bones
(:func:`core.reach.polish_canonical`: joints turn, the pelvis moves, pins weigh thirty
targets), and the polished pose is kept where it holds the pins nearer without losing one
that was held. Where that still leaves a pin off (the answer in a fold the polish does not
leave: random pins on the trunk and collars beside a dragged joint, a pinned collar 13 cm
off), the caller's start is polished instead: it holds every pin, and no step of the polish
takes one past half the tolerance. Its ``solvers`` end with ``pin-polish``; its targets may
end farther (pins come first), its bone lengths are the answer's.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import numpy.typing as npt

from core.reach import polish_canonical
from core.skeleton import bone_lengths
from service.problems import BatchAnswer, _Items


def hold_pins(items: _Items, ans: BatchAnswer) -> BatchAnswer:
    """``ans`` with every item whose pins it leaves beyond the item's tolerance polished
    onto them (its targets pursued as its reach asks: exact reach to the end, soft reach
    with the rest of the body following); items without pins off are untouched."""
    if items.cnt.tobytes() == items.n_t.tobytes():  # no pins (the common case): cnt = n_t
        return ans
    sel = _off(items, ans)
    if sel.size == 0:
        return ans
    before = ans.take(sel)
    pose, errors, bone_err = before.pose.copy(), before.errors.copy(), before.max_bone_error.copy()
    polished = np.zeros(sel.size, dtype=np.bool_)
    for i, b in enumerate(sel.tolist()):
        n_t, cnt, tol = int(items.n_t[b]), int(items.cnt[b]), float(items.tols[b])
        goals = [(int(j), items.tpos[b, q]) for q, j in enumerate(items.tidx[b, :cnt].tolist())]
        aims, holds = sorted(goals[:n_t], key=_joint), sorted(goals[n_t:], key=_joint)  # (*)
        idx, where = items.tidx[b, :cnt], items.tpos[b, :cnt]
        best, misses, rank = None, errors[i, :cnt], _rank(errors[i, :cnt], n_t, tol)
        # from the answer; then, where pins are still off, from the caller's start, which
        # holds every pin (pins are where the start has them): no step of its polish takes
        # one past half the tolerance, so the targets come as near as the pins let them
        start = items.poses[b]
        for origin in (pose[i], start):
            got = polish_canonical(origin, aims, holds, tol, bool(items.ex[b]))
            if got is None and origin is start:
                got = start  # no polish nearer: the start itself holds the pins
            if got is None:
                continue
            m = np.linalg.norm(got[idx] - where, axis=1)
            if (r := _rank(m, n_t, tol)) < rank:
                best, misses, rank = got, m, r
            if rank[0] == 0.0:
                break
        if best is None:
            continue
        polished[i], pose[i] = True, best
        errors[i, :cnt] = misses
        bone_err[i] = float(np.abs(bone_lengths(best) / bone_lengths(items.poses[b]) - 1.0).max())
    if not polished.any():
        return ans
    keep = np.flatnonzero(polished)
    out = dataclasses.replace(
        before, pose=pose, errors=errors, max_bone_error=bone_err,
        paths=tuple((*path, "pin-polish") for path in before.paths),
    ).take(keep)  # fmt: skip
    return ans.with_items(sel[keep], out)


def _joint(goal: tuple[int, Any]) -> int:
    """(*) Goals in joint order: the polish's sums follow them, and the answer must not
    depend on the order a request listed its targets and pins in."""
    return goal[0]


def _rank(misses: npt.NDArray[Any], n_t: int, tolerance: float) -> tuple[float, float]:
    """An answer's rank, lower is better: how far its farthest pin is beyond the
    tolerance, then its farthest target."""
    pins = float(misses[n_t:].max(initial=0.0))
    return max(pins - tolerance, 0.0), float(misses[:n_t].max(initial=0.0))


def _off(items: _Items, ans: BatchAnswer) -> npt.NDArray[np.intp]:
    """The items with a pin beyond their tolerance (one edit, the interactive case, without
    the array temporaries: they cost ~8 µs of a 0.55 ms pinned solve)."""
    if items.cnt.size == 1:
        pins = ans.errors[0, int(items.n_t[0]) : int(items.cnt[0])].tolist()
        return np.arange(int(max(pins) > float(items.tols[0])), dtype=np.intp)
    cols = np.arange(ans.errors.shape[1])[None, :]
    pinned = (cols >= items.n_t[:, None]) & (cols < items.cnt[:, None])
    out: npt.NDArray[np.intp] = np.flatnonzero(
        ((ans.errors > items.tols[:, None]) & pinned).any(axis=1)
    )
    return out
