"""The lean solve: a batch whose items all ask for the same thing of the networks.

The interactive drag (one item) and a clip's cleanup (many items, one target set) are
almost always: method neural, bone lengths kept, every target on a trained solver, the
same passes, pins or not. Such a batch needs none of the general path's grouping or
per-pass bookkeeping (:meth:`service.engine.Engine._solve_once`): each pass is one
compiled call in (:func:`core.compiled.prepare`), one onnxruntime run per solver of the
sequence, and one compiled call out (:func:`core.compiled.settle`: the bone pass and the
way back to the world); with pins, or exact reach's last pass, the bone pass, the compiled
FABRIK polish (and where exact reach's misses, plain FABRIK from the caller's start) and
the way back. These are the general path's kernels in its order, so
the answers are bit-identical to it (``tests/service/test_lean.py``).
"""

from __future__ import annotations

import threading
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from core import compiled
from core.skeleton import JOINT_NAMES, NUM_JOINTS
from service import networks
from service.problems import BatchAnswer, _Items, solver_path, solver_paths

if TYPE_CHECKING:  # pragma: no cover
    from service.engine import Engine

F64 = compiled.F64
Bool = compiled.Bool
#: A lean solve's world poses, target distances, bone errors and FABRIK iterations.
Solved = tuple[F64, F64, F64, npt.NDArray[np.int64]]
#: :func:`solve_lean`'s: and which items exact reach's fallback answered (plain FABRIK).
LeanSolved = tuple[F64, F64, F64, npt.NDArray[np.int64], npt.NDArray[np.bool_]]


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
    """The solver sequence of one target set if it covers every target, else None;
    memoised on the set's (joints, weights) bytes (one look-up where the plan's and
    :func:`uncovered`'s were two and their keys' making: ~1 us of a lone solve)."""
    key = (idx.tobytes(), weights.tobytes())
    seq = engine._covering.get(key, ())  # (() not known: a known one is None or not empty)
    if seq != ():
        return seq
    seq = None
    if idx.size:
        seq = engine._plan_for(np.ascontiguousarray(idx), np.ascontiguousarray(weights))
        if not seq or uncovered(seq, tuple(idx.tolist())).any():  # FABRIK would place one
            seq = None
    if len(engine._covering) >= 65536:  # bounded: forget everything, start again
        engine._covering.clear()
    engine._covering[key] = seq
    return seq


def lean_answer(
    engine: Engine, items: _Items, passes: int, sequence: tuple[str, ...] | None
) -> BatchAnswer:
    """The answer of a batch that :func:`lean_sequence` (``sequence``) or
    :func:`fabrik_batch` (``sequence`` None: FABRIK) let through."""
    n = items.poses.shape[0]
    if sequence is None:  # FABRIK: no sequence (-1), no suffix
        world, errors, bone_err, iterations, _ = solve_fabrik(engine, items)
        seq_of, suffix = np.full(n, -1, np.int64), np.zeros(n, np.int64)
    else:  # the general path's suffixes: 1 polish (exact reach, or pins), 2 fallback
        exact = bool(items.ex[0])
        world, errors, bone_err, iterations, fell = solve_lean(
            engine, items, passes, sequence, exact
        )
        polished = int(exact or int(items.cnt[0]) > int(items.n_t[0]))
        if n == 1:  # one edit: its path without the arrays of codes (solver_paths' own)
            path = solver_path(3 + (2 if fell[0] else polished), [sequence])
            return BatchAnswer(world, errors, bone_err, iterations, (path,), np.zeros(1, np.int64))
        seq_of, suffix = np.zeros(n, np.int64), np.where(fell, 2, polished)
    paths, path_of = solver_paths(seq_of, suffix, [sequence or ()])
    return BatchAnswer(world, errors, bone_err, iterations, paths, path_of)


