"""Turn search: a many-target edit may ask for the body to face another way.

The solvers were trained on pairs whose goal faces the start's way (docs/generalisation.md
item 1), so when the targets of an edit were taken from a body that has turned (a user
dragging the head, both hands and both feet round), the network bends the body towards
them instead of turning it: on held-out 5-end-effector edits whose two frames are more
than 45° apart its answer is worse than FABRIK's (11.7 against 10.4 cm). Here, before the
edit is solved, its start pose is tried turned about the vertical through its pelvis by
``turn_yaws`` evenly spaced yaws (0 first); each candidate is solved as a soft edit (the
item's passes, bone pass, carry) and the one whose answer scores lowest is kept: the mean
distance of its targets, plus ``turn_plausibility`` times the mean distance of the answer
to what ``turn_critic`` makes of it: the autoencoder's round trip of it, or the body
completion level 1 builds from the answer's own base key points (pelvis, neck, wrists,
ankles): a body bent towards targets it should have turned to is far from the body those
points imply (docs/generalisation-serving.md items 22, 24), the unturned start winning unless
another scores at least ``turn_margin`` metres lower (scores, margin and ``turn_fit`` at
the networks' body size: each answer over its body's scale, ``Engine.scales_of``, so that a
character scaled up or down keeps the same start). The edit is then solved as asked
from the kept start. Only neural items with at least ``turn_min_targets`` targets and no
pins take part (``options.turn_search: false`` opts out): fewer targets say little about a
facing, and pins ask for joints to stay where they are.

The unturned start is solved first, and where its score is within the margin the search
ends there (no other candidate could be kept); otherwise the other candidates are solved
as one batch. A soft item's kept candidate is its answer; an exact one is solved again
from the kept start. At most ``turn_yaws`` + 1 solves per searching item (+ 1 with
``turn_fit``); answers stay bit-identical (each item alone, argmin ties to the unturned
start). The answer's solver path ends with ``turn <deg>`` where the start turned.

With ``turn_fit`` > 0 the search has one more candidate, the start moved to fit its
targets (:func:`fitted`: turned about the vertical and shifted across by the rigid motion
that best carries the targeted joints onto their targets), for a body that travelled as
well as turned (docs/generalisation-serving-2.md item 34). It is kept only if it scores
``turn_fit`` metres below every other candidate; its path ends with ``fit <deg>``.

With ``turn_gate`` > 0 an item searches only if its targets lie at least that far across
from the joints they are for, on average, at the networks' body size
(:func:`target_motion`): targets that near ask for no turn (a quarter turn carries a
standing body's wrists 0.3 m), and such an edit is solved from its start as if it could
not search, on the lone edit's lean path too (docs/generalisation-3.md item 58).

With ``turn_quick`` each candidate is solved in its quick form (one pass, no mirror
image), and the edit then as asked from the start kept, soft ones too unless they asked
for that form (measured, not shipped: docs/generalisation-serving-2.md item 40).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt

from core import compiled
from core.geometry import canonicalise
from core.manifest import Serving
from core.skeleton import FACING_PAIRS, JOINT_INDEX
from service import completion
from service.problems import PELVIS, BatchAnswer, Solve, _Items

if TYPE_CHECKING:  # pragma: no cover
    from service.engine import Engine

F64 = npt.NDArray[np.float64]


@dataclass(frozen=True)
class TurnSearch:
    """An engine's turn search: ``yaws`` candidate turns (1: off) for neural items with at
    least ``min_targets`` targets and no pins, the unturned start kept unless another
    scores ``margin`` metres lower (``plausibility``: the weight in the score of the
    answer's distance to what ``critic`` makes of it, "autoencoder" or "completion"). Read
    from a manifest's ``serving`` block
    (:meth:`of`), which defines the settings and their defaults."""

    yaws: int
    margin: float
    min_targets: int
    plausibility: float
    critic: Literal["autoencoder", "completion"]
    #: > 0: one more candidate, the start moved to fit its targets (:func:`fitted`), kept
    #: only if it scores this many metres below every other
    fit: float = 0.0
    #: candidates solved in their quick form (one pass, no mirror image); the edit is then
    #: solved as asked from the start kept
    quick: bool = False
    #: metres (at the networks' body size): an item searches only if its targets lie this
    #: far across from their joints on average (:func:`target_motion`; 0: every item that
    #: may search does)
    gate: float = 0.0

    @property
    def candidates(self) -> int:
        """Candidate starts per searching item, the unturned one included."""
        return self.yaws + int(self.fit > 0.0)

    @staticmethod
    def of(serving: Serving) -> TurnSearch:
        """The search ``serving`` asks for (``turn_yaws`` 1: none)."""
        return TurnSearch(
            serving.turn_yaws, serving.turn_margin, serving.turn_min_targets,
            serving.turn_plausibility, serving.turn_critic, serving.turn_fit,
            serving.turn_quick, serving.turn_gate,
        )  # fmt: skip

    def searches(
        self, method: str, n_targets: int, pinned: bool, wanted: bool | None = None
    ) -> bool:
        """Whether an item searches (``wanted``: its ``options.turn_search``; None: yes)."""
        return (
            wanted is not False and self.yaws > 1 and method != "fabrik" and not pinned
            and n_targets >= self.min_targets
        )  # fmt: skip

    def factor(self, method: str, n_targets: int, pinned: bool, wanted: bool | None = None) -> int:
        """The solves an item costs per pass: its candidates and itself, or 1 (with
        ``quick``, an upper bound: its candidates each cost one pass, one view)."""
        return self.candidates + 1 if self.searches(method, n_targets, pinned, wanted) else 1


#: No search (models without ``serving.turn_*``, FABRIK-only callers).
NO_SEARCH = TurnSearch.of(Serving())


def searching(engine: Engine, items: _Items) -> npt.NDArray[np.intp]:
    """The items that search: neural, enough targets, no pins, and with ``gate`` targets
    that far from their joints (:func:`target_motion`; none if the search is off)."""
    t = engine.turn_search
    if t.yaws <= 1:
        return np.zeros(0, dtype=np.intp)
    if items.poses.shape[0] == 1:  # one edit (the interactive case): without ufuncs
        return _searching_one(engine, items)
    ok = items.turn & items.neural_unpinned() & (items.n_t >= t.min_targets)
    sel = np.flatnonzero(ok)
    if t.gate > 0.0 and sel.size:  # only those whose targets say the body turned or moved
        starts = items.poses[sel]
        moved = target_motion(starts, items, sel) / engine.body_scales(starts)
        sel = sel[moved >= t.gate]
    return sel


def _searching_one(engine: Engine, items: _Items) -> npt.NDArray[np.intp]:
    """:func:`searching` of one item, in scalars: the same tests and the same division
    (3.2 us where the batch's ufuncs and gathers took 7.7: every lone 5-target edit's)."""
    t, n_t = engine.turn_search, int(items.n_t[0])
    ok = bool(items.turn[0]) and items.neural_unpinned_one(0)
    sel = np.zeros(1 if ok and n_t >= t.min_targets else 0, dtype=np.intp)
    if t.gate > 0.0 and sel.size:
        starts = compiled.as_f64(items.poses)
        moved = target_motion(starts, items, sel)[0] / engine.body_scales(starts)[0]
        return sel if moved >= t.gate else sel[:0]
    return sel


def turned(poses: F64, yaw: float) -> F64:
    """``poses [N, 21, 3]`` (world, +Y up) turned by ``yaw`` radians about the vertical
    through each pose's pelvis."""
    out: F64 = turned_by(poses, np.array([yaw]))[0]
    return out


def turned_by(poses: F64, yaws: F64) -> F64:
    """``poses [N, 21, 3]`` turned by each of ``yaws [S]`` as :func:`turned` turns them:
    ``[S, N, 21, 3]``, one vectorised pass for every turn."""
    c, s = np.cos(yaws)[:, None, None], np.sin(yaws)[:, None, None]
    pelvis = poses[:, PELVIS : PELVIS + 1]
    x, z = poses[..., 0] - pelvis[..., 0], poses[..., 2] - pelvis[..., 2]
    out = np.empty((len(yaws), *poses.shape))
    out[..., 0] = c * x + s * z + pelvis[..., 0]
    out[..., 1] = poses[..., 1]
    out[..., 2] = -s * x + c * z + pelvis[..., 2]
    return out


def own_sum(x: npt.NDArray[np.floating], widths: npt.NDArray[np.int64]) -> F64:
    """``x [N, K, ...]`` summed over each row's own first ``widths[n]`` target columns, as
    numpy sums them for the row alone: the columns a batch pads an item with never take
    part (numpy pairs a sum's terms differently at each width, so a searching item's
    answer moved by ~1e-13 m beside a wider item, and a near tie could have kept another
    candidate)."""
    if widths.size and widths.min() == widths.max() == x.shape[1]:  # no padding: one sum
        whole: F64 = x.sum(axis=1)
        return whole
    out = np.zeros(x.shape[:1] + x.shape[2:])
    for width in np.unique(widths):
        rows = np.flatnonzero(widths == width)
        out[rows] = x[rows, :width].sum(axis=1)
    return out


def target_motion(poses: F64, items: _Items, rows: npt.NDArray[np.intp]) -> F64:
    """How far across (m) the targets of each of ``items[rows]`` lie from the joints of its
    start ``poses [N, 21, 3]`` they are for, on average: an edit that moves its targets
    this little asks for no turn of the body (a quarter turn carries a standing body's
    wrists 0.3 m and its ankles 0.15). Compiled (``core.compiled.target_motion``)."""
    return compiled.target_motion(
        compiled.as_f64(poses), items.tidx, items.tpos, items.n_t, compiled.as_i64(rows)
    )


#: The floor's axes (x, z) of a position.
_XZ = np.array([0, 2], dtype=np.intp)


def fitted(poses: F64, items: _Items, rows: npt.NDArray[np.intp]) -> tuple[F64, F64]:
    """``poses [N, 21, 3]`` (world, +Y up; the starts of ``items[rows]``) each moved by
    the turn about the vertical and the shift across that best carry its targeted joints
    onto their targets (least squares over x and z; heights as they were), and each turn
    in radians, as :func:`turned` would turn it."""
    tidx, tpos = items.tidx[rows], items.tpos[rows]
    own = items.n_t[rows]  # each item's targets: its first columns (no pins: it searches)
    n = own[:, None].astype(np.float64)
    src = poses[np.arange(len(rows))[:, None, None], tidx[:, :, None], _XZ]  # [N, K, 2]
    dst = tpos[:, :, _XZ]
    sc = own_sum(src, own) / n  # centroids [N, 2]
    dc = own_sum(dst, own) / n
    a, b = src - sc[:, None], dst - dc[:, None]
    # turned(): x' = c x + s z, z' = -s x + c z; maximise sum(b . R a)
    cos = own_sum(a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1], own)
    sin = own_sum(a[..., 1] * b[..., 0] - a[..., 0] * b[..., 1], own)
    yaw = np.arctan2(sin, cos)
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    x, z = poses[:, :, 0] - sc[:, :1], poses[:, :, 2] - sc[:, 1:]
    out = poses.copy()
    out[:, :, 0] = c * x + s * z + dc[:, :1]
    out[:, :, 2] = -s * x + c * z + dc[:, 1:]
    return out, yaw


