"""The data plane: validated requests in, poses out. onnxruntime + numpy, no torch.

A solve, for each item (world space in, world space out):

1. canonicalise the start pose like the dataset (pelvis floor projection to the origin,
   yaw to face +Z) and scale it to the size the networks know (``serving.body``);
2. ``method=neural``: encode, run the solver sequence that covers the target set
   (re-encoding with the solved targets pasted between solvers), decode; targets on joints
   no trained solver covers are then placed by a FABRIK polish holding the solved targets;
   ``method=fabrik``: full-body FABRIK from the start pose, no learned prior;
3. scale back, restore the INPUT pose's bone lengths (root outwards), optionally polish
   onto the targets exactly (``reach=exact``), and transform back to the world.

Batches run one onnxruntime call per stage for all items that share a solver sequence; a
single-solver sequence runs as one fused graph (encoder, solver and decoder composed at
load time), a composed one as encoder, solvers (with re-encoding) and decoder.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core import compiled, compiled_fabrik
from core.compiled_limbs import floor_group
from core.ends import active as active_chains
from core.geometry import canonical_transform, facing_transform
from core.manifest import Manifest, ModelEntry, Serving, load_manifest, serving_with
from core.rest import rest_lengths, rest_pose
from core.skeleton import (
    BONES,
    JOINT_INDEX,
    JOINT_NAMES,
    MIRROR,
    NUM_JOINTS,
    bone_lengths,
    flat_columns,
    mirror_key,
    set_key,
)
from service import completion, networks, retry, turns
from service.fabrik_set import fabrik_set
from service.fallback import prefer_fabrik
from service.lean import covering, fabrik_batch, lean_answer, lean_sequence, solve_lean, uncovered
from service.problems import (
    PELVIS,
    BatchAnswer,
    CompleteResult,
    SolveProblem,
    SolveResult,
    _Group,
    _groups,
    _Items,
    _per_item,
    others,
    solver_paths,
    stacked,
)
from service.runtime import ROW_BLOCK, Fused, Net, session_options

F64 = npt.NDArray[np.floating[Any]]
#: Metres by which the exact-reach fallback must beat the polish to be used.
_TIE = 1e-12
#: How far exact reach may lift a body whose pelvis FABRIK holds, as a share of its summed
#: bone lengths (``Engine._shifted_fallback``): 2.5 %, ~10 cm for an adult. The body rises
#: whole, feet too: the price of meeting a trunk target out of reach without pins (pin the
#: feet to keep them down: the pelvis is then free and the legs take the move).
LIFT = 0.025
#: A lone edit that searches its turn (``Engine._lean_single``): its items as asked and
#: travelled, and the searching ones.
Searches = tuple[_Items, _Items, npt.NDArray[np.intp]]


class Engine:
    """Loaded models and the solve / complete logic (stateless between calls)."""

    def __init__(
        self,
        models_dir: Path,
        *,
        threads: int = 1,
        composition_passes: int = 1,
        composition: str = "reencode",
        composition_projections: int = 1,
        fabrik_max_iterations: int = compiled_fabrik.MAX_ITERATIONS,
        serving: Mapping[str, Any] | None = None,
    ) -> None:
        self.models_dir = Path(models_dir)
        self.manifest: Manifest = load_manifest(self.models_dir, verify=True)
        #: the serving settings this engine runs with: the manifest's, with ``serving``'s
        #: overrides (a bench's, a test's, the service settings'; ``serving_with``)
        self.serving: Serving = serving_with(self.manifest.serving, serving)
        options = session_options(threads)

        def net(entry: ModelEntry) -> Net:
            return Net(self.models_dir / entry.file, entry, options)

        m = self.manifest
        self.encoder = net(m.autoencoder("encoder"))
        self.decoder = net(m.autoencoder("decoder"))
        self.solvers = {key: net(entry) for key, entry in m.solvers().items()}
        self.solver_joints = {key: np.asarray([JOINT_INDEX[j] for j in entry.joints], dtype=np.intp)
                              for key, entry in m.solvers().items()}  # fmt: skip
        #: each solver's targets as flat canvas columns ``[3k]`` (its fused graph's input)
        self.solver_columns = {key: flat_columns(j) for key, j in self.solver_joints.items()}
        #: how each solver's edit is asked of its mirror image (``serving.solve_mirror``),
        #: and the shipped graphs that ask both in one run (``trainer.mirror``)
        self.mirror_views = networks.mirror_views(self.solver_joints)
        #: (a set that is its own mirror image runs both views as rows of one graph: half
        #: the rows per block, as many inside)
        self.mirror_graphs = {
            key: Net(self.models_dir / entry.file, entry, options,
                     ROW_BLOCK // 2 if mirror_key(key) == key else ROW_BLOCK)
            for key, entry in m.mirrors().items()
        }  # fmt: skip
        self.completion = [net(entry) for entry in m.completion_levels()]
        #: completion level 1's key points (the turn search's critic's input, when it has one)
        base = m.completion_levels()[0].joints if m.completion_levels() else ()
        self.base_points = np.asarray([JOINT_INDEX[j] for j in base], dtype=np.intp)
        # each completion level's key points in its input order, and where each one's
        # mirror image sits in that order (the symmetry views of serving.completion_*)
        self.level_mirror = [
            [entry.joints.index(JOINT_NAMES[MIRROR[JOINT_INDEX[j]]]) for j in entry.joints]
            if self.serving.completion_mirror
            else list(range(len(entry.joints)))
            for entry in m.completion_levels()
        ]
        enc, dec = m.autoencoder("encoder"), m.autoencoder("decoder")
        # one graph per single-solver edit: shipped fused at export time (then it already
        # gives the served answer, delta included), else composed here at load time
        self.fused: dict[str, Net | Fused] = (
            {key: net(entry) for key, entry in m.fused().items()}
            if m.fused()
            else {
                key: Fused(enc, entry, dec, self.models_dir, options)
                for key, entry in m.solvers().items()
            }
        )
        ref = m.skeleton.reference_bone_lengths
        self.reference_lengths = np.asarray(
            [ref[JOINT_NAMES[c]] for c, _ in BONES], dtype=np.float64
        )
        # every serving setting is read from ``self.serving`` where it is used (one source
        # of truth: the manifest's block with its overrides); what is derived from them once:
        #: the mask ``[C]`` of chains the bone pass may keep where the networks put them
        #: (``serving.keep_ends``, ``serving.keep_elbows``; ``core.ends.active``; which of
        #: them an edit keeps: ``core.ends.kept_chains``)
        self.chain_mask = active_chains(self.serving.keep_ends, self.serving.keep_elbows)
        #: the turn search of many-target edits (``serving.turn_*``, :mod:`service.turns`)
        self.turn_search = turns.TurnSearch.of(self.serving)
        known = np.asarray(m.skeleton.skeletons, dtype=np.float64)  # [C, 20]
        self._shape_totals = known.sum(axis=-1)
        self._shapes = known / self._shape_totals[:, None]
        self._shapes_c = np.ascontiguousarray(self._shapes, dtype=np.float64)
        self._reference_total = float(np.sum(self.reference_lengths))
        #: how the compiled kernels size a body (``compiled.scale_item``'s arguments, as
        #: :meth:`scales_of`): the training skeletons' shapes and totals, the mode, the total
        self.body_args: tuple[compiled.F64, compiled.F64, bool, float] = (
            self._shapes_c, self._shape_totals, self.serving.body == "total_length",
            self._reference_total,
        )  # fmt: skip
        compiled.warm()  # compile the kernels, or load them from numba's cache
        compiled_fabrik.warm()
        if composition not in ("reencode", "sequential"):
            raise ValueError(f"unknown composition strategy {composition!r}")
        self._plans: dict[tuple[bytes, bytes], tuple[str, ...]] = {}
        self._covering: dict[tuple[bytes, bytes], tuple[str, ...] | None] = {}  # lean.covering
        self._delta_steps: dict[
            tuple[str, ...], list[tuple[str, npt.NDArray[np.intp], npt.NDArray[np.intp] | None]]
        ] = {}
        self.composition_passes = composition_passes
        self.composition = composition
        self.projections = composition_projections
        self.fabrik_max_iterations = fabrik_max_iterations
        self.version = m.version

    def inert_settings(self) -> tuple[tuple[str, ...], str]:
        """The composition settings set away from their default that change nothing here,
        and why: delta models (``serving.delta``) run a composed sequence once, so the
        latent chain's cycles (``composition_passes``) and closing rounds
        (``composition_projections``) have nothing to act on; the paper's plain chain
        (``composition="sequential"``) has no closing rounds (:mod:`service.networks`)."""
        chain: tuple[tuple[str, int], ...]
        if self.serving.delta:
            chain = (("composition_passes", self.composition_passes),
                     ("composition_projections", self.projections))  # fmt: skip
            why = "the models answer in deltas (serving.delta): a composed sequence runs once"
        elif self.composition == "sequential":
            chain, why = (("composition_projections", self.projections),), "the plain chain"
        else:
            return (), ""
        return tuple(name for name, value in chain if value != 1), why

    def scales_of(self, lengths: F64) -> F64:
        """How much bigger each character ``[..., 20]`` is than the body size the networks
        know. Networks trained on many random bodies (``serving.body = total_length``) see
        every character at the reference skeleton's total bone length; older ones see it at
        the size of the training skeleton whose proportions it matches best. Either way a
        1.9 m or a 1.2 m copy of a character is solved exactly as that character."""
        total = np.sum(lengths, axis=-1, keepdims=True)
        if self.serving.body == "total_length":
            return np.asarray(total[..., 0] / np.sum(self.reference_lengths), dtype=np.float64)
        shape = lengths / total
        distance = np.linalg.norm(shape[..., None, :] - self._shapes, axis=-1)  # [..., C]
        nearest = np.argmin(distance, axis=-1)
        return np.asarray(total[..., 0] / self._shape_totals[nearest], dtype=np.float64)

    # -- solver choice -------------------------------------------------------------------
    def plan(self, joints: frozenset[str], weights: dict[str, float]) -> list[str]:
        """Solver keys covering ``joints`` in the order they run (see ``_cover``)."""
        order = _cover(joints, frozenset(self.solvers))
        # heavier targets run later, so the last word is theirs; ties keep cover order
        return sorted(order, key=lambda k: max(weights[j] for j in k.split("+")))

    # -- solving ---------------------------------------------------------------------------
    def solve(self, problems: Sequence[SolveProblem]) -> list[SolveResult]:
        """Solve a batch of validated problems: :meth:`solve_arrays` on their padded
        arrays, then one :class:`SolveResult` per item."""
        n = len(problems)
        if n == 0:
            return []
        if n == 1:  # one edit (the interactive case): the lean path, if it qualifies
            lean = self._lean_single(problems[0])
            if isinstance(lean, SolveResult):
                return [lean]
            if lean is not None:  # it searches its turn: from the items it was looked at as
                return [self.solve_searching(problems[0], lean)]
        ans = self.solve_arrays(
            **stacked(problems),
            passes=np.fromiter((self.passes_of(p) for p in problems), np.int64, n),
            carry=np.fromiter((self.carry_of(p) for p in problems), np.float64, n),
            mirror=np.fromiter((self.mirror_of(p) for p in problems), np.bool_, n),
        )
        return [self._result(p, ans, b) for b, p in enumerate(problems)]

    def _lean_single(self, p: SolveProblem, one: bool = False) -> SolveResult | Searches | None:
        """One edit on the lean path (:mod:`service.lean`) straight from its problem, if
        it qualifies: what :meth:`solve_arrays` gives it, without its option arrays;
        if it searches its turn (:mod:`service.turns`), its items (:meth:`_items_of`) and
        the searching ones (:meth:`_searched` solves it from them); None if it takes the
        general path for another reason (``one``: or needs more than one solver)."""
        tidx = compiled.as_i64(p.target_idx)
        weights = compiled.as_f64(p.weights)
        passes, seq, look = 1, None, None
        if p.method != "fabrik":
            pinned = p.n_targets < len(tidx)
            if self.turn_search.searches(p.method, p.n_targets, pinned, p.turn_search):
                look = self._items_of(p)
                sel = turns.searching(self, look[1])
                if sel.size:  # its targets say the body turned (or no gate: it searches)
                    return (*look, sel)
            if not p.preserve_bone_lengths:
                return None  # the bone pass left out: the general path
            passes, seq = self.passes_of(p), covering(self, tidx, weights)
            if seq is None or passes < 1 or (one and len(seq) > 1):
                return None
        asked, items = self._items_of(p) if look is None else look
        ans = retry.last_steps(self, items, lean_answer(self, items, passes, seq))
        return self._result(p, prefer_fabrik(self, asked, ans, self._solve_items), 0)

    def solve_lone(self, p: SolveProblem) -> SolveResult | Searches | None:
        """``solve([p])[0]`` if ``p`` takes the lean path with one solver (a few network
        runs: the routes run it on the event loop); if it searches its turn, its items as
        looked at, for :meth:`solve_searching` (in a worker; its items made once); None
        for anything else (composed solvers, the general path): :meth:`solve` in a worker."""
        return self._lean_single(p, one=True)

    def solve_searching(self, p: SolveProblem, searches: Searches) -> SolveResult:
        """``solve([p])[0]`` of an edit that searches its turn, from its items as
        :meth:`solve_lone` (or :meth:`solve`) looked at them."""
        return self._result(p, self._searched(p, *searches), 0)

    def _searched(
        self, p: SolveProblem, asked: _Items, items: _Items, sel: npt.NDArray[np.intp]
    ) -> BatchAnswer:
        """:meth:`solve_arrays`' answer to ``p`` alone, which searches its turn: from its
        items as :meth:`_lean_single` made them (``asked``, ``items`` travelled, ``sel``
        the searching ones), not made again from :func:`stacked` ``([p])`` (the same
        arrays: ``_Items.of_problem``)."""
        reps = np.array([self.passes_of(p)], dtype=np.int64)
        if int(reps[0]) < 1:
            raise ValueError(f"passes must be at least 1, got {int(reps[0])}")
        return self._searched_items(asked, items, reps, sel)

    def _searched_items(
        self, asked: _Items, items: _Items, reps: npt.NDArray[np.int64],
        sel: npt.NDArray[np.intp] | None = None,
    ) -> BatchAnswer:  # fmt: skip
        """:meth:`solve_arrays` from its normalised items (``asked``, and ``items``
        travelled) on: the turn search (``sel``: the items that search, if known), the
        solve, the last steps, the critic's FABRIK."""
        items, turned, known = turns.search(self, items, reps, self._solve_items, sel)
        ans = turns.mark(
            retry.last_steps(self, items, self._solve_rest(items, reps, known)), turned
        )
        return prefer_fabrik(self, asked, ans, self._solve_items)

    def _items_of(self, p: SolveProblem) -> tuple[_Items, _Items]:
        """One problem as items: as asked, and with its start moved across as the serving
        settings move it before a solve (``_Items.travelled``)."""
        asked = _Items.of_problem(p, self.carry_of(p), self.mirror_of(p))
        return asked, asked.travelled(
            self.serving.pelvis_travel, self.serving.reach_travel, self.turn_search.min_targets
        )

    def passes_of(self, p: SolveProblem) -> int:
        """The neural passes ``p`` asks for (``serving.passes`` unless it says)."""
        return self.serving.passes if p.passes is None else p.passes

    def carry_of(self, p: SolveProblem) -> float:
        """The carry below targets ``p`` asks for (``carry`` unless it says)."""
        return self.serving.carry if p.carry is None else p.carry

    def mirror_of(self, p: SolveProblem) -> bool:
        """Whether ``p`` has its mirror image solved too (``serving.solve_mirror`` unless
        it says)."""
        return self.serving.solve_mirror if p.mirror is None else p.mirror

    @staticmethod
    def _result(p: SolveProblem, ans: BatchAnswer, b: int) -> SolveResult:
        e = ans.errors[b, : p.n_targets]
        return SolveResult(
            pose=ans.pose[b], errors=e, reached=e <= p.tolerance,
            pin_errors=ans.errors[b, p.n_targets : len(p.target_idx)],
            max_bone_error=float(ans.max_bone_error[b]),
            solvers=list(ans.paths[ans.path_of[b]]), iterations=int(ans.iterations[b]),
        )  # fmt: skip

    def solve_arrays(
        self,
        poses: npt.ArrayLike,
        target_idx: npt.ArrayLike,
        target_pos: npt.ArrayLike,
        *,
        counts: npt.ArrayLike | None = None,
        n_targets: npt.ArrayLike | None = None,
        weights: npt.ArrayLike | None = None,
        fabrik: npt.ArrayLike = False,
        preserve_bone_lengths: npt.ArrayLike = True,
        exact: npt.ArrayLike = False,
        tolerance: npt.ArrayLike = 1e-3,
        floor: npt.ArrayLike = 0.0,
        passes: npt.ArrayLike | None = None,
        carry: npt.ArrayLike | None = None,
        turn_search: npt.ArrayLike = True,
        mirror: npt.ArrayLike | None = None,
        soft_ik: npt.ArrayLike = 0.0,
    ) -> BatchAnswer:
        """Solve a batch given as arrays (validated like :class:`SolveProblem`), no
        per-item objects: ``poses [B, 21, 3]`` world; ``target_idx [B, K]`` joints (per
        item its first ``counts[b]`` entries: targets, then pins from ``n_targets[b]``
        on; the rest is padding), ``target_pos [B, K, 3]`` world, ``weights [B, K]``.
        Per-item options are ``[B]`` arrays or scalars: ``fabrik`` (method), ``exact``
        (reach), ``preserve_bone_lengths``, ``tolerance`` (m), ``floor`` (world y),
        ``passes`` (neural solves; default ``serving.passes``), ``carry`` (the
        branch below each target, 0-1, :mod:`core.carry`; default the engine's ``carry``),
        ``turn_search`` (False: never search the turn, :mod:`service.turns`), ``mirror``
        (also solve the mirror image; default ``serving.solve_mirror``), ``soft_ik`` (m:
        kept limbs ease into full stretch, ``core.ends.soft_reach``; 0: none).

        Geometry runs in compiled kernels (:mod:`core.compiled`), one call per stage for
        the whole batch; items that share a solver sequence share one onnxruntime run per
        stage; FABRIK and the polish run per target set (:mod:`core.compiled_fabrik`).
        Every item is computed alone: its answer does not depend on the batch.

        A neural item with ``passes`` = p > 1 is first solved p - 1 times in soft reach
        with its bone lengths restored, each pass starting from the previous answer; the
        last pass is the one asked for. At refinement pass k (from 0) the items with
        p > k + 1 take part, the others keep their pose: an item with p passes gets what
        an engine built with ``serving={"passes": p}`` gives it. FABRIK items ignore ``passes``."""
        items = _Items.of_arrays(
            poses,
            target_idx,
            target_pos,
            counts=counts,
            n_targets=n_targets,
            weights=weights,
            fabrik=fabrik,
            preserve_bone_lengths=preserve_bone_lengths,
            exact=exact,
            tolerance=tolerance,
            floor=floor,
            carry=self.serving.carry if carry is None else carry,
            turn_search=turn_search,
            mirror=self.serving.solve_mirror if mirror is None else mirror,
            soft_ik=soft_ik,
        )
        n, fab = items.poses.shape[0], items.fab
        reps = _per_item(self.serving.passes if passes is None else passes, n, np.int64)
        if n and int(reps.min()) < 1:
            raise ValueError(f"passes must be at least 1, got {int(reps.min())}")
        reps = np.where(fab, 1, reps)  # FABRIK items: one solve (and not the caller's array)
        asked = items
        items = items.travelled(
            self.serving.pelvis_travel, self.serving.reach_travel, self.turn_search.min_targets
        )
        return self._searched_items(asked, items, reps)

    def _solve_rest(
        self, items: _Items, reps: npt.NDArray[np.int64], known: turns.Known | None
    ) -> BatchAnswer:
        """:meth:`_solve_items` of the items whose answer the turn search does not have."""
        if known is None:
            return self._solve_items(items, reps)
        n = items.poses.shape[0]
        rest = others(n, known[0])
        if rest.size == 0 and n == 1:  # a lone item's: the answer as it is
            return known[1]
        if rest.size == 0:
            return BatchAnswer.scatter(n, [known])
        part = self._solve_items(items.take(rest), reps[rest])
        return BatchAnswer.scatter(n, [(rest, part), known])

    def collar_items(self, items: _Items) -> npt.NDArray[np.bool_]:
        """Which items turn a kept wrist's collar (``serving.keep_collar``) ``[B]``: edits of
        few targets asked in soft reach. Exact reach has its FABRIK polish (its soft passes
        before go without); edits of many targets search the body's turn instead, whose
        soft candidates a collar turn would make look nearer than they are."""
        if items.n_t.shape[0] == 1:  # one edit (the interactive case): without ufuncs
            one = bool(items.asked_soft[0]) and int(items.n_t[0]) < self.turn_search.min_targets
            return np.array([one and bool(self.serving.keep_collar)], dtype=np.bool_)
        few = items.n_t < self.turn_search.min_targets
        return items.asked_soft & few & self.serving.keep_collar

    def pelvis_holds(self, items: _Items) -> npt.NDArray[np.float64]:
        """How much of the networks' pelvis move each item drops (``serving.keep_pelvis``,
        m; 0: none) ``[B]``: edits of few targets (the turn search's many turn the body
        about its pelvis) none of which, pins included, is on the pelvis itself."""
        if self.serving.keep_pelvis == 0.0:  # off (the shipped models): nothing to work out
            return np.zeros(items.tidx.shape[0])
        few = items.n_t < self.turn_search.min_targets
        cols = np.arange(items.tidx.shape[1])[None, :] < items.cnt[:, None]
        on_pelvis = ((items.tidx == PELVIS) & cols).any(axis=1)
        return np.where(few & ~on_pelvis, self.serving.keep_pelvis, 0.0)

    def pairs_of(self, body: F64) -> compiled.F64:
        """``serving.keep_pairs``' reference (``compiled.unscale``): the callers' starts
        ``body``, not a pass's (docs/kinematics.md, "A dragged trunk"); none where off."""
        return compiled.as_f64(body) if self.serving.keep_pairs else compiled.NO_PAIRS

    def body_scales(self, poses: compiled.F64) -> compiled.F64:
        """:meth:`scales_of` of world poses ``[B, 21, 3]``, compiled (``compiled.body_scales``:
        the scale ``compiled.prepare`` gives the networks, bit for bit)."""
        return compiled.body_scales(poses, *self.body_args)

    def _solve_items(self, items: _Items, reps: npt.NDArray[np.int64]) -> BatchAnswer:
        """:meth:`solve_arrays` of normalised items with their passes ``reps``."""
        pose_a = items.poses
        n = pose_a.shape[0]
        # a batch all alike (service.lean): FABRIK on one target set, or neural with every
        # target on a solver
        lean = None if fabrik_batch(items) else lean_sequence(self, items, reps)
        if lean is not None or fabrik_batch(items):
            return lean_answer(self, items, int(reps[0]), lean)
        rounds = int(reps.max()) - 1 if n else 0
        if rounds == 0:
            return self._solve_once(items)
        current = pose_a.copy()
        for k in range(rounds):
            now = np.flatnonzero(reps > k + 1)  # these items take part in pass k
            soft = items.soft(now, current)
            lean = lean_sequence(self, soft, np.ones(len(now), dtype=np.int64))
            if lean is None:
                current[now] = self._solve_once(soft).pose
            else:  # e.g. exact reach's soft passes before its last (service.lean)
                current[now] = solve_lean(self, soft, 1, lean)[0]
        return self._solve_once(
            dataclasses.replace(items, poses=current), origin=pose_a, moved=reps > 1
        )

    def _solve_once(
        self,
        batch: _Items,
        origin: F64 | None = None,
        moved: npt.NDArray[np.bool_] | None = None,
    ) -> BatchAnswer:
        """One pass of :meth:`solve_arrays`. ``origin`` ``[B, 21, 3]``: the caller's own
        start poses of the items ``moved`` by earlier passes; exact reach falls back to
        plain FABRIK from there, not from the previous pass's answer (whose pelvis the
        network may have moved out of a target's reach)."""
        pose_a, tidx, cnt, n_t, w = batch.poses, batch.tidx, batch.cnt, batch.n_t, batch.w
        fab, keep, ex, tols, floors = batch.fab, batch.keep, batch.ex, batch.tols, batch.floors
        n = pose_a.shape[0]
        neural = np.ascontiguousarray(~fab)
        tpos, (canon, facing, trans, lengths, scales, tcan, x, canvas) = self._prepare(
            pose_a, batch, neural
        )
        groups = _groups(cnt, n_t, tidx, w)
        iterations = np.zeros(n, dtype=np.int64)
        suffix = np.zeros(n, dtype=np.int64)  # 0: none, 1: fabrik-polish, 2: fabrik-fallback
        seq_of = np.full(n, -1, dtype=np.int64)  # index into `sequences`; -1: FABRIK
        sequences: list[tuple[str, ...]] = []
        out = canon
        if neural.any():
            seq_ids: dict[tuple[str, ...], int] = {}
            for g in groups:
                mine = g.members[neural[g.members]]
                if mine.size:
                    seq = self._plan_for(g.idx, g.weights)
                    seq_of[mine] = seq_ids.setdefault(seq, len(seq_ids))
            sequences = list(seq_ids)
            bone = keep | ex
            collar, hold = self.collar_items(batch), self.pelvis_holds(batch)
            if len(sequences) == 1 and neural.all():  # the common case: no gathers
                decoded = networks.answer(self, x, canvas, sequences[0], batch.mirror)
                out = compiled.unscale(
                    decoded, scales, canon, lengths, bone, tidx, cnt, batch.carry, self.chain_mask,
                    self.serving.keep_ease, collar, hold, self.pairs_of(batch.body),
                    self.serving.bend_side, batch.soft_ik, self.serving.keep_feet,
                )  # fmt: skip
            else:
                items = np.flatnonzero(neural)
                decoded = np.empty((n, 3 * NUM_JOINTS), dtype=np.float32)
                for s, seq in enumerate(sequences):
                    sel = np.flatnonzero(seq_of == s)
                    decoded[sel] = networks.answer(
                        self, x[sel], canvas[sel], seq, batch.mirror[sel]
                    )
                out = canon.copy()
                out[items] = compiled.unscale(
                    decoded[items], scales[items], canon[items], lengths[items], bone[items],
                    tidx[items], cnt[items], batch.carry[items], self.chain_mask,
                    self.serving.keep_ease, collar[items], hold[items],
                    self.pairs_of(batch.body[items]), self.serving.bend_side, batch.soft_ik[items],
                    self.serving.keep_feet,
                )  # fmt: skip
        start = canon
        if origin is not None and moved is not None and moved.any():
            start = canon.copy()  # the caller's start poses in this pass's canonical frame
            start[moved] = self.origin_in(origin[moved], facing[moved], trans[moved], floors[moved])
        for g in groups:
            self._finish_group(g, fab, ex, seq_of, sequences, start, out, lengths, tcan,
                               tols, iterations, suffix, batch.body)  # fmt: skip
        world, errors, bone_err = compiled.finish(
            out, facing, trans, floors, tidx, tpos, cnt, lengths
        )
        paths, path_of = solver_paths(seq_of, suffix, sequences)
        return BatchAnswer(world, errors, bone_err, iterations, paths, path_of)

    def _prepare(
        self, poses: compiled.F64, items: _Items, neural: npt.NDArray[np.bool_],
        tpos: compiled.F64 | None = None,
    ) -> tuple[compiled.F64, compiled.Prepared]:  # fmt: skip
        """``compiled.prepare`` of ``poses`` with the targets, counts and floors of
        ``items`` and this engine's body mapping; first the targets with the floor taken
        off (the networks know a floor at y = 0), which ``compiled.finish`` takes too
        (``tpos``: those, already taken off by an earlier call)."""
        if tpos is None:
            tpos = items.tpos.copy()
            tpos[:, :, 1] -= items.floors[:, None]
        return tpos, compiled.prepare(
            poses, items.floors, items.tidx, tpos, items.cnt, neural, *self.body_args
        )

    def _fabrik(
        self, polish: bool, starts: F64, lengths: F64, goals: F64, tols: F64,
        idx: npt.NDArray[np.int64], weights: F64, hold: npt.NDArray[np.bool_],
        reference: F64 | None = None,
    ) -> tuple[compiled.F64, npt.NDArray[np.int64], compiled.F64]:  # fmt: skip
        """:func:`service.fabrik_set.fabrik_set` at this engine's iteration cap."""
        return fabrik_set(polish, starts, lengths, goals, tols, idx, weights, hold,
                          self.fabrik_max_iterations, reference)  # fmt: skip

    def exact_fallback(
        self, polished: tuple[compiled.F64, npt.NDArray[np.int64], compiled.F64], start: F64,
        lengths: F64, goal: F64, tols: F64, idx: npt.NDArray[np.int64], weights: F64,
        pins: npt.NDArray[np.bool_], before: compiled.F64,
    ) -> tuple[compiled.F64, npt.NDArray[np.int64], npt.NDArray[np.bool_]]:  # fmt: skip
        """Exact reach's last word on a batch of one target set: ``polished`` (poses,
        iterations, errors of the FABRIK polish from the networks' answer), and for every
        item it left beyond its tolerance, plain FABRIK from its ``start`` (the caller's
        start, canonical), kept where it ends nearer. Ties (equal to rounding: e.g. both
        at the stretch a pin allows) keep the polish, whose pose is nearer the network's.
        Returns poses (:meth:`planted` from ``before``, the poses polished, where the polish
        was kept; where the fallback's was, only legs sunk below the floor raised), iterations
        (FABRIK's added where kept) and which kept it."""
        pose, its, errs = polished
        fell = np.zeros(len(pose), dtype=np.bool_)
        missed = np.flatnonzero(np.any(errs > tols[:, None], axis=1))
        if missed.size:
            alt, alt_its, alt_errs = self._fabrik(
                False, start[missed], lengths[missed], goal[missed], tols[missed], idx, weights,
                pins,
            )  # fmt: skip
            _keep_nearer(missed, (alt, alt_its, alt_errs), pose, its, errs, fell)
            if not pins.any():
                self._shifted_fallback(pose, its, errs, fell, lengths, goal, tols, idx, weights,
                                       pins)  # fmt: skip
        if self.serving.keep_feet:  # (where the fallback's answer was kept, no plant:
            for sel, plant in ((~fell, True), (fell, False)):  # it did not polish before)
                if sel.any():
                    part = compiled.as_f64(pose[sel])
                    floor_group(part, compiled.as_f64(before[sel]), idx, plant)
                    pose[sel] = part
        return pose, its, fell

    def planted(
        self, pose: compiled.F64, before: compiled.F64, idx: npt.NDArray[np.int64]
    ) -> compiled.F64:
        """``pose [M, 21, 3]``, a FABRIK polish of ``before`` (one target set, joints ``idx``),
        with ``serving.keep_feet`` its legs no target names put back at the height they had
        there, in place, as far as they stretch (``core.compiled_limbs.floor_item``'s
        ``plant``)."""
        if self.serving.keep_feet:
            floor_group(pose, before, idx, True)
        return pose

    def _shifted_fallback(
        self, pose: F64, its: npt.NDArray[np.int64], errs: F64, fell: npt.NDArray[np.bool_],
        lengths: F64, goal: F64, tols: F64, idx: npt.NDArray[np.int64], weights: F64,
        pins: npt.NDArray[np.bool_],
    ) -> None:  # fmt: skip
        """Exact reach of a set without pins (``pins`` all false) whose targets all hang
        from one branch of the pelvis (a collar, the neck, the spine, one limb): FABRIK
        holds the pelvis there, so a target beyond that branch's reach stays short by the
        whole excess (3 cm above a standing body's neck: missed by 3 cm, where with both
        ankles pinned the pelvis is free and it was reached). Each item still short is
        moved whole by its targets' weighted mean miss, polished again, and kept where that
        ends nearer without losing a target it had reached or sinking a joint below the
        floor (canonical y 0) or its lowest joint: across as far as it takes (as
        ``serving.reach_travel`` moves a soft answer's start), up by at most ``LIFT`` of
        the body's summed bone lengths (feet included: the body is lifted whole, ~10 cm at
        most for an adult, so a hand 3 m up is approached, not reached by a body in the
        air). In place."""
        short = np.flatnonzero(np.any(errs > tols[:, None], axis=1))
        if not short.size:
            return
        w = weights / np.sum(weights)
        shift = np.einsum("k,nkc->nc", w, goal[short] - pose[short][:, idx])
        low = pose[short][..., 1].min(axis=1)
        shift[:, 1] = np.clip(shift[:, 1], -np.maximum(low, 0.0), LIFT * lengths[short].sum(axis=1))
        alt_pose, alt_its, alt_errs = self._fabrik(
            True, pose[short] + shift[:, None, :], lengths[short], goal[short], tols[short],
            idx, weights, pins,
        )  # fmt: skip
        # never a target it had reached lost, nor a joint sunk below where the floor (or
        # the answer's own lowest joint) was: the polish after the move knows no floor
        tol = tols[short, None]
        lost = ((errs[short] <= tol) & (alt_errs > tol)).any(axis=1)
        sunk = alt_pose[..., 1].min(axis=1) < np.minimum(low, 0.0) - _TIE
        ok = ~lost & ~sunk
        _keep_nearer(short[ok], (alt_pose[ok], alt_its[ok], alt_errs[ok]), pose, its, errs, fell)

    @staticmethod
    def origin_in(origin: F64, facing: F64, trans: F64, floors: F64) -> F64:
        """World poses ``origin [B, 21, 3]`` (over ``floors``) in the canonical frames of a
        pass (its ``facing``, ``trans``): where exact reach's fallback starts."""
        lifted = origin.copy()
        lifted[..., 1] -= floors[:, None]
        out: F64 = facing_transform(facing[:, 0], facing[:, 1], trans).to_canonical(lifted)
        return out

    def _plan_for(self, idx: npt.NDArray[np.int64], weights: F64) -> tuple[str, ...]:
        """``plan`` of a target set, memoised on its (joints, weights) bytes."""
        key = (idx.tobytes(), weights.tobytes())
        plan = self._plans.get(key)
        if plan is None:
            names = [JOINT_NAMES[j] for j in idx.tolist()]
            plan = tuple(
                self.plan(frozenset(names), dict(zip(names, weights.tolist(), strict=True)))
            )
            if len(self._plans) >= 65536:  # bounded: forget everything, start again
                self._plans.clear()
            self._plans[key] = plan
        return plan

    def _finish_group(
        self, g: _Group, fab: npt.NDArray[np.bool_], ex: npt.NDArray[np.bool_],
        seq_of: npt.NDArray[np.int64], sequences: list[tuple[str, ...]], canon: F64, out: F64,
        lengths: F64, tcan: F64, tols: F64, iterations: npt.NDArray[np.int64],
        suffix: npt.NDArray[np.int64], body: F64,
    ) -> None:  # fmt: skip
        """FABRIK items, and the polish of neural items that need one, of one target set
        (``out``, ``iterations``, ``suffix`` are written in place; ``body``: the items'
        ``_Items.body``, whose hips' width a polish keeps)."""
        k = len(g.idx)
        pinned = np.arange(k) >= g.n_targets

        def run(
            polish: bool, sel: npt.NDArray[np.intp], start: F64, goal: F64
        ) -> tuple[compiled.F64, npt.NDArray[np.int64], compiled.F64]:
            return self._fabrik(polish, start, lengths[sel], goal, tols[sel], g.idx, g.weights,
                                pinned, body[sel] if polish else None)  # fmt: skip

        members = g.members
        sel = members[fab[members]]
        if sel.size:
            out[sel], iterations[sel], _ = run(False, sel, canon[sel], tcan[sel, :k])
        neural = members[~fab[members]]
        if not neural.size:
            return
        sel = neural[ex[neural]]
        if sel.size:  # exact reach: the polish, or plain FABRIK where that reaches closer
            goal = tcan[sel, :k]
            pose, its, fell = self.exact_fallback(
                run(True, sel, out[sel], goal), canon[sel], lengths[sel], goal, tols[sel],
                g.idx, g.weights, pinned, compiled.as_f64(out[sel]),
            )  # fmt: skip
            suffix[sel] = np.where(fell, 2, 1)
            out[sel], iterations[sel] = pose, its
        sel = neural[~ex[neural]]
        if not sel.size:
            return
        free = uncovered(sequences[int(seq_of[neural[0]])], tuple(g.idx.tolist()))
        if free.any() or pinned.any():
            # pins and targets no solver covers go exactly where asked, by a FABRIK
            # polish that holds the neurally solved targets where they are
            place = (free | pinned)[None, :, None]
            goal = np.where(place, tcan[sel, :k], out[sel][:, g.idx])
            pose, iterations[sel], _ = run(True, sel, out[sel], goal)
            out[sel], suffix[sel] = self.planted(pose, compiled.as_f64(out[sel]), g.idx), 1

    def reconstruct(self, world: F64) -> F64:
        """The autoencoder's round trip of world poses ``[B, 21, 3]`` through the same body
        mapping as a solve (canonical frame, size): how well the pose space holds a body."""
        world = np.asarray(world, dtype=np.float64)
        frame = canonical_transform(world)
        canon = frame.to_canonical(world)
        scales = self.scales_of(bone_lengths(world))[:, None, None]
        x = (canon / scales).reshape(len(world), -1).astype(np.float32)
        out = self.decoder(self.encoder(x)).astype(np.float64).reshape(len(world), NUM_JOINTS, 3)
        return np.asarray(frame.to_world(out * scales))

    # -- key-point completion (service.completion) --------------------------------------
    def complete(
        self,
        keypoints: dict[str, F64],
        given_lengths: dict[str, float] | None,
        tolerance: float = 1e-3,
        floor: float = 0.0,
    ) -> CompleteResult:
        """A whole pose from key points: :func:`service.completion.complete`."""
        return completion.complete(self, keypoints, given_lengths, tolerance, floor)

    def warmup(self) -> None:
        """A real solve on the reference rest pose; raises if anything is off."""
        rest = rest_pose()
        rest = rest * (np.sum(self.reference_lengths) / np.sum(rest_lengths()))
        wrist = JOINT_INDEX["left_wrist"]
        problem = SolveProblem(
            pose=rest,
            target_idx=np.asarray([wrist], dtype=np.intp),
            target_pos=rest[[wrist]] + np.array([[0.05, 0.1, 0.05]]),
            weights=np.ones(1),
            n_targets=1,
        )
        for method in ("neural", "fabrik"):
            (result,) = self.solve([SolveProblem(**{**problem.__dict__, "method": method})])
            if not np.all(np.isfinite(result.pose)) or result.max_bone_error > 1e-5:
                raise RuntimeError(f"warm-up {method} solve gave an invalid pose")