def solve_lean(
    engine: Engine, items: _Items, passes: int, sequence: tuple[str, ...], exact: bool = False
) -> LeanSolved:
    """``passes`` neural solves of every item of ``items`` (one target set), each from the
    previous answer: world poses ``[B, 21, 3]``, each target's distance ``[B, K]``, the
    relative bone error ``[B]`` and FABRIK iterations ``[B]``. Pins (the columns from
    ``n_t`` on) go exactly where they are asked in every pass, by the FABRIK polish that
    holds the solved targets where the networks put them. ``exact``: the last pass ends
    with the FABRIK polish onto each item's tolerance, pins held; where it leaves an item
    beyond it, plain FABRIK from the caller's start too, the nearer kept
    (:meth:`Engine.exact_fallback`, as the general path): those items are marked."""
    n = items.poses.shape[0]
    c = int(items.cnt[0])
    collar, hold = engine.collar_items(items), engine.pelvis_holds(items)
    fell = np.zeros(n, dtype=np.bool_)
    if (
        (n == 1 or (n <= BOUND_ITEMS and one_view(items))) and not exact and c == int(items.n_t[0])
    ):  # one soft edit (or a few, as a turn search's candidates), no pins: in place
        one = solve_one(engine, items, passes, sequence, collar, hold)
        if one is not None:  # (one graph answers each pass)
            return (*one, fell)
    pins = np.arange(c) >= int(items.n_t[0])
    pinned = bool(pins.any())
    tidx, counts, floors = items.tidx, items.cnt, items.floors
    every = np.ones(n, dtype=np.bool_)
    pose = items.poses
    errors, bone_err = np.zeros(tidx.shape), np.zeros(n)
    iterations = np.zeros(n, dtype=np.int64)
    tpos = None  # the targets with the floor taken off: the first pass's, for every pass
    for k in range(passes):
        tpos, (canon, facing, trans, lengths, scales, tcan, x, canvas) = engine._prepare(
            pose, items, every, tpos
        )
        decoded = networks.answer(engine, x, canvas, sequence, items.mirror)
        last = exact and k == passes - 1
        if not (last or pinned):
            pose, errors, bone_err = compiled.settle(
                decoded, scales, canon, lengths, facing, trans, floors, tidx, tpos, counts,
                items.carry, engine.chain_mask, engine.serving.keep_ease, collar, hold,
                engine.pairs_of(items.body), engine.serving.bend_side, items.soft_ik,
                engine.serving.keep_feet,
            )  # fmt: skip
            continue
        out = compiled.unscale(
            decoded, scales, canon, lengths, every, tidx, counts, items.carry, engine.chain_mask,
            engine.serving.keep_ease, collar, hold, engine.pairs_of(items.body),
            engine.serving.bend_side, items.soft_ik, engine.serving.keep_feet,
        )  # fmt: skip
        # exact: every column onto its goal; soft: the pins, the solved targets held
        goal = (
            tcan[:, :c] if last else np.where(pins[None, :, None], tcan[:, :c], out[:, tidx[0, :c]])
        )
        polished = engine._fabrik(
            True, out, lengths, goal, items.tols, tidx[0, :c], items.w[0, :c], pins, items.body
        )
        before, (out, iterations) = out, polished[:2]
        if not last:  # the legs the polish for the pins raised or sank put back
            out = engine.planted(out, before, tidx[0, :c])
        if last:  # from the caller's start: this pass's own where it is the first
            start = canon if k == 0 else engine.origin_in(items.poses, facing, trans, floors)
            out, iterations, fell = engine.exact_fallback(
                polished, start, lengths, goal, items.tols, tidx[0, :c], items.w[0, :c], pins,
                before,
            )  # fmt: skip
        pose, errors, bone_err = compiled.finish(
            out, facing, trans, floors, tidx, tpos, counts, lengths
        )
    return pose, errors, bone_err, iterations, fell


#: At most this many soft items without pins are solved as :func:`solve_one` solves one:
#: one bound run per pass for them all (a lone edit's turn search's 13 candidates: ~60 us
#: less than the general lean loop's runs and arrays, the same bits: rows are answered alone).
BOUND_ITEMS = 16
#: Per thread: :func:`solve_one`'s canonical frame, lengths and scale between its kernels.
_WORK = threading.local()


def one_view(items: _Items) -> bool:
    """Whether every item of ``items`` asks alike for the mirror image (all or none)."""
    return bool(items.mirror.all()) or not bool(items.mirror.any())


def _workspace() -> tuple[F64, F64, F64, F64, F64]:
    """This thread's ``canon [1, 21, 3]``, ``facing [1, 2]``, ``trans [1, 3]``,
    ``lengths [1, 20]`` and ``scales [1]`` (overwritten by every :func:`solve_one`)."""
    ws: tuple[F64, F64, F64, F64, F64] | None = getattr(_WORK, "ws", None)
    if ws is None:
        ws = _WORK.ws = (
            np.empty((1, NUM_JOINTS, 3)), np.empty((1, 2)), np.empty((1, 3)),
            np.empty((1, NUM_JOINTS - 1)), np.empty(1),
        )  # fmt: skip
    return ws


def _workspace_of(n: int) -> tuple[F64, F64, F64, F64, F64]:
    """:func:`_workspace`'s arrays for ``n`` items, made afresh."""
    return (
        np.empty((n, NUM_JOINTS, 3)), np.empty((n, 2)), np.empty((n, 3)),
        np.empty((n, NUM_JOINTS - 1)), np.empty(n),
    )  # fmt: skip