#: Items whose final answer the search already has: their indices and that answer.
Known = tuple[npt.NDArray[np.intp], BatchAnswer]


@dataclass(frozen=True)
class Turns:
    """What the search did to each item's start: its turn in whole degrees (0: none), and
    whether it was the fitted start (turned and moved across, :func:`fitted`)."""

    degrees: npt.NDArray[np.int64]  # [B]
    moved: npt.NDArray[np.bool_]  # [B]


def search(
    engine: Engine, items: _Items, reps: npt.NDArray[np.int64],
    solve: Solve, sel: npt.NDArray[np.intp] | None = None,
) -> tuple[_Items, Turns, Known | None]:  # fmt: skip
    """``items`` with the start of every searching item turned as the search chose, what
    it did to each (:class:`Turns`), and the answers it already has: a soft
    item's kept candidate was solved as the item asks, so it is not solved again.
    ``solve(items, reps)`` solves a batch (the engine's own path); ``sel``: the items
    that search (:func:`searching`), if the caller knows them.

    Scores are never negative and another candidate is kept only if it scores ``margin``
    below the unturned start, so an unturned score within the margin ends the search with
    the answer the full search gives. The items are solved unturned first and the other
    turns only for the items still open (fewer rows; a lone item: :func:`_search_one`).
    Each item's answer is the one it gets alone."""
    sel = searching(engine, items) if sel is None else sel
    degrees = np.zeros(len(items.poses), dtype=np.int64)
    moved = np.zeros(len(items.poses), dtype=np.bool_)
    if sel.size == 0:
        return items, Turns(degrees, moved), None
    t = engine.turn_search
    if sel.size == 1:  # one item searches (a lone edit's)
        return _search_one(engine, items, reps, sel, solve)
    first = np.arange(1)  # solved for every item
    scores, found, poses, yaws = _candidates(engine, items, reps, sel, first, solve)
    scores[0] -= t.margin
    best = np.argmin(scores, axis=0)  # ties: the first, the unturned start
    open_ = np.flatnonzero(scores[0] > 0.0)
    if open_.size:
        more, ans, turned_poses, open_yaws = _candidates(
            engine, items, reps, sel[open_], np.arange(1, t.candidates), solve
        )
        more = _kept_never_nan(more)
        if open_yaws is not None:  # (the fitted turns of the open items, by item)
            yaws = np.zeros(sel.size)
            yaws[open_] = open_yaws
        pick = np.argmin(np.vstack([scores[0, open_], more]), axis=0)
        turn = np.flatnonzero(pick > 0)
        best[open_[turn]] = pick[turn]
        row = (pick[turn] - 1) * open_.size + turn  # the kept candidate's row of `ans`
        found = found.with_items(open_[turn], ans.take(row))
        poses = np.concatenate([poses, turned_poses])
        best_rows = np.arange(sel.size)
        best_rows[open_[turn]] = sel.size + row
    else:
        best_rows = best * sel.size + np.arange(sel.size)
        found = found.take(best_rows)
    out = items.poses.copy()
    out[sel] = poses[best_rows]
    deg = np.rint(360.0 * best / t.yaws).astype(np.int64)
    fit = np.flatnonzero(best == t.yaws) if t.fit > 0.0 else np.zeros(0, np.intp)
    if fit.size and yaws is not None:  # the fitted start: its own turn
        deg[fit] = np.rint(np.degrees(yaws[fit])).astype(np.int64) % 360
        moved[sel[fit]] = True
    degrees[sel] = np.where(deg > 180, deg - 360, deg)
    mine = _as_asked(t, items, reps, sel)
    kept = found if mine.all() else found.take(np.flatnonzero(mine))  # (a lone item's: all)
    known = (sel[mine], kept) if mine.any() else None
    return dataclasses.replace(items, poses=out), Turns(degrees, moved), known


