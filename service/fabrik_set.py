"""The compiled FABRIK of one target set, as the engine runs it: the textbook algorithm,
and where its answer folds the hips, the same with the hips rigid.

The textbook algorithm places each child of the pelvis on its own: its backward pass turns
each hip bone towards its own knee. With both feet pinned and the pelvis dragged past a hip,
both knees lie on one side of the pelvis and so do both hips: an audit (2026-12-07) dragged
a real pose's pelvis 10 cm sideways over pinned ankles and got the hips 0.028 m apart
(0.129 in the start; a character's hips turned 93 degrees), every target "reached". FABRIK
with rigid hips everywhere cannot turn the pelvis and loses reach (docs/kinematics.md), so
an answer whose hips ended nearer each other than :data:`FOLDED` of the start's is solved
again with ``rigid_hips`` and kept where that reaches as well (:data:`SLACK`). A drag the
translated pelvis cannot follow (a pelvis target beyond the pinned legs' reach without
turning it) keeps the folded answer: the retry cannot improve on it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from core import compiled_fabrik
from core.rigid import SQUEEZED
from core.skeleton import JOINT_INDEX, SUBTREE

F64 = npt.NDArray[np.floating[Any]]
#: An answer whose hips are nearer each other than this share of the start's distance has
#: folded them onto one side of the pelvis (as ``serving.keep_pairs`` calls a pair squeezed).
FOLDED = SQUEEZED
#: The rigid answer is kept where it reaches every target the folded one reached and the
#: others no more than this farther (metres, canonical): a valid body before a few mm.
SLACK = 0.01
_HIPS = (JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"])
#: The joints of the legs: only a target or pin on one moves a hip (the others carry them)
_LEGS = SUBTREE[_HIPS[0]] | SUBTREE[_HIPS[1]]


def fabrik_set(
    polish: bool, starts: F64, lengths: F64, goals: F64, tols: F64,
    idx: npt.NDArray[np.int64], weights: F64, hold: npt.NDArray[np.bool_], max_iterations: int,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.float64]]:  # fmt: skip
    """The compiled FABRIK (``polish``: the exact-reach polish) of canonical ``starts``
    ``[B, 21, 3]`` onto ``goals`` ``[B, K, 3]`` for one target set (joints ``idx``,
    ``weights``, pins ``hold``): poses, iterations (a rigid retry's added) and each target's
    error. The columns are solved in joint order, so the answer is the set's whatever order
    a request listed its targets and pins in (the polish's sweeps follow the columns: an
    API audit, 2026-12-06, saw both ankles pinned as ``[right, left]`` move an unasked wrist
    44 cm from ``[left, right]``)."""
    order = np.argsort(idx, kind="stable")
    plans = compiled_fabrik.packed_plans(idx[order], weights[order], hold[order])

    def run(sel: npt.NDArray[np.intp] | slice, rigid: bool) -> tuple[Any, ...]:
        return compiled_fabrik.solve_batch(
            polish, np.ascontiguousarray(starts[sel]), np.ascontiguousarray(lengths[sel]),
            np.ascontiguousarray(goals[sel][:, order]), np.ascontiguousarray(tols[sel]),
            max_iterations, plans.local_ints, plans.local_floats, plans.has_local, plans.ints,
            plans.floats, np.ascontiguousarray(hold[order]), True, rigid,
        )  # fmt: skip

    pose, its, errs, _ = run(slice(None), False)
    if not _LEGS[idx].any():  # no hip moved: none folded
        folded = np.empty(0, dtype=np.intp)
    else:
        folded = np.flatnonzero(width2(pose) < FOLDED * FOLDED * width2(starts))
    if folded.size:  # again with the hips rigid, kept where it reaches as well
        r_pose, r_its, r_errs, _ = run(folded, True)
        was, tol = errs[folded], tols[folded, None]
        near = np.all(np.where(was <= tol, r_errs <= tol, r_errs <= was + SLACK), axis=1)
        sel = folded[near]
        pose[sel], its[sel], errs[sel] = r_pose[near], its[sel] + r_its[near], r_errs[near]
    back = np.empty_like(errs)
    back[:, order] = errs
    return pose, its, back


def width2(poses: F64) -> npt.NDArray[np.float64]:
    """The squared distance between the hips of each pose ``[B, 21, 3]``."""
    d = poses[:, _HIPS[0]] - poses[:, _HIPS[1]]
    out: npt.NDArray[np.float64] = np.einsum("ij,ij->i", d, d)
    return out
