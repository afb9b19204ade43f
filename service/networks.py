"""The networks' side of a solve: canonical poses and targets in, the networks' answer out.

One fused graph for a single-solver edit (the anchored delta answer inside it), or a
composed sequence of solvers (re-encoding with the targets solved so far pasted between
them, ``composition``), and with ``serving.solve_mirror`` the mirror image's answer too,
averaged in. The engine (:mod:`service.engine`) prepares the canonical inputs and settles
the answer (bone pass, way back to the world); this module runs onnxruntime.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt

from core.skeleton import (
    NUM_JOINTS,
    flat_columns,
    mirror_key,
    mirror_target_columns,
    mirrored_flat,
)
from service.runtime import Fused, _FewRows

if TYPE_CHECKING:  # pragma: no cover
    from service.engine import Engine


def answer(
    engine: Engine, x: npt.NDArray[np.float32], canvas: npt.NDArray[np.float32],
    sequence: tuple[str, ...], views: npt.NDArray[np.bool_],
) -> npt.NDArray[np.float32]:  # fmt: skip
    """The networks' answer ``[B, 63]`` to canonical poses ``x [B, 63]`` and targets
    ``canvas [B, 21, 3]``: :func:`run_once`; for the rows ``views [B]`` asks
    (``serving.solve_mirror``, ``options.mirror``) the mean of it and the answer to the
    mirror image, taken back (``core.skeleton.mirrored_flat``); both views in one run per
    stage where the target set is its own mirror image. Each row alone. One solver's edit
    takes :func:`both_views`, which mirrors its few target columns only (a 2-target solve
    35-60 us faster than this way, interleaved A/B in one process)."""
    if not (views[0] if len(views) == 1 else views.any()):
        return run_once(engine, x, canvas, sequence)
    if len(sequence) == 1 and sequence[0] in engine.mirror_views:  # one solver: the fast way
        return both_views(engine, x, canvas, engine.mirror_views[sequence[0]], views)
    back = mirror_of(engine, sequence)
    if back is None:
        return run_once(engine, x, canvas, sequence)
    n, rows = len(x), np.flatnonzero(views)
    x_m = mirrored_flat(x[rows])
    c_m = mirrored_flat(canvas[rows].reshape(len(rows), -1)).reshape(len(rows), NUM_JOINTS, 3)
    if back == sequence:
        both = run_once(engine, np.concatenate([x, x_m]), np.concatenate([canvas, c_m]), back)
        own, other = both[:n], both[n:]
    elif engine.serving.delta:  # the two sequences step by step together
        own, other = delta_views(engine, x, canvas, x_m, c_m, sequence, back)
    else:
        own, other = run_once(engine, x, canvas, sequence), run_once(engine, x_m, c_m, back)
    own[rows] = (own[rows] + mirrored_flat(other)) * np.float32(0.5)
    return own


@dataclass(frozen=True)
class MirrorView:
    """How one solver's edit is asked of its mirror image: the mirror solver's key
    (``back``; the same key where the target set is its own mirror image), the flat
    canvas columns ``[3k]`` of this solver's targets in its input order (``own``), and
    those whose mirror image is the mirror solver's targets (``other``, x negated by
    ``signs``)."""

    key: str
    back: str
    own: npt.NDArray[np.intp]
    other: npt.NDArray[np.intp]
    signs: npt.NDArray[np.float32]


def mirror_views(solver_joints: dict[str, npt.NDArray[np.intp]]) -> dict[str, MirrorView]:
    """:class:`MirrorView` of every solver whose mirror image is among the solvers."""
    out = {}
    for key, joints in solver_joints.items():
        back = mirror_key(key)
        if back in solver_joints:
            own, other, signs = mirror_target_columns(joints, solver_joints[back])
            out[key] = MirrorView(key, back, own, other, signs.astype(np.float32))
    return out


def both_views(
    engine: Engine, x: npt.NDArray[np.float32], canvas: npt.NDArray[np.float32],
    view: MirrorView, views: npt.NDArray[np.bool_],
) -> npt.NDArray[np.float32]:  # fmt: skip
    """:func:`answer` of one solver's edit (``view``) with its mirror image on the rows
    ``views`` asks: the mirrored inputs taken straight from flat columns, one run of both
    views where the target set is its own mirror image. The same numbers as the general
    way (a permutation and a sign are exact). Where every row asks and the models ship
    the set's mirror graph (``trainer.mirror``), that graph does all of it in one run."""
    n = len(x)
    flat = canvas.reshape(n, -1)
    targets = flat.take(view.own, axis=1)  # (a quarter of indexing's cost on one row)
    graph = engine.mirror_graphs.get(view.key)
    if graph is not None and (views[0] if n == 1 else views.all()):
        return graph(x, targets)
    rows = np.flatnonzero(views)
    x_m = mirrored_flat(x[rows])
    t_m = flat[rows[:, None], view.other] * view.signs
    if view.back == view.key:
        both = engine.fused[view.key](np.concatenate([x, x_m]), np.concatenate([targets, t_m]))
        own, other = both[:n], both[n:]
    else:
        own, other = engine.fused[view.key](x, targets), engine.fused[view.back](x_m, t_m)
    own[rows] = (own[rows] + mirrored_flat(other)) * np.float32(0.5)
    return own