def _search_one(
    engine: Engine, items: _Items, reps: npt.NDArray[np.int64], sel: npt.NDArray[np.intp],
    solve: Solve,
) -> tuple[_Items, Turns, Known | None]:  # fmt: skip
    """:func:`search` where one item ``sel [1]`` searches (a lone edit's), as the batch's
    way searches each: its unturned start solved and scored first, and where that score is
    within the margin the search ends there (57 % of `bench.ab`'s searching 5-target
    edits: one candidate solved and scored, not 13); else the other candidates, the critic
    asked only of those whose targets alone do not already put them at or above the
    unturned score less the margin (a score is its targets' term plus the critic's, never
    negative, and the fitted start's bar: such a candidate is never kept). The same start,
    turn and answer as every candidate scored at once (each row's answer and score are
    its own: row for row the same bits)."""
    t = engine.turn_search
    scores, found, poses, _ = _candidates(engine, items, reps, sel, np.arange(1), solve)
    bar = float(scores[0, 0] - t.margin)  # (as search takes the margin off)
    if not bar > 0.0:  # within the margin (NaN: the first, as argmin)
        return _kept_one(engine, items, reps, int(sel[0]), 0, found, poses[0], None)
    steps = np.arange(1, t.candidates)
    more, ans, turned, yaws = _candidates(engine, items, reps, sel, steps, solve, bar)
    more = _kept_never_nan(more)
    k = int(np.argmin(np.concatenate([[bar], more[:, 0]])))  # ties: the unturned start
    if k == 0:
        return _kept_one(engine, items, reps, int(sel[0]), 0, found, poses[0], None)
    row = np.array([k - 1], dtype=np.intp)
    return _kept_one(engine, items, reps, int(sel[0]), k, ans.take(row), turned[k - 1], yaws)


