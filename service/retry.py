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
from typing import TYPE_CHECKING, Any

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

#: Metres: how much nearer the polish must bring an item's farthest target to be kept; where
#: the farthest stays where it was (an unreachable target the polish does not move), the
#: targets' mean decides, by as much. A strict ``<`` on the farthest alone kept or dropped
#: a polish that brought another target 6 mm nearer by the last bits of an error it did not
#: change: the same edit 1 nm across answered 5 cm apart (an API audit, 2026-12-06).
NEARER = 1e-9


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
    reach, within = reaches(engine, items, ans.errors)
    if within:  # the common case: one kernel
        return ans
    sel = short(items, ans, reach)
    if sel.size == 0:
        return ans
    again = engine._solve_items(
        items.soft(sel, compiled.as_f64(ans.pose)), np.ones(sel.size, np.int64)
    )
    ans = ans.with_items(sel, again)
    return polish_short(engine, items, ans, reach) if engine.serving.retry_polish else ans


def reaches(
    engine: Engine, items: _Items, errors: npt.NDArray[np.floating[Any]]
) -> tuple[F64, bool]:
    """``[B]``: how far from a target each item's soft answer may end before it is retried
    (the module's threshold, ``compiled.retry_reaches``), and whether ``errors [B, K]``
    are all within the least of them."""
    out = np.empty(items.poses.shape[0])
    within = compiled.retry_reaches(
        items.poses, items.soft_ik, engine.serving.retry_reach, *engine.body_args,
        compiled.as_f64(errors), out,
    )  # fmt: skip
    return out, within


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
    with it is not given it twice), or ``fabrik-fallback`` where the fallback's answer was
    kept, as exact reach says it. An item the polish would leave no nearer (the iteration
    cap; :data:`NEARER`) keeps its answer."""
    sel = short(items, ans, reach)
    if sel.size == 0:
        return ans
    few = dataclasses.replace(items.take(sel), poses=compiled.as_f64(ans.pose[sel]))
    lengths = np.ascontiguousarray(bone_lengths(items.poses[sel]))  # the caller's own
    before = ans.take(sel)
    world, errors = before.pose.copy(), before.errors.copy()
    bone_err, iterations = before.max_bone_error.copy(), before.iterations.copy()
    fell = np.zeros(sel.size, dtype=np.bool_)
    for g in _groups(few.cnt, few.n_t, few.tidx, few.w):
        m = g.members
        world[m], errors[m], bone_err[m], its, fell[m] = solve_fabrik(
            engine, few.take(m), polish=True, lengths=lengths[m], origin=items.poses[sel[m]]
        )
        iterations[m] += its
    nearer = np.flatnonzero(_nearer(few, errors, before.errors))
    paths, path_of = _polished_paths(before, fell)
    polished = BatchAnswer(world, errors, bone_err, iterations, paths, path_of).take(nearer)
    return ans.with_items(sel[nearer], polished)


def _nearer(
    items: _Items, errors: npt.NDArray[np.floating[Any]], before: npt.NDArray[np.floating[Any]]
) -> npt.NDArray[np.bool_]:
    """Which items ``errors`` brings nearer their targets than ``before`` (:data:`NEARER`):
    the farthest target, or where that stays, the targets' mean."""
    far, was = items.farthest(errors), items.farthest(before)
    gain = np.where(items.targets(), before - errors, 0.0).sum(axis=1)  # n_t times the mean's
    level = np.abs(far - was) <= NEARER
    out: npt.NDArray[np.bool_] = (far < was - NEARER) | (level & (gain > NEARER * items.n_t))
    return out


def _polished_paths(
    before: BatchAnswer, fell: npt.NDArray[np.bool_]
) -> tuple[tuple[tuple[str, ...], ...], npt.NDArray[np.int64]]:
    """Each polished item's solver path: its own, then ``fabrik-polish`` (once), or
    ``fabrik-fallback`` where exact reach's fallback answered (``fell``)."""
    index: dict[tuple[str, ...], int] = {}
    path_of = np.empty(fell.size, dtype=np.int64)
    for i, (p, f) in enumerate(zip(before.path_of.tolist(), fell.tolist(), strict=True)):
        path = before.paths[p]
        base = path[:-1] if path[-1:] == ("fabrik-polish",) else path
        step = "fabrik-fallback" if f else "fabrik-polish"
        path_of[i] = index.setdefault((*base, step), len(index))
    return tuple(index), path_of