class OneRun(NamedTuple):
    """How :func:`answer` of one row runs one graph once (:func:`one_run`): the graph's
    few-rows runner, its rows (2: the mirror image's the second), the flat canvas columns
    ``[3k]`` of its target input in its order (``own``), and for the second row, the
    columns whose mirror images are its targets (``other``, x negated by ``signs``).
    (A named tuple: a frozen dataclass cost ~1 us more per solve to make.)"""

    few: _FewRows
    rows: int
    own: npt.NDArray[np.intp]
    other: npt.NDArray[np.intp]
    signs: npt.NDArray[np.float32]


_NO_COLUMNS, _NO_SIGNS = np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.float32)


def one_run(engine: Engine, sequence: tuple[str, ...], mirror: bool) -> OneRun | None:
    """Where :func:`answer` of one row runs one graph once (a single solver): the set's
    fused graph; with ``mirror``, on two rows (the mirror image's the second) where the set
    is its own mirror image (``both_views``' numpy way, bit for bit the mirror graph's:
    the mirroring and the mean go into the kernels, ``core.compiled.prepare_into``, and the
    run costs ~5 us less than the mirror graph's, whose ten gathers, products and sums are
    each an onnxruntime node), else its mirror graph; None where it is not one run."""
    if len(sequence) != 1:
        return None
    key = sequence[0]
    view = engine.mirror_views.get(key) if mirror else None
    if view is not None and view.back != view.key:  # both_views: the mirror graph's run
        graph = engine.mirror_graphs.get(view.key)
        return None if graph is None else OneRun(graph.few, 1, view.own, _NO_COLUMNS, _NO_SIGNS)
    # run_once (no mirror image asked, or none to ask), or both views as rows of one run
    net = engine.fused.get(key)
    if net is None or (isinstance(net, Fused) and net.chain is not None):  # not one run
        return None
    if view is None:
        return OneRun(net.few, 1, engine.solver_columns[key], _NO_COLUMNS, _NO_SIGNS)
    return OneRun(net.few, 2, view.own, view.other, view.signs)


def mirror_of(engine: Engine, sequence: tuple[str, ...]) -> tuple[str, ...] | None:
    """The solver sequence of ``sequence``'s mirror image, or None if a solver has no
    mirror among the models."""
    got = [engine.mirror_views.get(key) for key in sequence]
    if not got or None in got:  # no networks to ask, or one without a mirror image
        return None
    return tuple(v.back for v in got if v is not None)


def run_once(
    engine: Engine,
    x: npt.NDArray[np.float32],
    canvas: npt.NDArray[np.float32],
    sequence: tuple[str, ...],
) -> npt.NDArray[np.float32]:
    """Encode, run a solver sequence, decode: one ORT run per stage."""
    if len(sequence) == 1:  # one fused run: encode, solve, decode (the delta answer in it)
        key = sequence[0]
        targets = canvas.take(engine.solver_joints[key], axis=1).reshape(len(x), -1)
        return engine.fused[key](x, targets)
    if engine.serving.delta:  # shipped fused graphs give the (anchored) delta answer
        return delta(engine, x, canvas, sequence)
    z = engine.encoder(x)  # none (only uncovered joints) or a composed sequence
    if sequence:
        z = compose(engine, z, canvas, sequence)
    return engine.decoder(z)


def delta(
    engine: Engine,
    x: npt.NDArray[np.float32],
    canvas: npt.NDArray[np.float32],
    sequence: tuple[str, ...],
) -> npt.NDArray[np.float32]:
    """Delta answers (``serving.delta``) of a sequence of solvers (one alone is
    :func:`run_once`'s single fused run): each solver's fused graph moves the CURRENT
    pose by what it changes in the decoded pose (anchored or not, as exported), so the
    autoencoder's own error on the start pose never reaches the answer. Between solvers
    the targets solved so far are pasted onto the pose (``composition="reencode"``): the
    one view of :func:`delta_views`."""
    return delta_views(engine, x, canvas, x[:0], canvas[:0], sequence, sequence)[0]


