"""Pins hold: the last step of every solve (:meth:`service.engine.Engine.solve_arrays`).

The FABRIK stages hold pins (``core.kinematics``, ``pinned=``), but two pinned chains off
one sub-base converge slowly: with both wrists pinned and the head, the pelvis or an ankle
dragged far away, the chest must sit where both arms still reach, and FABRIK stopped at
its iteration cap or stalled with a wrist up to 26 mm off (15 of ``python -m bench.pins``'
11,808 edits). An item any of whose pins the answer leaves beyond its tolerance is
polished from its answer by damped least squares on its own bones
(:func:`core.reach.polish_canonical`: joints turn, the pelvis moves, pins weigh thirty
targets), and the polished pose is kept where it holds the pins nearer without losing one
that was held. Its ``solvers`` end with ``pin-polish``; its targets may end farther (pins
come first), its bone lengths are the answer's.
"""

from __future__ import annotations

import dataclasses

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
        n_t, cnt = int(items.n_t[b]), int(items.cnt[b])
        goals = [(int(j), items.tpos[b, q]) for q, j in enumerate(items.tidx[b, :cnt].tolist())]
        got = polish_canonical(
            pose[i], goals[:n_t], goals[n_t:],
            float(items.tols[b]), bool(items.ex[b]),
        )  # fmt: skip
        if got is None:
            continue
        polished[i], pose[i] = True, got
        errors[i, :cnt] = np.linalg.norm(got[items.tidx[b, :cnt]] - items.tpos[b, :cnt], axis=1)
        bone_err[i] = float(np.abs(bone_lengths(got) / bone_lengths(items.poses[b]) - 1.0).max())
    if not polished.any():
        return ans
    keep = np.flatnonzero(polished)
    out = dataclasses.replace(
        before, pose=pose, errors=errors, max_bone_error=bone_err,
        paths=tuple((*path, "pin-polish") for path in before.paths),
    ).take(keep)  # fmt: skip
    return ans.with_items(sel[keep], out)


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