def solve_one(
    engine: Engine, items: _Items, passes: int, sequence: tuple[str, ...], collar: Bool,
    hold: F64,
) -> Solved | None:  # fmt: skip
    """:func:`solve_lean` of one soft edit without pins (``items`` of one; or of a few,
    :data:`BOUND_ITEMS`, of one target set, all asking alike for the mirror image), where
    each pass is one run of one graph (:func:`service.networks.one_run`); else None. The same
    kernels in the same order, in three calls and no copies: the canonical inputs go
    straight into onnxruntime's bound input buffers (:func:`core.compiled.prepare_into`),
    each pass but the last ends and the next begins in one call from the bound output
    (:func:`core.compiled.settle_prepare`), and the last ends in
    :func:`core.compiled.settle_last`. Bit for bit :func:`solve_lean`'s answer
    (``tests/service/test_lean.py``)."""
    found = networks.one_run(engine, sequence, bool(items.mirror[0]))
    if found is None:
        return None
    few, rows, cols, other, signs = found
    n = items.poses.shape[0]
    (x_in, t_in), out, run = few.bound(((rows * n, 3 * NUM_JOINTS), (rows * n, cols.shape[0])))
    canon, facing, trans, lengths, scales = _workspace() if n == 1 else _workspace_of(n)
    s = engine.serving
    body = engine.body_args
    compiled.prepare_into(
        items.poses, items.floors, items.tidx, items.tpos, items.cnt, *body, cols, other, signs,
        x_in, t_in, canon, facing, trans, lengths, scales,
    )  # fmt: skip
    rest = (items.floors, items.tidx, items.tpos, items.cnt, items.carry, engine.chain_mask,
            s.keep_ease, collar, hold, engine.pairs_of(items.body), s.bend_side, items.soft_ik,
            s.keep_feet)  # fmt: skip
    for _ in range(passes - 1):
        run()
        compiled.settle_prepare(
            out,
            scales,
            canon,
            lengths,
            facing,
            trans,
            *rest,
            *body,
            cols,
            other,
            signs,
            x_in,
            t_in,
        )
    run()
    pose, errors, bone_err = np.empty((n, NUM_JOINTS, 3)), np.empty(items.tidx.shape), np.empty(n)
    compiled.settle_last(
        out, scales, canon, lengths, facing, trans, *rest, pose, errors, bone_err
    )  # (into arrays made here: a returned one costs numba more)
    return pose, errors, bone_err, np.zeros(n, dtype=np.int64)


def fabrik_batch(items: _Items) -> bool:
    """Whether every item of ``items`` is a FABRIK solve of one target set (the same joints,
    weights and number of pins): :func:`solve_fabrik` answers it."""
    return items.poses.shape[0] > 0 and bool(items.fab.all()) and one_set(items)


def solve_fabrik(
    engine: Engine, items: _Items, *, polish: bool = False, lengths: F64 | None = None,
    origin: F64 | None = None,
) -> LeanSolved:  # fmt: skip
    """FABRIK for every item of ``items`` (one target set, its targets then its pins): the
    canonical frame, the compiled FABRIK, the way back; as :func:`solve_lean` answers (and
    which items kept exact reach's fallback: none without ``origin``).
    ``polish``: the exact-reach polish instead (trunk held first); ``lengths`` ``[B, 20]``:
    the bones to keep (default: the poses' own); ``origin`` ``[B, 21, 3]`` (world): the
    callers' starts, from which exact reach's fallback tries plain FABRIK (and the body
    moved across) where the polish leaves a target beyond its tolerance
    (:meth:`Engine.exact_fallback`)."""
    n = items.poses.shape[0]
    c = int(items.cnt[0])
    tpos, (canon, facing, trans, own, _scales, tcan, _x, _canvas) = engine._prepare(
        items.poses, items, np.zeros(n, dtype=np.bool_)
    )
    lengths = own if lengths is None else lengths
    idx, w, pins = items.tidx[0, :c], items.w[0, :c], np.arange(c) >= int(items.n_t[0])
    polished = engine._fabrik(polish, canon, lengths, tcan[:, :c], items.tols, idx, w, pins,
                              items.body if polish else None)  # fmt: skip
    out, iterations = polished[0], polished[1]
    fell = np.zeros(n, dtype=np.bool_)
    if origin is not None:
        start = engine.origin_in(origin, facing, trans, items.floors)
        out, iterations, fell = engine.exact_fallback(
            polished, start, lengths, tcan[:, :c], items.tols, idx, w, pins, canon
        )
    pose, errors, bone_err = compiled.finish(
        out, facing, trans, items.floors, items.tidx, tpos, items.cnt, lengths
    )
    return pose, errors, bone_err, iterations, fell
