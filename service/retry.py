"""What every solve's answer goes through last (``Engine.solve``, the lean path's too): one
more pass for a soft answer its passes left short, then, with ``serving.retry_polish``, the
polish of what that pass still leaves short, then pins still off polished onto them
(:func:`service.pins.hold_pins`).

"Short" is measured against each item's retry threshold: ``serving.retry_reach`` at the
networks' body size, scaled with the body (``compiled.retry_reaches``: a 1.9 m or a 1.2 m
copy of a character is answered as that character), plus ``soft_ik / e`` for an item asked
to ease into full stretch (the shortfall it asked for: neither a retry nor the polish,
which straightens the limb, is for that).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from core import compiled
from core.skeleton import bone_lengths
from service.lean import solve_fabrik
from service.pins import hold_pins
from service.problems import BatchAnswer, _groups, _Items

if TYPE_CHECKING:  # pragma: no cover
    from service.engine import Engine

F64 = compiled.F64


def last_steps(engine: Engine, items: _Items, ans: BatchAnswer) -> BatchAnswer:
    """What every answer goes through last: :func:`retry`, then
    :func:`service.pins.hold_pins`."""
    return hold_pins(items, retry(engine, items, ans))


def retry(engine: Engine, items: _Items, ans: BatchAnswer) -> BatchAnswer:
    """``ans`` with one more pass, from its answer, for every soft neural item (bone lengths
    kept) whose farthest target is still beyond its threshold (:func:`reaches`): the passes
    left it short, as the bone pass takes back what the networks reached for
    (docs/generalisation-serving.md item 25). Such an item gets what one more of its passes
    would give it; the others are untouched. With ``serving.retry_polish``, an item that
    pass still leaves short is then polished onto its targets (:func:`polish_short`)."""
    if engine.serving.retry_reach <= 0.0 or ans.pose.shape[0] == 0:
        return ans
    reach, least = reaches(engine, items)
    if float(ans.errors.max()) <= least:  # the common case: one reduction, one kernel
        return ans
    sel = short(items, ans, reach)
    if sel.size == 0:
        return ans
    again = engine._solve_items(
        items.soft(sel, compiled.as_f64(ans.pose)), np.ones(sel.size, np.int64)
    )
    ans = ans.with_items(sel, again)
    return polish_short(engine, items, ans, reach) if engine.serving.retry_polish else ans


def reaches(engine: Engine, items: _Items) -> tuple[F64, float]:
    """``[B]``: how far from a target each item's soft answer may end before it is retried,
    and the least of them (the module's threshold, ``compiled.retry_reaches``)."""
    return compiled.retry_reaches(
        items.poses, items.soft_ik, engine.serving.retry_reach, *engine.body_args
    )


def short(items: _Items, ans: BatchAnswer, reach: F64) -> npt.NDArray[np.intp]:
    """The soft neural items (bone lengths kept) of ``ans`` whose farthest user target is
    more than their ``reach`` (:func:`reaches`) away."""
    far = items.farthest(ans.errors) > reach
    out: npt.NDArray[np.intp] = np.flatnonzero(far & ~items.fab & ~items.ex & items.keep)
    return out


def polish_short(engine: Engine, items: _Items, ans: BatchAnswer, reach: F64) -> BatchAnswer:
    """``ans`` with every item still short (:func:`short`) polished from its answer onto its
    targets, to its own tolerance, as exact reach polishes: the compiled FABRIK polish,
    trunk held first, pins held, and where that leaves a target beyond the tolerance, exact
    reach's fallback from the caller's start (plain FABRIK, the body moved across:
    ``Engine.exact_fallback``) (``serving.retry_polish``, docs/generalisation-serving-2.md
    item 37). Its ``solvers`` end with ``fabrik-polish`` (once: a path that already ends
    with it is not given it twice). An item the polish would leave no nearer (the
    iteration cap) keeps its answer."""
    sel = short(items, ans, reach)
    if sel.size == 0:
        return ans
    few = dataclasses.replace(items.take(sel), poses=compiled.as_f64(ans.pose[sel]))
    lengths = np.ascontiguousarray(bone_lengths(items.poses[sel]))  # the caller's own
    before = ans.take(sel)
    world, errors = before.pose.copy(), before.errors.copy()
    bone_err, iterations = before.max_bone_error.copy(), before.iterations.copy()
    for g in _groups(few.cnt, few.n_t, few.tidx, few.w):
        m = g.members
        world[m], errors[m], bone_err[m], its = solve_fabrik(
            engine, few.take(m), polish=True, lengths=lengths[m], origin=items.poses[sel[m]]
        )
        iterations[m] += its
    nearer = np.flatnonzero(few.farthest(errors) < few.farthest(before.errors))
    polished = BatchAnswer(
        world, errors, bone_err, iterations,
        tuple(path if path[-1:] == ("fabrik-polish",) else (*path, "fabrik-polish")
              for path in before.paths), before.path_of,
    ).take(nearer)  # fmt: skip
    return ans.with_items(sel[nearer], polished)