def _as_asked(t: TurnSearch, items: _Items, reps: npt.NDArray[np.int64], rows: Any) -> Any:
    """Whether the kept candidates of ``items[rows]`` (indices, or one index) were solved as
    the items ask, so that their answers stand: soft, bone lengths kept; in the quick form
    (one pass, no mirror image) only where the item asks so."""
    mine = ~items.ex[rows] & items.keep[rows]
    if t.quick:
        mine = mine & (reps[rows] == 1) & ~items.mirror[rows]
    return mine


def _kept_never_nan(scores: F64) -> F64:
    """The turned candidates' ``scores`` with a NaN (a critic answering NaN for a finite
    pose: never seen) made infinite: such a candidate is never kept, by a batch's search or
    a lone edit's, which asks the critic only of candidates that may win (argmin would keep
    the first NaN, and the two ways could keep different ones). Finite scores as they are."""
    return np.where(np.isnan(scores), np.inf, scores)


def _kept_one(
    engine: Engine, items: _Items, reps: npt.NDArray[np.int64], b: int, k: int,
    found: BatchAnswer, start: F64, yaws: F64 | None,
) -> tuple[_Items, Turns, Known | None]:  # fmt: skip
    """:func:`search`'s end where only item ``b`` searched and kept candidate ``k`` (its
    answer ``found``, of one row, its start ``start [21, 3]``; the fitted start's turn
    ``yaws [1]``): the start, turn and known answer of the arrays' way, in scalars."""
    t, n = engine.turn_search, len(items.poses)
    degrees, moved = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.bool_)
    out = items.poses.copy()
    out[b] = start
    deg = round(360.0 * k / t.yaws)  # (half to even, as np.rint)
    if t.fit > 0.0 and k == t.yaws and yaws is not None:  # the fitted start: its own turn
        deg = int(np.rint(np.degrees(yaws)).astype(np.int64)[0]) % 360
        moved[b] = True
    degrees[b] = deg - 360 if deg > 180 else deg
    mine = bool(_as_asked(t, items, reps, b))
    known = (np.array([b], dtype=np.intp), found) if mine else None
    return dataclasses.replace(items, poses=out), Turns(degrees, moved), known


