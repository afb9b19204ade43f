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

from core import compiled, compiled_fabrik
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
    if n == 0 or items.fab.any() or not items.keep.all():
        return None
    if n > 1 and not (items.ex == items.ex[0]).all():  # all exact reach, or none
        return None
    if not np.array_equal(items.cnt, items.n_t):  # pins: a FABRIK polish holds them
        return None
    if not (one_set(items) and int(passes.min()) == int(passes.max())):
        return None
    c = int(items.cnt[0])
    return covering(engine, items.tidx[0, :c], items.w[0, :c])


def one_set(items: _Items) -> bool:
    """Whether every item has the first one's target set: joints, weights, targets vs pins."""
    if items.poses.shape[0] <= 1:
        return True
    c = int(items.cnt[0])
    return (
        bool((items.cnt == c).all())
        and bool((items.n_t == items.n_t[0]).all())
        and bool((items.tidx[:, :c] == items.tidx[0, :c]).all())
        and bool((items.w[:, :c] == items.w[0, :c]).all())
    )


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
    exact: F64 | None = None,
    weights: F64 | None = None,
) -> tuple[F64, F64, F64, npt.NDArray[np.int64]] | None:
    """``passes`` neural solves of every item, each from the previous answer (inputs as
    :meth:`Engine.solve_arrays` normalises them): world poses ``[B, 21, 3]``, each
    target's distance ``[B, K]``, the relative bone error ``[B]`` and FABRIK iterations
    ``[B]``. ``exact``: the items' tolerances ``[B]`` for exact reach: the last pass ends
    with the FABRIK polish (``weights [K]``: the target set's); if it leaves any item
    beyond its tolerance, None (the general path then also tries plain FABRIK from the
    caller's start, and keeps the closer)."""
    n = poses.shape[0]
    tpos = tpos.copy()
    tpos[:, :, 1] -= floors[:, None]  # the networks know a floor at y = 0
    every = np.ones(n, dtype=np.bool_)
    pose = poses
    errors, bone_err = np.zeros(tidx.shape), np.zeros(n)
    iterations = np.zeros(n, dtype=np.int64)
    for k in range(passes):
        canon, facing, trans, lengths, scales, tcan, x, canvas = compiled.prepare(
            pose, floors, tidx, tpos, counts, every, engine._shapes_c, engine._shape_totals,
            engine.body == "total_length", engine._reference_total,
        )  # fmt: skip
        decoded = engine._run_sequence(x, canvas, sequence)
        if exact is None or k < passes - 1:
            pose, errors, bone_err = compiled.settle(
                decoded, scales, canon, lengths, facing, trans, floors, tidx, tpos, counts
            )
            continue
        out = compiled.unscale(decoded, scales, canon, lengths, every)
        c = int(counts[0])
        w = np.ones(c) if weights is None else weights
        plans = compiled_fabrik.packed_plans(tidx[0, :c], w)
        out, iterations, errs, _ = compiled_fabrik.solve_batch(
            True, out, lengths, np.ascontiguousarray(tcan[:, :c]), exact,
            engine.fabrik_max_iterations, plans.local_ints, plans.local_floats, plans.has_local,
            plans.ints, plans.floats, np.zeros(c, dtype=np.bool_), True,
        )  # fmt: skip
        if np.any(errs > exact[:, None]):
            return None
        pose, errors, bone_err = compiled.finish(
            out, facing, trans, floors, tidx, tpos, counts, lengths
        )
    return pose, errors, bone_err, iterations


def fabrik_batch(items: _Items) -> bool:
    """Whether every item of ``items`` is a FABRIK solve of one target set (the same joints,
    weights and number of pins): :func:`solve_fabrik` answers it."""
    return items.poses.shape[0] > 0 and bool(items.fab.all()) and one_set(items)


def solve_fabrik(
    engine: Engine,
    poses: F64,
    tidx: npt.NDArray[np.int64],
    tpos: F64,
    counts: npt.NDArray[np.int64],
    floors: F64,
    tols: F64,
    weights: F64,
    n_targets: int,
) -> tuple[F64, F64, F64, npt.NDArray[np.int64]]:
    """FABRIK for every item (one target set, ``weights [K]``, the first ``n_targets``
    targets and the rest pins): the canonical frame, the compiled FABRIK, the way back.
    The general path's kernels in its order (bit-identical to it)."""
    n = poses.shape[0]
    tpos = tpos.copy()
    tpos[:, :, 1] -= floors[:, None]
    canon, facing, trans, lengths, _scales, tcan, _x, _canvas = compiled.prepare(
        poses, floors, tidx, tpos, counts, np.zeros(n, dtype=np.bool_), engine._shapes_c,
        engine._shape_totals, engine.body == "total_length", engine._reference_total,
    )  # fmt: skip
    c = int(counts[0])
    plans = compiled_fabrik.packed_plans(tidx[0, :c], weights)
    out, iterations, _, _ = compiled_fabrik.solve_batch(
        False, canon, lengths, np.ascontiguousarray(tcan[:, :c]), tols,
        engine.fabrik_max_iterations, plans.local_ints, plans.local_floats, plans.has_local,
        plans.ints, plans.floats, np.arange(c) >= n_targets, True,
    )  # fmt: skip
    pose, errors, bone_err = compiled.finish(
        out, facing, trans, floors, tidx, tpos, counts, lengths
    )
    return pose, errors, bone_err, iterations