def delta_views(
    engine: Engine, x: npt.NDArray[np.float32], canvas: npt.NDArray[np.float32],
    x_m: npt.NDArray[np.float32], c_m: npt.NDArray[np.float32],
    sequence: tuple[str, ...], back: tuple[str, ...],
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:  # fmt: skip
    """:func:`delta` of ``sequence`` on ``x``, ``canvas`` and of its mirror sequence
    ``back`` on the mirror image ``x_m``, ``c_m``, the two step by step together, so that
    a step whose set is its own mirror image (both ankles, both wrists, the head) runs both
    views as the rows of one run; a step whose mirror is another set runs the two graphs.
    Each view's numbers are those it gets alone (a composed edit with such a step 5-7 %
    faster, interleaved A/B in one process). No mirrored rows: :func:`delta`."""
    pose, pose_m = x.copy(), x_m.copy()
    n, m = len(x), len(x_m)
    flat, flat_m = canvas.reshape(n, -1), c_m.reshape(m, 3 * NUM_JOINTS)  # m may be 0
    for (key, joints, cols), (key_m, joints_m, cols_m) in zip(
        steps(engine, sequence), steps(engine, back), strict=True
    ):
        if cols is not None:
            pose[:, cols] = flat[:, cols]
        if cols_m is not None:
            pose_m[:, cols_m] = flat_m[:, cols_m]
        t, t_m = canvas[:, joints].reshape(n, -1), c_m[:, joints_m].reshape(m, 3 * len(joints_m))
        if key == key_m and m:  # both views as the rows of one run
            both = engine.fused[key](np.concatenate([pose, pose_m]), np.concatenate([t, t_m]))
            pose, pose_m = both[:n], both[n:]
            continue
        pose = engine.fused[key](pose, t)
        if m:
            pose_m = engine.fused[key_m](pose_m, t_m)
    return pose, pose_m


def steps(
    engine: Engine, sequence: tuple[str, ...]
) -> list[tuple[str, npt.NDArray[np.intp], npt.NDArray[np.intp] | None]]:
    """Per solver of a delta sequence: its key, its joints, and the pose columns of
    the targets solved before it, pasted first (None: nothing to paste). Memoised."""
    out = engine._delta_steps.get(sequence)
    if out is None:
        out, done = [], list[int]()
        for key in sequence:
            joints = engine.solver_joints[key]
            cols = None
            if engine.composition == "reencode" and done:
                cols = flat_columns(done)
            out.append((key, joints, cols))
            done.extend(int(j) for j in joints if int(j) not in done)
        if len(engine._delta_steps) >= 4096:  # bounded: forget everything, start again
            engine._delta_steps.clear()
        engine._delta_steps[sequence] = out
    return out


def compose(
    engine: Engine,
    z: npt.NDArray[np.float32],
    canvas: npt.NDArray[np.float32],
    sequence: tuple[str, ...],
) -> npt.NDArray[np.float32]:
    """Run a solver sequence on latents ``[M, D]`` whose targets are on ``canvas``.

    ``composition="reencode"`` (default): before each solver after the first, decode,
    paste the targets solved so far onto their joints and re-encode, so a later solver
    starts from a pose that already meets the earlier targets; after the last solver,
    ``projections`` rounds of paste-all-targets and re-encode. ``"sequential"``: the
    paper's ẑ = S_t3(S_t2(S_t1(z))). Either cycles ``passes`` times through the
    sequence (1 is best: a solver re-applied to its own output overshoots)."""
    if len(sequence) == 1:
        key = sequence[0]
        return engine.solvers[key](z, canvas[:, engine.solver_joints[key]].reshape(len(z), -1))
    flat = canvas.reshape(len(z), -1)
    done: list[int] = []
    for _ in range(engine.composition_passes):
        for key in sequence:
            joints = engine.solver_joints[key]
            if engine.composition == "reencode" and done:
                z = paste(engine, z, flat, done)
            z = engine.solvers[key](z, canvas[:, joints].reshape(len(z), -1))
            done.extend(int(j) for j in joints if int(j) not in done)
    if engine.composition == "reencode":
        for _ in range(engine.projections):
            z = paste(engine, z, flat, done)
    return z


def paste(
    engine: Engine, z: npt.NDArray[np.float32], flat: npt.NDArray[np.float32], joints: list[int]
) -> npt.NDArray[np.float32]:
    """Decode, put ``joints`` on their targets, encode: back onto the pose manifold."""
    x = engine.decoder(z)
    cols = flat_columns(joints)
    x[:, cols] = flat[:, cols]
    return engine.encoder(x)
