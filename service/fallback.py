"""FABRIK's answer where the critic finds the networks' answer unlike a real body and
FABRIK's like one (``serving.critic_fabrik``, docs/generalisation-3.md item 55).

The networks answer most edits with a body like the ones they learnt; now and then, on a
body or a pose unlike those, they answer with one that is not, where FABRIK, which moves
only the chains to the targets, leaves the rest of the body as the caller's start has it.
The turn search's critic (``serving.turn_critic``, :func:`service.turns.implausibility`:
the mean distance of a pose to the body the completion networks make of its key points)
tells such answers: where it finds the neural answer more than ``critic_fabrik`` metres
further from a real body than FABRIK's answer to the same edit, and FABRIK's answer reaches
every target and pin within the item's tolerance, the edit is answered by FABRIK (its
solver path: the networks' solvers, which ran, then ``fabrik-critic``). An answer FABRIK
cannot give (a target out of its chains' reach from where the body stands, which the
networks may reach by moving the body) stays the networks', and so does an edit asked to
ease into full stretch (``soft_ik``): a switch between two answers is not smooth, and
FABRIK's does not ease.

Per item, in the same kernels as any FABRIK edit: an item's answer does not depend on
its batch. FABRIK runs only for the items the networks answered with bone lengths kept
whose own score is above the margin (no FABRIK answer can then be better by more)."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from service.problems import BatchAnswer, Solve, _Items, trained_solvers
from service.turns import implausibility

if TYPE_CHECKING:
    from service.engine import Engine

#: The end of the solver path of an edit answered by FABRIK instead of the networks.
STEP = "fabrik-critic"


def prefer_fabrik(engine: Engine, asked: _Items, ans: BatchAnswer, solve: Solve) -> BatchAnswer:
    """``ans`` with FABRIK's answer (from the caller's starts, ``asked`` as the caller gave
    them) for every neural item, bone lengths kept, that the critic finds more than
    ``serving.critic_fabrik`` (m) less like a real body than FABRIK's, FABRIK's reaching
    every target and pin within the item's tolerance."""
    margin = engine.serving.critic_fabrik
    if margin <= 0.0 or ans.pose.shape[0] == 0:
        return ans
    # (an edit asked to ease into full stretch is left to the networks: a switch between
    # two answers is no smooth answer, and FABRIK's does not ease)
    sel = np.flatnonzero(~asked.fab & asked.keep & (asked.soft_ik == 0.0))
    if sel.size == 0:
        return ans
    mine = implausibility(engine, ans.pose[sel], asked.floors[sel])
    far = mine > margin  # only these can lose to a FABRIK answer by more than the margin
    sel, mine = sel[far], mine[far]
    if sel.size == 0:
        return ans
    items = asked.take(sel)
    ones = np.ones(sel.size, dtype=np.int64)
    fab = solve(dataclasses.replace(items, fab=ones.astype(np.bool_)), ones)
    theirs = implausibility(engine, fab.pose, items.floors)
    used = np.arange(items.tidx.shape[1])[None, :] < items.cnt[:, None]
    reached = np.all(~used | (fab.errors <= items.tols[:, None]), axis=1)
    better: npt.NDArray[np.intp] = np.flatnonzero(reached & (theirs + margin < mine))
    if better.size == 0:
        return ans
    rows = sel[better]
    was = ans.take(rows)
    # the networks' solvers (they ran, and lost), then this step: not the turn, polish or
    # pin steps of an answer that is not given
    paths = tuple((*trained_solvers(path), STEP) for path in was.paths)
    chosen = fab.take(better)
    return ans.with_items(rows, dataclasses.replace(chosen, paths=paths, path_of=was.path_of))
