"""What a solve takes and gives: validated problems, results, and a batch's arrays.

The engine (:mod:`service.engine`) works on these; the HTTP layer builds
:class:`SolveProblem` from validated requests and answers from :class:`SolveResult` /
:class:`BatchAnswer`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import numpy.typing as npt

from core import compiled
from core.ends import SOFT_IK_MAX
from core.skeleton import JOINT_INDEX, NUM_JOINTS, ROOT

F64 = npt.NDArray[np.floating[Any]]
PELVIS = JOINT_INDEX[ROOT]


# --------------------------------------------------------------------------------------
# Validated problems
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SolveProblem:
    pose: F64  # [21, 3] world
    target_idx: npt.NDArray[np.intp]  # [K] targets, then pins
    target_pos: F64  # [K, 3] world
    weights: F64  # [K]
    n_targets: int  # the first n entries are user targets; the rest are pins
    method: str = "neural"
    preserve_bone_lengths: bool = True
    reach: str = "soft"
    tolerance: float = 1e-3
    floor: float = 0.0  # world y of the ground under the character
    passes: int | None = None  # neural solves (None: the engine's ``serving.passes``)
    carry: float | None = None  # the branch below targets, 0-1 (None: the engine's)
    turn_search: bool | None = None  # search the turn (service.turns; None: if the models do)
    mirror: bool | None = None  # also solve the mirror image (None: if the models do)
    soft_ik: float = 0.0  # kept limbs ease into full stretch over this many m (core.ends)
    #: the names the client gave the targets, then the pins (a character's own), where
    #: they are not the canonical ones: the character answers report them beside
    names: tuple[str, ...] | None = None


#: (:class:`SolveResult`, :class:`BatchAnswer` and :class:`_Items` are made afresh per solve,
#: several times on some paths, and never assigned to: plain dataclasses, as a frozen one's
#: ``__init__`` sets each field through ``object.__setattr__``, ~0.1 us a field, 2.5 us of
#: a lone 2-target solve's 95 for the three.)
@dataclass
class SolveResult:
    pose: F64  # [21, 3] world
    errors: F64  # [K] for user targets (pins excluded)
    reached: npt.NDArray[np.bool_]
    pin_errors: F64  # [P] distance of each pinned joint from where it was
    max_bone_error: float
    solvers: list[str]
    iterations: int


@dataclass
class BatchAnswer:
    """Answers of :meth:`Engine.solve_arrays` (B items, K target columns)."""

    pose: F64  # [B, 21, 3] world
    errors: F64  # [B, K] distance of each targeted joint (targets, then pins; 0 padding)
    max_bone_error: F64  # [B] relative, against the input pose's bone lengths
    iterations: npt.NDArray[np.int64]  # [B] FABRIK / polish iterations
    paths: tuple[tuple[str, ...], ...]  # the distinct solver paths of the batch
    path_of: npt.NDArray[np.int64]  # [B] index into ``paths``

    def take(self, rows: npt.NDArray[np.intp]) -> BatchAnswer:
        """The answers of items ``rows``, in that order (only their solver paths)."""
        if len(self.paths) == 1:  # one path (the common case): nothing to renumber
            used, path_of = np.zeros(1, np.int64), np.zeros(len(rows), np.int64)
        else:
            used, path_of = np.unique(self.path_of[rows], return_inverse=True)
        return BatchAnswer(
            self.pose[rows], self.errors[rows], self.max_bone_error[rows],
            self.iterations[rows], tuple(self.paths[i] for i in used.tolist()),
            path_of.astype(np.int64).reshape(-1),
        )  # fmt: skip

    @staticmethod
    def scatter(n: int, parts: Sequence[tuple[npt.NDArray[np.intp], BatchAnswer]]) -> BatchAnswer:
        """One answer for ``n`` items from ``parts``, each the answers of items ``sel``
        (together every item once); solver paths renumbered in part order."""
        k = max(a.errors.shape[1] for _, a in parts)
        pose, errors = np.empty((n, NUM_JOINTS, 3)), np.zeros((n, k))
        bone, its = np.empty(n), np.empty(n, dtype=np.int64)
        path_of = np.empty(n, dtype=np.int64)
        index: dict[tuple[str, ...], int] = {}
        for sel, a in parts:
            pose[sel], bone[sel], its[sel] = a.pose, a.max_bone_error, a.iterations
            errors[sel, : a.errors.shape[1]] = a.errors
            path_of[sel] = renumber(index, a)
        return BatchAnswer(pose, errors, bone, its, tuple(index), path_of)

    def with_items(self, sel: npt.NDArray[np.intp], other: BatchAnswer) -> BatchAnswer:
        """These answers with items ``sel`` replaced by ``other``'s (one per ``sel``)."""
        rest = others(len(self.pose), sel)
        return BatchAnswer.scatter(len(self.pose), [(rest, self.take(rest)), (sel, other)])