def _keep_nearer(
    rows: npt.NDArray[np.intp], alt: tuple[compiled.F64, npt.NDArray[np.int64], compiled.F64],
    pose: F64, its: npt.NDArray[np.int64], errs: F64, fell: npt.NDArray[np.bool_],
) -> None:  # fmt: skip
    """Exact reach's fallbacks: where ``alt`` (poses, iterations, errors of ``rows``) ends
    nearer its farthest target than the answer so far, by more than rounding, it is the
    answer (its iterations added, marked fallen back). Ties keep the answer so far."""
    alt_pose, alt_its, alt_errs = alt
    better = np.max(alt_errs, axis=1) < np.max(errs[rows], axis=1) - _TIE
    take = rows[better]
    pose[take], its[take] = alt_pose[better], its[take] + alt_its[better]
    errs[take] = alt_errs[better]
    fell[take] = True


@lru_cache(maxsize=4096)
def _cover(joints: frozenset[str], available: frozenset[str]) -> tuple[str, ...]:
    """Trained sets covering ``joints``: the exact set if trained, else greedily the
    largest trained subsets of the target set until no trained set adds a joint (ties: sets
    of centre joints first, then by name with a right joint read as its left one, so that
    an edit and its mirror image run mirror-image sequences: by name alone, ``pelvis`` then
    ``right_knee`` against ``left_knee`` then ``pelvis`` answered mirror images 28 cm apart,
    an audit, 2026-12-07). Joints no trained set contains stay uncovered (FABRIK's)."""
    key = set_key(joints)
    if key in available:
        return (key,)
    left = {k: set_key([j.replace("right_", "left_") for j in k.split("+")]) for k in available}
    candidates = sorted(
        (k for k in available if set(k.split("+")) <= joints),
        key=lambda k: (-len(k.split("+")), "_" in k, left[k], k),
    )
    chosen: list[str] = []
    covered: set[str] = set()
    for k in candidates:
        if (members := set(k.split("+"))) - covered:
            chosen.append(k)
            covered |= members
    return tuple(chosen)
