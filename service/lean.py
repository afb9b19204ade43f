"""The lean solve: a batch whose items all ask for the same thing of the networks.

The interactive drag (one item) and a clip's cleanup (many items, one target set) are
almost always: method neural, soft reach, bone lengths kept, no pins, every target on a
trained solver, the same passes. Such a batch needs none of the general path's grouping,
FABRIK polish or per-pass bookkeeping (:meth:`service.engine.Engine._solve_once`): each
pass is one compiled call in (:func:`core.compiled.prepare`), one onnxruntime run per
solver of the sequence, and one compiled call out (:func:`core.compiled.settle`: the bone
pass and the way back to the world). These are the general path's kernels in its order,
so the answers are bit-identical to it (``tests/service/test_lean.py``).
"""

from __future__ import annotations

from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from core import compiled
from core.skeleton import JOINT_NAMES

if TYPE_CHECKING:  # pragma: no cover
    from service.engine import Engine
    from service.problems import _Items

F64 = compiled.F64


@lru_cache(maxsize=4096)
def uncovered(sequence: tuple[str, ...], idx: tuple[int, ...]) -> npt.NDArray[np.bool_]:
    """Which targets of ``idx`` no solver of ``sequence`` covers."""
    covered = {j for key in sequence for j in key.split("+")}
    return np.asarray([JOINT_NAMES[j] not in covered for j in idx], dtype=np.bool_)


def lean_sequence(
    engine: Engine, items: _Items, passes: npt.NDArray[np.int64]
) -> tuple[str, ...] | None:
    """The solver sequence every item of ``items`` runs, if the batch can take the lean
    path; else None (the general path solves it)."""
    n = items.poses.shape[0]
    if n == 0 or items.fab.any() or items.ex.any() or not items.keep.all():
        return None
    if not np.array_equal(items.cnt, items.n_t):  # pins: a FABRIK polish holds them
        return None
    c = int(items.cnt[0])
    if n > 1 and not (
        int(passes.min()) == int(passes.max())
        and bool((items.cnt == c).all())
        and bool((items.tidx[:, :c] == items.tidx[0, :c]).all())
        and bool((items.w[:, :c] == items.w[0, :c]).all())
    ):
        return None
    return covering(engine, items.tidx[0, :c], items.w[0, :c])


def covering(engine: Engine, idx: npt.NDArray[np.int64], weights: F64) -> tuple[str, ...] | None:
    """The solver sequence of one target set if it covers every target, else None."""
    if idx.size == 0:
        return None
    seq = engine._plan_for(np.ascontiguousarray(idx), np.ascontiguousarray(weights))
    if not seq or uncovered(seq, tuple(idx.tolist())).any():  # FABRIK would place one
        return None
    return seq


def solve_lean(
    engine: Engine,
    poses: F64,
    tidx: npt.NDArray[np.int64],
    tpos: F64,
    counts: npt.NDArray[np.int64],
    floors: F64,
    passes: int,
    sequence: tuple[str, ...],
) -> tuple[F64, F64, F64]:
    """``passes`` neural soft solves of every item, each from the previous answer (inputs
    as :meth:`Engine.solve_arrays` normalises them): world poses ``[B, 21, 3]``, each
    target's distance ``[B, K]`` and the relative bone error ``[B]``."""
    n = poses.shape[0]
    tpos = tpos.copy()
    tpos[:, :, 1] -= floors[:, None]  # the networks know a floor at y = 0
    every = np.ones(n, dtype=np.bool_)
    pose = poses
    errors, bone_err = np.zeros(tidx.shape), np.zeros(n)
    for _ in range(passes):
        canon, facing, trans, lengths, scales, _tcan, x, canvas = compiled.prepare(
            pose, floors, tidx, tpos, counts, every, engine._shapes_c, engine._shape_totals,
            engine.body == "total_length", engine._reference_total,
        )  # fmt: skip
        decoded = engine._run_sequence(x, canvas, sequence)
        pose, errors, bone_err = compiled.settle(
            decoded, scales, canon, lengths, facing, trans, floors, tidx, tpos, counts
        )
    return pose, errors, bone_err