#: Steps of a solver path that are not trained solvers: FABRIK, its polish, exact reach's
#: fallback and the critic's choice (``fabrik-*``), the pins' polish, the turn search's turn
#: or fitted start (``service.engine``, ``service.fallback``, ``service.pins``,
#: ``service.turns``).
PATH_STEPS = ("fabrik", "pin-polish", "turn ", "fit ")


def trained_solvers(path: Sequence[str]) -> list[str]:
    """The trained solvers' keys of a solver path, in order (its other steps left out)."""
    return [s for s in path if not s.startswith(PATH_STEPS)]


def solver_paths(
    seq_of: npt.NDArray[np.int64], suffix: npt.NDArray[np.int64],
    sequences: list[tuple[str, ...]],
) -> tuple[tuple[tuple[str, ...], ...], npt.NDArray[np.int64]]:  # fmt: skip
    """Each item's solver path as an index into the distinct paths of the batch: ``seq_of``
    the item's solver sequence in ``sequences`` (-1: FABRIK), ``suffix`` what ran after it
    (0: nothing, 1: the FABRIK polish, 2: exact reach's FABRIK fallback)."""
    if len(seq_of) == 1:  # one item: no array arithmetic
        code = (int(seq_of[0]) + 1) * 3 + int(suffix[0])
        return (solver_path(code, sequences),), np.zeros(1, dtype=np.int64)
    codes = (seq_of + 1) * 3 + suffix
    if bool((codes == codes[0]).all()):
        distinct, path_of = codes[:1], np.zeros(len(codes), dtype=np.int64)
    else:
        distinct, path_of = np.unique(codes, return_inverse=True)
    paths = tuple(solver_path(c, sequences) for c in distinct.tolist())
    return paths, path_of.astype(np.int64).reshape(-1)


#: What ran after a solver sequence, by :func:`solver_paths`' suffix code.
_ENDS: tuple[tuple[str, ...], ...] = ((), ("fabrik-polish",), ("fabrik-fallback",))