def _candidates(
    engine: Engine, items: _Items, reps: npt.NDArray[np.int64], sel: npt.NDArray[np.intp],
    steps: npt.NDArray[np.int64], solve: Solve, bar: float | None = None,
) -> tuple[F64, BatchAnswer, F64, F64 | None]:  # fmt: skip
    """Items ``sel`` solved soft from their starts turned by ``steps`` (of the search's
    ``yaws`` steps; 0 unturned) in one batch (with ``quick``: one pass, no mirror image),
    turn-major: the scores ``[turns, sel]``,
    the answers, the candidate starts (rows ``turn * len(sel) + item``) and the fitted
    start's turns ``[sel]`` (radians; None if it is not a candidate). ``bar`` (one item):
    the candidates whose targets' term (with the fitted start's bar) is at or above it
    score infinity, the critic not asked (:func:`_search_one`)."""
    y = engine.turn_search.yaws
    starts = items.poses[sel]
    turns = steps[steps < y]  # the fitted start (TurnSearch.fit), if asked, is step y
    if turns.size == 1 and turns[0] == 0:  # the unturned start alone, as it is
        parts = [starts.copy()]
    else:
        parts = [turned_by(starts, 2.0 * np.pi * turns / y).reshape(-1, *starts.shape[1:])]
    if turns.size > 1 and turns[0] == 0:  # the unturned start as it is
        parts[0][: len(sel)] = starts
    yaws = None
    if turns.size < steps.size:
        moved, yaws = fitted(starts, items, sel)
        parts.append(moved)
    poses = np.concatenate(parts) if len(parts) > 1 else parts[0]
    rep = np.tile(sel, len(steps))
    no = np.zeros(len(rep), dtype=np.bool_)  # (items.soft's, from these starts)
    soft = dataclasses.replace(items.take(rep), poses=poses, fab=no, keep=~no, ex=no)
    if engine.turn_search.quick:  # one pass, no mirror image
        soft = dataclasses.replace(soft, mirror=np.zeros(len(rep), dtype=np.bool_))
        ans = solve(soft, np.ones(len(rep), dtype=np.int64))
    else:
        ans = solve(soft, reps[rep])
    scale: F64 = np.tile(engine.body_scales(np.ascontiguousarray(starts)), len(steps))
    if bar is not None:  # one item: only the candidates that may score below the bar
        return _scored_below(engine, soft, ans, scale, steps, bar), ans, poses, yaws
    scores = _score(engine, soft, ans, scale).reshape(len(steps), -1)
    scores[steps == y] += engine.turn_search.fit  # the fitted start's bar (0 if not tried)
    return scores, ans, poses, yaws