def solver_path(code: int, sequences: Sequence[tuple[str, ...]]) -> tuple[str, ...]:
    """The solver path of code ``(sequence index + 1) * 3 + suffix`` (:func:`solver_paths`;
    below 3: FABRIK)."""
    return ("fabrik",) if code < 3 else (*sequences[code // 3 - 1], *_ENDS[code % 3])


def others(n: int, sel: npt.NDArray[np.intp]) -> npt.NDArray[np.intp]:
    """The items of ``n`` not in ``sel``, in order."""
    keep = np.ones(n, dtype=np.bool_)
    keep[sel] = False
    return np.flatnonzero(keep)


def renumber(index: dict[tuple[str, ...], int], ans: BatchAnswer) -> npt.NDArray[np.int64]:
    """``ans.path_of`` as indices into ``index`` (distinct solver paths in order), which
    takes in the paths of ``ans`` it did not have."""
    remap = np.array([index.setdefault(path, len(index)) for path in ans.paths], np.int64)
    out: npt.NDArray[np.int64] = remap[ans.path_of]
    return out


@dataclass
class _Items:
    """A batch's inputs as contiguous per-item arrays (what :meth:`Engine.solve_arrays`
    takes, normalised once): B items, K target columns, positions in world space."""

    poses: compiled.F64  # [B, 21, 3]
    tidx: npt.NDArray[np.int64]  # [B, K]
    tpos: compiled.F64  # [B, K, 3]
    cnt: npt.NDArray[np.int64]  # [B] columns in use (targets, then pins)
    n_t: npt.NDArray[np.int64]  # [B] user targets
    w: compiled.F64  # [B, K]
    fab: npt.NDArray[np.bool_]  # [B] method=fabrik
    keep: npt.NDArray[np.bool_]  # [B] preserve_bone_lengths
    ex: npt.NDArray[np.bool_]  # [B] reach=exact
    tols: compiled.F64  # [B]
    floors: compiled.F64  # [B]
    carry: compiled.F64  # [B] the branch below the targets (core.carry), 0-1
    turn: npt.NDArray[np.bool_]  # [B] may search its turn (service.turns)
    #: [B] the caller asked for soft reach: ``~ex`` as asked, kept through the soft passes
    #: before an exact one (which serving.keep_collar leaves alone)
    asked_soft: npt.NDArray[np.bool_]
    #: [B] each neural pass also solves the mirror image (``serving.solve_mirror``)
    mirror: npt.NDArray[np.bool_]
    #: [B] kept limbs ease into full stretch over this many metres (0: none; the
    #: request's ``soft_ik``, ``core.ends.soft_reach``)
    soft_ik: compiled.F64
    #: [B, 21, 3] the callers' own starts, as ``poses`` were before a pass, the turn search
    #: or a move across replaced them: the body whose hips' width a polish keeps
    #: (``service.fabrik_set``)
    body: compiled.F64

    @staticmethod
    def of_problem(p: SolveProblem, carry: float, mirror: bool) -> _Items:
        """One problem as a batch of one (``carry``, ``mirror``: what it asks for), as
        :meth:`of_arrays` makes it from :func:`stacked` ``([p])``."""
        if not (0.0 <= carry <= 1.0 and 0.0 <= p.soft_ik <= SOFT_IK_MAX):  # as of_arrays
            raise ValueError(f"carry must be in [0, 1], soft_ik in [0, {SOFT_IK_MAX}] m")
        tidx, k = compiled.as_i64(p.target_idx), len(p.target_idx)
        # each per-item option a one-element view of one array per dtype (an array each
        # cost 1-2 us: a third of a lean solve's Python before this)
        ints = np.array([k, p.n_targets], dtype=np.int64)
        reals = np.array([p.tolerance, p.floor, carry, p.soft_ik], dtype=np.float64)
        flags = np.array(
            [p.method == "fabrik", p.preserve_bone_lengths, p.reach == "exact",
             p.turn_search is not False, p.reach != "exact", mirror], dtype=np.bool_,
        )  # fmt: skip
        pose = compiled.as_f64(p.pose)
        return _Items(
            poses=pose[None], tidx=tidx[None],
            tpos=compiled.as_f64(p.target_pos).reshape(1, k, 3), cnt=ints[0:1], n_t=ints[1:2],
            w=compiled.as_f64(p.weights)[None], fab=flags[0:1], keep=flags[1:2], ex=flags[2:3],
            tols=reals[0:1], floors=reals[1:2], carry=reals[2:3], turn=flags[3:4],
            asked_soft=flags[4:5], mirror=flags[5:6], soft_ik=reals[3:4], body=pose[None],
        )  # fmt: skip

    @staticmethod
    def of_arrays(
        poses: npt.ArrayLike, target_idx: npt.ArrayLike, target_pos: npt.ArrayLike, *,
        counts: npt.ArrayLike | None, n_targets: npt.ArrayLike | None,
        weights: npt.ArrayLike | None, fabrik: npt.ArrayLike,
        preserve_bone_lengths: npt.ArrayLike, exact: npt.ArrayLike, tolerance: npt.ArrayLike,
        floor: npt.ArrayLike, carry: npt.ArrayLike, turn_search: npt.ArrayLike,
        mirror: npt.ArrayLike, soft_ik: npt.ArrayLike = 0.0,
    ) -> _Items:  # fmt: skip
        """A batch given as arrays (:meth:`Engine.solve_arrays`' arguments, per-item
        options as ``[B]`` arrays or scalars) as contiguous per-item arrays."""
        pose_a = compiled.as_f64(poses)
        n = pose_a.shape[0]
        tidx = compiled.as_i64(target_idx).reshape(n, -1)
        k_max = tidx.shape[1]
        cnt = _per_item(k_max if counts is None else counts, n, np.int64)
        ex = _per_item(exact, n, np.bool_)
        items = _Items(
            poses=pose_a, tidx=tidx,
            tpos=np.array(target_pos, dtype=np.float64).reshape(n, k_max, 3), cnt=cnt,
            n_t=cnt if n_targets is None else _per_item(n_targets, n, np.int64),
            w=_per_item(1.0 if weights is None else weights, n, np.float64, k_max),
            fab=_per_item(fabrik, n, np.bool_),
            keep=_per_item(preserve_bone_lengths, n, np.bool_), ex=ex,
            tols=_per_item(tolerance, n, np.float64), floors=_per_item(floor, n, np.float64),
            carry=_per_item(carry, n, np.float64), turn=_per_item(turn_search, n, np.bool_),
            asked_soft=~ex, mirror=_per_item(mirror, n, np.bool_),
            soft_ik=_per_item(soft_ik, n, np.float64), body=pose_a,
        )  # fmt: skip
        if n and not bool(np.all((items.carry >= 0.0) & (items.carry <= 1.0))):
            raise ValueError("carry must be in [0, 1]")
        if n and not bool(np.all((items.soft_ik >= 0.0) & (items.soft_ik <= SOFT_IK_MAX))):
            raise ValueError(f"soft_ik must be in [0, {SOFT_IK_MAX}] m")
        return items

    def targets(self) -> npt.NDArray[np.bool_]:
        """``[B, K]``: which columns of each item are its user targets (not pins, padding)."""
        out: npt.NDArray[np.bool_] = np.arange(self.tidx.shape[1])[None, :] < self.n_t[:, None]
        return out

    def farthest(self, errors: F64) -> F64:
        """``[B]``: each item's largest distance ``errors [B, K]`` to its user targets."""
        out: F64 = np.where(self.targets(), errors, 0.0).max(axis=1)
        return out

    def neural_unpinned(self) -> npt.NDArray[np.bool_]:
        """``[B]``: neural items with no pins (every column in use is a user target), the
        ones whose start the engine may move or turn before solving."""
        out: npt.NDArray[np.bool_] = ~self.fab & (self.cnt == self.n_t)
        return out

    def neural_unpinned_one(self, b: int) -> bool:
        """:meth:`neural_unpinned` of item ``b`` alone, in scalars (a lone edit's)."""
        return not self.fab[b] and int(self.cnt[b]) == int(self.n_t[b])

    def travelled(self, pelvis: bool, reach: bool, few: int) -> _Items:
        """These items with their starts moved across first, as the serving settings say
        (:func:`core.compiled.travel`; only neural starts with no pins move): onto a pelvis
        target (``pelvis``: ``serving.pelvis_travel``; horizontally, so that the start's
        pelvis lies over that target; the height is the networks' to change), then, in
        edits of fewer than ``few`` targets, towards a target out of reach (``reach``:
        ``serving.reach_travel``; a body steps towards what it cannot reach, as FABRIK's
        root moves), by the farthest such target's excess across (x, z) over its chain,
        so that the networks see it within reach."""
        if not (pelvis or reach):
            return self
        poses, moved = compiled.travel(
            self.poses, self.tidx, self.tpos, self.cnt, self.n_t, self.fab, pelvis, reach, few
        )
        return dataclasses.replace(self, poses=poses) if moved else self

    def take(self, rows: npt.NDArray[np.intp]) -> _Items:
        """Items ``rows``, as they are."""
        return _Items(*(getattr(self, f.name)[rows] for f in fields(self)))

    def soft(self, sel: npt.NDArray[np.intp], poses: compiled.F64) -> _Items:
        """Items ``sel`` from ``poses`` as a refinement pass solves them: neural, soft
        reach, bone lengths restored."""
        no = np.zeros(len(sel), dtype=np.bool_)
        return dataclasses.replace(self.take(sel), poses=poses[sel], fab=no, keep=~no, ex=no)


#: :meth:`service.engine.Engine._solve_items`: items and their passes to their answers (what
#: the turn search and the critic's FABRIK solve with).
Solve = Callable[[_Items, npt.NDArray[np.int64]], BatchAnswer]


@dataclass(frozen=True)
class _Group:
    """Items of a batch with one target set: joints, weights and number of user targets."""

    idx: npt.NDArray[np.int64]  # [k]
    weights: F64  # [k]
    n_targets: int
    members: npt.NDArray[np.intp]


def _groups(
    cnt: npt.NDArray[np.int64], n_t: npt.NDArray[np.int64], tidx: npt.NDArray[np.int64], w: F64
) -> list[_Group]:
    """The batch split by target set (joints, weights, targets vs pins), vectorised."""
    n, k = tidx.shape
    if n == 1:
        c = int(cnt[0])
        return [_Group(tidx[0, :c].copy(), w[0, :c].copy(), int(n_t[0]), np.zeros(1, np.intp))]
    valid = np.arange(k)[None, :] < cnt[:, None]
    key = np.concatenate(
        [cnt[:, None], n_t[:, None], np.where(valid, tidx, -1),
         np.ascontiguousarray(np.where(valid, w, 0.0)).view(np.int64)],
        axis=1,
    )  # fmt: skip
    if n == 1 or bool((key == key[0]).all()):
        firsts, members = [0], [np.arange(n)]
    else:
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
        order = np.argsort(inverse, kind="stable")
        bounds = np.cumsum(np.bincount(inverse, minlength=len(first)))[:-1]
        firsts, members = first.tolist(), np.split(order, bounds)
    out = []
    for f, m in zip(firsts, members, strict=True):
        c = int(cnt[f])
        out.append(_Group(tidx[f, :c].copy(), w[f, :c].copy(), int(n_t[f]), m))
    return out


def stacked(problems: Sequence[SolveProblem]) -> dict[str, Any]:
    """Validated problems as :meth:`Engine.solve_arrays`' arguments: targets and pins
    padded to the longest item's columns, every per-item option a ``[B]`` array but
    ``passes``, ``carry`` and ``mirror``, whose defaults are the engine's (it adds them)."""
    n = len(problems)
    counts = np.fromiter((len(p.target_idx) for p in problems), np.int64, n)
    k_max = int(counts.max())
    tidx = np.zeros((n, k_max), dtype=np.int64)
    tpos = np.zeros((n, k_max, 3))
    weights = np.ones((n, k_max))
    for b, p in enumerate(problems):
        k = len(p.target_idx)
        tidx[b, :k] = p.target_idx
        tpos[b, :k] = p.target_pos
        weights[b, :k] = p.weights
    return dict(
        poses=np.stack([p.pose for p in problems]), target_idx=tidx, target_pos=tpos,
        counts=counts, n_targets=np.fromiter((p.n_targets for p in problems), np.int64, n),
        weights=weights,
        fabrik=np.fromiter((p.method == "fabrik" for p in problems), np.bool_, n),
        preserve_bone_lengths=np.fromiter(
            (p.preserve_bone_lengths for p in problems), np.bool_, n
        ),
        exact=np.fromiter((p.reach == "exact" for p in problems), np.bool_, n),
        tolerance=np.fromiter((p.tolerance for p in problems), np.float64, n),
        floor=np.fromiter((p.floor for p in problems), np.float64, n),
        turn_search=np.fromiter((p.turn_search is not False for p in problems), np.bool_, n),
        soft_ik=np.fromiter((p.soft_ik for p in problems), np.float64, n),
    )  # fmt: skip


def _per_item(value: npt.ArrayLike, n: int, dtype: type[np.generic], k: int | None = None) -> Any:
    """A per-item option as a contiguous, writable ``[n]`` (or ``[n, k]``) array; scalars
    repeat. Writable: a read-only array (what ``np.broadcast_to`` gives) would be another
    type to the compiled kernels, compiled on first use instead of at start."""
    shape = (n,) if k is None else (n, k)
    if isinstance(value, (bool, int, float)) or np.ndim(value) == 0:
        return np.full(shape, value, dtype=dtype)
    given = np.asarray(value, dtype=dtype)
    if given.shape == shape:  # the common case, a fraction of broadcasting's cost
        return given.copy()  # C order, writable, and never the caller's array
    wide = np.broadcast_to(given, shape)
    return np.require(wide, requirements=["C_CONTIGUOUS", "WRITEABLE"])


@dataclass(frozen=True)
class CompleteResult:
    pose: F64
    errors: F64
    reached: npt.NDArray[np.bool_]
    levels: list[int]
    floor: float  # the floor the networks saw (the request's, or where it was clamped)
    scale_warning: str | None = None  # the body's size not the request's (``scale_warning``)
    up_warning: str | None = None  # key points not upright along +Y (``up_warning``)