def _scored_below(
    engine: Engine, soft: _Items, ans: BatchAnswer, scale: F64, steps: npt.NDArray[np.int64],
    bar: float,
) -> F64:  # fmt: skip
    """:func:`_candidates`' scores ``[steps, 1]`` of one item's candidates, infinity for
    each whose targets' term (:func:`_score`'s first, plus the fitted start's bar) is
    already at or above ``bar``: its score would be too (the critic's term is never
    negative), so it is never kept, and the critic is not asked of it. The others' scores
    are :func:`_score`'s, row for row the same bits."""
    t = engine.turn_search
    fit = steps == t.yaws
    least = own_sum(ans.errors, soft.n_t) / soft.n_t / scale  # (a score is never below it)
    least[fit] += t.fit
    live = np.flatnonzero(~(least >= bar))  # (NaN: scored)
    scores = np.full(len(steps), np.inf)
    if live.size:
        scores[live] = _scores(
            engine, ans.errors[live], ans.pose[live], soft.n_t[live], soft.floors[live],
            scale[live],
        )  # fmt: skip
        scores[live[fit[live]]] += t.fit
    return scores[:, None]


def _score(engine: Engine, soft: _Items, ans: BatchAnswer, scale: F64) -> F64:
    """Each candidate's score: the mean distance of its targets, plus ``plausibility``
    times its answer's distance to what the critic makes of it (never negative); both at
    the networks' body size, the answer over its body's ``scale`` (``Engine.scales_of``),
    as the margin and the fitted start's bar are: a character scaled up or down keeps the
    same start (a 1.9 m copy of make bench's B5 edits kept others, 65 mm from the reference
    answers, with scores in metres and the critic's completion networks, which read a
    body's size from its key points, asked at the character's own size)."""
    return _scores(engine, ans.errors, ans.pose, soft.n_t, soft.floors, scale)


def _scores(
    engine: Engine, errors: npt.NDArray[np.floating], pose: npt.NDArray[np.floating],
    n_t: npt.NDArray[np.int64], floors: F64, scale: F64,
) -> F64:  # fmt: skip
    """:func:`_score` of answers' ``errors`` and ``pose`` to items with ``n_t`` targets over
    ``floors`` (only what it reads: a few rows' without taking every array of theirs)."""
    score: F64 = own_sum(errors, n_t) / n_t / scale  # (its targets first)
    if engine.turn_search.plausibility > 0:  # how unlike a real body the answer is
        at = np.asarray(pose) / scale[:, None, None]
        score += engine.turn_search.plausibility * implausibility(engine, at, floors / scale)
    return score


def implausibility(engine: Engine, poses: npt.NDArray[np.floating], floors: F64) -> F64:
    """Mean per-joint distance (m) of world ``poses [N, 21, 3]`` (over ``floors [N]``) to
    what the search's critic makes of them: small for poses like the training ones."""
    world = np.asarray(poses, dtype=np.float64).copy()
    world[:, :, 1] -= floors[:, None]
    other: npt.NDArray[np.floating]
    if engine.turn_search.critic == "completion":
        # each answer facing +Z over its pelvis floor point (its own canonical frame, as the
        # solve's): the networks were trained at every yaw but answer each a little
        # differently, and the world's yaw must not pick the turn (it did: 12 of 60
        # random 5-8-target edits turned the world 37, 90 or 180 degrees kept another)
        world = _canonical(world)
        other = completion.implied_bodies(engine, world)
    else:
        other = engine.reconstruct(world)
    out: F64 = np.linalg.norm(other - world, axis=-1).mean(axis=-1)
    return out


#: The joints whose left-right differences give a body's facing (core.geometry's).
_LEFT = np.asarray([JOINT_INDEX[left] for left, _ in FACING_PAIRS], dtype=np.intp)
_RIGHT = np.asarray([JOINT_INDEX[right] for _, right in FACING_PAIRS], dtype=np.intp)


def _canonical(world: F64) -> F64:
    """``core.geometry.canonicalise`` of world poses ``[N, 21, 3]``: the same operations on
    the same arrays, bit for bit, less its generic steps (the guard against a pose with no
    facing only where one has none; ~15 us of a turn search's critic)."""
    across = (world[:, _LEFT] - world[:, _RIGHT]).sum(axis=-2)
    fx, fz = -across[..., 2], across[..., 0]
    norm = np.hypot(fx, fz)
    if (norm < 1e-12).any():  # a pose lying on its side: the reference's guard
        return np.asarray(canonicalise(world), dtype=np.float64)
    fx, fz = fx / norm, fz / norm
    rotation = np.zeros((len(world), 3, 3))  # (core.geometry._rotation_from_forward)
    rotation[:, 0, 0], rotation[:, 0, 2], rotation[:, 1, 1] = fz, fx, 1.0
    rotation[:, 2, 0], rotation[:, 2, 2] = -fx, fz
    translation = world[:, PELVIS].copy()
    translation[:, 1] = 0.0
    out: F64 = np.einsum("...ji,...kj->...ki", rotation, world - translation[:, None, :])
    return out


def mark(ans: BatchAnswer, turns: Turns) -> BatchAnswer:
    """``ans`` with ``turn <deg>`` (a fitted start: ``fit <deg>``) at the end of the solver
    path of every item the search turned or moved."""
    if not (turns.degrees.any() or turns.moved.any()):
        return ans
    keys = [
        (int(p), int(d), bool(m))
        for p, d, m in zip(
            ans.path_of.tolist(), turns.degrees.tolist(), turns.moved.tolist(), strict=True
        )
    ]
    distinct = list(dict.fromkeys(keys))
    paths = tuple(
        ans.paths[p] + ((f"fit {d}",) if m else (f"turn {d}",) if d else ())
        for p, d, m in distinct
    )  # fmt: skip
    index = {k: i for i, k in enumerate(distinct)}
    path_of = np.fromiter((index[k] for k in keys), np.int64, len(keys))
    return dataclasses.replace(ans, paths=paths, path_of=path_of)
