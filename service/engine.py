"""The data plane: validated requests in, poses out. onnxruntime + numpy, no torch.

A solve, for each item (world space in, world space out):

1. canonicalise the start pose like the dataset (pelvis floor projection to the origin,
   yaw to face +Z) and scale it to the size of the training skeleton whose proportions
   it matches best, so the networks see a body they know;
2. ``method=neural``: encode, run the solver sequence that covers the target set
   (re-encoding with the solved targets pasted between solvers), decode; targets on
   joints that no trained
   solver covers are then placed by a FABRIK polish that holds the solved targets;
   ``method=fabrik``: full-body FABRIK from the start pose, no learned prior;
3. scale back, restore the INPUT pose's bone lengths (root outwards), optionally polish
   onto the targets exactly (``reach=exact``), and transform back to the world.

Batches run one onnxruntime call per stage for all items that share a solver sequence; a
single-solver sequence runs as one fused graph (encoder, solver and decoder composed at
load time), a composed one as encoder, solvers (with re-encoding) and decoder.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core import kinematics
from core.geometry import canonical_transform
from core.manifest import Manifest, ModelEntry, load_manifest
from core.rest import rest_lengths, rest_pose
from core.skeleton import (
    BONES,
    JOINT_INDEX,
    JOINT_NAMES,
    NUM_JOINTS,
    bone_lengths,
    set_key,
)
from service.errors import InvalidRequest
from service.runtime import Fused, Net, session_options

F64 = npt.NDArray[np.floating[Any]]


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


@dataclass(frozen=True)
class SolveResult:
    pose: F64  # [21, 3] world
    errors: F64  # [K] for user targets (pins excluded)
    reached: npt.NDArray[np.bool_]
    pin_errors: F64  # [P] distance of each pinned joint from where it was
    max_bone_error: float
    solvers: list[str]
    iterations: int


@dataclass(frozen=True)
class CompleteResult:
    pose: F64
    errors: F64
    reached: npt.NDArray[np.bool_]
    levels: list[int]


# --------------------------------------------------------------------------------------
# Engine
# --------------------------------------------------------------------------------------
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
        fabrik_max_iterations: int = 64,
    ) -> None:
        self.models_dir = Path(models_dir)
        self.manifest: Manifest = load_manifest(self.models_dir, verify=True)
        options = session_options(threads)

        def net(entry: ModelEntry) -> Net:
            return Net(self.models_dir / entry.file, entry, options)

        m = self.manifest
        self.encoder = net(m.autoencoder("encoder"))
        self.decoder = net(m.autoencoder("decoder"))
        self.solvers = {key: net(entry) for key, entry in m.solvers().items()}
        self.solver_joints = {
            key: np.asarray([JOINT_INDEX[j] for j in entry.joints], dtype=np.intp)
            for key, entry in m.solvers().items()
        }
        self.completion = [net(entry) for entry in m.completion_levels()]
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
        self.body = m.serving.body
        self.delta = m.serving.delta
        known = np.asarray(m.skeleton.skeletons, dtype=np.float64)  # [C, 20]
        self._shape_totals = known.sum(axis=-1)
        self._shapes = known / self._shape_totals[:, None]
        if composition not in ("reencode", "sequential"):
            raise ValueError(f"unknown composition strategy {composition!r}")
        self._plans: dict[tuple[bytes, bytes], tuple[str, ...]] = {}
        self.passes = composition_passes
        self.composition = composition
        self.projections = composition_projections
        self.fabrik_max_iterations = fabrik_max_iterations
        self.version = m.version

    def scales_of(self, lengths: F64) -> F64:
        """How much bigger each character ``[..., 20]`` is than the body size the networks
        know. Networks trained on many random bodies (``serving.body = total_length``) see
        every character at the reference skeleton's total bone length; older ones see it at
        the size of the training skeleton whose proportions it matches best. Either way a
        1.9 m or a 1.2 m copy of a character is solved exactly as that character."""
        total = np.sum(lengths, axis=-1, keepdims=True)
        if self.body == "total_length":
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

    def _plan_of(self, p: SolveProblem) -> tuple[str, ...]:
        """``plan`` for a problem, memoised on its (joints, weights) bytes."""
        key = (p.target_idx.tobytes(), p.weights.tobytes())
        plan = self._plans.get(key)
        if plan is None:
            names = [JOINT_NAMES[j] for j in p.target_idx.tolist()]
            weights = dict(zip(names, p.weights.tolist(), strict=True))
            plan = tuple(self.plan(frozenset(names), weights))
            if len(self._plans) >= 65536:  # bounded: forget everything, start again
                self._plans.clear()
            self._plans[key] = plan
        return plan

    # -- solving ---------------------------------------------------------------------------
    def solve(self, problems: Sequence[SolveProblem]) -> list[SolveResult]:
        """Solve a batch. Geometry, the bone pass and the answers are vectorised over the
        batch; neural items share one ORT run per stage; only FABRIK runs per item."""
        n = len(problems)
        if n == 0:
            return []
        poses = np.stack([p.pose for p in problems])  # [B, 21, 3] world
        floors = np.asarray([p.floor for p in problems])
        up = np.zeros((n, 1, 3))
        up[:, 0, 1] = floors  # the networks know a floor at y = 0
        poses = poses - up
        frame = canonical_transform(poses)
        canon = frame.to_canonical(poses)
        lengths = bone_lengths(poses)  # [B, 20]
        scales = self.scales_of(lengths)  # [B]
        # ragged targets as padded arrays: [B, K] joints, [B, K, 3] world positions
        k_max = max(len(p.target_idx) for p in problems)
        tidx = np.zeros((n, k_max), dtype=np.intp)
        tpos = np.zeros((n, k_max, 3))
        for b, p in enumerate(problems):
            k = len(p.target_idx)
            tidx[b, :k] = p.target_idx
            tpos[b, :k] = p.target_pos
            tidx[b, k:] = p.target_idx[0]  # padding repeats a real target
            tpos[b, k:] = p.target_pos[0]
        tpos = tpos - up
        tcan = frame.to_canonical(tpos)  # [B, K, 3]

        out = canon.copy()
        paths: list[list[str]] = [["fabrik"] for _ in range(n)]
        neural = np.flatnonzero([p.method == "neural" for p in problems])
        if neural.size:
            solved, neural_paths = self._neural(
                problems, neural, canon, lengths, tidx, tcan, scales
            )
            out[neural] = solved
            for row, item in enumerate(neural):
                paths[int(item)] = neural_paths[row]
            bone = [
                int(i)
                for i in neural
                if problems[int(i)].preserve_bone_lengths or problems[int(i)].reach == "exact"
            ]
            if bone:
                sel = np.asarray(bone, dtype=np.intp)
                out[sel] = kinematics.bone_pass(out[sel], lengths[sel], reference=canon[sel])

        iterations = np.zeros(n, dtype=np.int64)
        for b, p in enumerate(problems):
            k = len(p.target_idx)
            if p.method == "fabrik":
                res = kinematics.fabrik(
                    canon[b], lengths[b], p.target_idx, tcan[b, :k], weights=p.weights,
                    tolerance=p.tolerance, max_iterations=self.fabrik_max_iterations,
                    pinned=np.arange(k) >= p.n_targets,
                )  # fmt: skip
                out[b], iterations[b] = res.positions, res.iterations
                continue
            covered = {j for key in paths[b] for j in key.split("+")}
            uncovered = np.asarray([JOINT_NAMES[j] not in covered for j in p.target_idx])
            pinned = np.arange(k) >= p.n_targets
            if p.reach != "exact" and not uncovered.any() and not pinned.any():
                continue
            if p.reach == "exact":
                pose, its, path = self._exact(p, canon[b], out[b], lengths[b], tcan[b, :k])
                out[b], iterations[b], paths[b] = pose, its, [*paths[b], *path]
            else:  # pins and targets no solver covers go exactly where asked, by a
                # FABRIK polish that holds the neurally solved targets where they are
                exact = (uncovered | pinned)[:, None]
                goal = np.where(exact, tcan[b, :k], out[b][p.target_idx])
                res = kinematics.polish(
                    out[b], lengths[b], p.target_idx, goal, weights=p.weights,
                    tolerance=p.tolerance, max_iterations=self.fabrik_max_iterations,
                    pinned=pinned,
                )  # fmt: skip
                out[b], iterations[b] = res.positions, res.iterations
                paths[b] = [*paths[b], "fabrik-polish"]

        world = frame.to_world(out)
        rows = np.arange(n)[:, None]
        errors = np.linalg.norm(world[rows, tidx] - tpos, axis=-1)  # [B, K]
        world = world + up
        bone_err = np.max(np.abs(bone_lengths(world) / lengths - 1.0), axis=-1)
        results = []
        for b, p in enumerate(problems):
            e = errors[b, : p.n_targets]
            pin_e = errors[b, p.n_targets : len(p.target_idx)]
            results.append(
                SolveResult(
                    pose=world[b],
                    errors=e,
                    reached=e <= p.tolerance,
                    pin_errors=pin_e,
                    max_bone_error=float(bone_err[b]),
                    solvers=paths[b],
                    iterations=int(iterations[b]),
                )
            )
        return results

    def _neural(
        self,
        problems: Sequence[SolveProblem],
        items: npt.NDArray[np.intp],
        canon: F64,
        lengths: F64,
        tidx: npt.NDArray[np.intp],
        tcan: F64,
        scales: F64,
    ) -> tuple[F64, list[list[str]]]:
        """Encode, run each item's solver sequence, decode: one ORT run per stage."""
        m = len(items)
        x = (canon[items] / scales[items, None, None]).reshape(m, -1).astype(np.float32)
        # every item's targets on a [21, 3] canvas, so a solver gathers its joints at once
        canvas = np.zeros((m, NUM_JOINTS, 3), dtype=np.float32)
        rows = np.arange(m)[:, None]
        canvas[rows, tidx[items]] = (
            self._within_reach(canon[items], lengths[items], tidx[items], tcan[items])
            / (scales[items, None, None])
        )
        groups: dict[tuple[str, ...], list[int]] = {}
        plans: list[list[str]] = []
        for row, b in enumerate(items.tolist()):
            plan = self._plan_of(problems[b])
            plans.append(list(plan))
            groups.setdefault(plan, []).append(row)
        decoded = np.empty((m, 3 * NUM_JOINTS), dtype=np.float32)
        for sequence, members in groups.items():
            sel = np.asarray(members, dtype=np.intp)
            if self.delta:  # shipped fused graphs give the (anchored) delta answer
                decoded[sel] = self._delta(x[sel], canvas[sel], sequence)
            elif len(sequence) == 1:  # one fused run: encode, solve, decode
                key = sequence[0]
                targets = canvas[sel][:, self.solver_joints[key]].reshape(len(sel), -1)
                decoded[sel] = self.fused[key](x[sel], targets)
            else:  # none (only uncovered joints) or a composed sequence
                z = self.encoder(x[sel])
                if sequence:
                    z = self._compose(z, canvas[sel], sequence)
                decoded[sel] = self.decoder(z)
        out = decoded.astype(np.float64).reshape(m, NUM_JOINTS, 3)
        return out * scales[items, None, None], plans

    @staticmethod
    def _within_reach(start: F64, lengths: F64, tidx: npt.NDArray[np.intp], targets: F64) -> F64:
        """Targets ``[M, K, 3]`` as the networks see them: one beyond the body's reach (its
        chain from the pelvis plus a leg's length of root travel) is pulled back along
        the line from the pelvis, so a target 10 km away asks for a full stretch towards it
        rather than for a pose the networks never saw. Reach errors are still measured
        against the real target."""
        chain = lengths @ _CHAIN.T  # [M, 21]: pelvis -> joint along the skeleton
        radius = np.take_along_axis(chain, tidx, axis=1) + chain[:, [_LEG]]
        offset = targets - start[:, :1]
        dist = np.linalg.norm(offset, axis=-1)
        factor = np.minimum(1.0, radius / np.maximum(dist, 1e-12))
        return np.asarray(start[:, :1] + offset * factor[..., None])

    def _delta(
        self, x: npt.NDArray[np.float32], canvas: npt.NDArray[np.float32], sequence: tuple[str, ...]
    ) -> npt.NDArray[np.float32]:
        """Delta answers (``serving.delta``): each solver's fused graph moves the CURRENT
        pose by what it changes in the decoded pose (anchored or not, as exported), so the
        autoencoder's own error on the start pose never reaches the answer. Between solvers
        the targets solved so far are pasted onto the pose (``composition="reencode"``)."""
        pose = x.copy()
        flat = canvas.reshape(len(x), -1)
        done: list[int] = []
        for key in sequence:
            joints = self.solver_joints[key]
            if self.composition == "reencode" and done:
                cols = np.asarray([3 * j + k for j in done for k in range(3)], dtype=np.intp)
                pose[:, cols] = flat[:, cols]
            pose = self.fused[key](pose, canvas[:, joints].reshape(len(x), -1))
            done.extend(int(j) for j in joints if int(j) not in done)
        return pose

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

    def _compose(
        self, z: npt.NDArray[np.float32], canvas: npt.NDArray[np.float32], sequence: tuple[str, ...]
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
            return self.solvers[key](z, canvas[:, self.solver_joints[key]].reshape(len(z), -1))
        flat = canvas.reshape(len(z), -1)
        done: list[int] = []
        for _ in range(self.passes):
            for key in sequence:
                joints = self.solver_joints[key]
                if self.composition == "reencode" and done:
                    z = self._paste(z, flat, done)
                z = self.solvers[key](z, canvas[:, joints].reshape(len(z), -1))
                done.extend(int(j) for j in joints if int(j) not in done)
        if self.composition == "reencode":
            for _ in range(self.projections):
                z = self._paste(z, flat, done)
        return z

    def _paste(
        self, z: npt.NDArray[np.float32], flat: npt.NDArray[np.float32], joints: list[int]
    ) -> npt.NDArray[np.float32]:
        """Decode, put ``joints`` on their targets, encode: back onto the pose manifold."""
        x = self.decoder(z)
        cols = np.asarray([3 * j + k for j in joints for k in range(3)], dtype=np.intp)
        x[:, cols] = flat[:, cols]
        return self.encoder(x)

    def _exact(
        self, p: SolveProblem, start: F64, neural: F64, lengths: F64, goal: F64
    ) -> tuple[F64, int, list[str]]:
        """Exact reach: polish the neural pose onto the targets. When that leaves a target
        the plain FABRIK solve from the start pose does reach (the network moved the
        pelvis where a target is out of reach), that FABRIK answer is used."""
        kw = {"weights": p.weights, "tolerance": p.tolerance,
              "max_iterations": self.fabrik_max_iterations,
              "pinned": np.arange(len(p.target_idx)) >= p.n_targets}  # fmt: skip
        res = kinematics.polish(neural, lengths, p.target_idx, goal, **kw)  # type: ignore[arg-type]
        if bool(np.all(res.reached)):
            return res.positions, res.iterations, ["fabrik-polish"]
        alt = kinematics.fabrik(start, lengths, p.target_idx, goal, **kw)  # type: ignore[arg-type]
        if float(np.max(alt.errors)) < float(np.max(res.errors)):
            return alt.positions, res.iterations + alt.iterations, ["fabrik-fallback"]
        return res.positions, res.iterations, ["fabrik-polish"]

    # -- key-point completion -----------------------------------------------------------
    def complete(
        self,
        keypoints: dict[str, F64],
        given_lengths: dict[str, float] | None,
        tolerance: float = 1e-3,
        floor: float = 0.0,
    ) -> CompleteResult:
        levels = self.manifest.completion_levels()
        missing = [j for j in levels[0].joints if j not in keypoints]
        if missing:
            raise InvalidRequest(
                f"keypoints: the six base points are required; missing {missing}",
                missing=missing,
            )
        # pelvis floor projection to the origin; the networks were trained for any yaw
        origin = keypoints["pelvis"].copy()
        origin[1] = floor
        ref = self.reference_lengths
        bones = {JOINT_NAMES[c]: b for b, (c, _) in enumerate(BONES)}
        lengths = ref.copy()
        scale = 1.0
        if given_lengths:
            bad = sorted(set(given_lengths) - set(bones))
            if bad:
                raise InvalidRequest(
                    f"bone_lengths: no bone ends at {bad} (name the child joint of each bone)"
                )
            ratio = float(np.median([given_lengths[j] / ref[bones[j]] for j in given_lengths]))
            lengths = ref * ratio
            # networks trained on random bodies at random sizes read the size from the key
            # points; older ones are fed the size of their nearest training skeleton
            scale = 1.0 if self.body == "total_length" else float(self.scales_of(lengths))
            for j, value in given_lengths.items():
                lengths[bones[j]] = value
        given = {j: (v - origin) / scale for j, v in keypoints.items()}
        last = len(levels)
        for n, entry in enumerate(levels, start=1):
            if set(given) <= set(entry.joints):
                last = n
                break
        pred: F64 | None = None
        run: list[int] = []
        for n in range(1, last + 1):
            joints = levels[n - 1].joints
            rows = []
            for j in joints:
                if j in given:
                    rows.append(given[j])
                else:
                    assert pred is not None
                    rows.append(pred[JOINT_INDEX[j]])
            x = np.concatenate(rows)[None].astype(np.float32)
            pred = self.completion[n - 1](x)[0].astype(np.float64).reshape(NUM_JOINTS, 3)
            run.append(n)
        assert pred is not None
        if not given_lengths:  # the network's own estimate of this body's proportions
            lengths = np.asarray(bone_lengths(pred), dtype=np.float64)
        pose = kinematics.bone_pass(pred * scale, lengths)
        idx = np.asarray([JOINT_INDEX[j] for j in keypoints], dtype=np.intp)
        goal = np.stack([given[j] * scale for j in keypoints])
        res = kinematics.polish(
            pose,
            lengths,
            idx,
            goal,
            tolerance=tolerance,
            max_iterations=self.fabrik_max_iterations,
        )
        world = res.positions + origin
        errors = np.linalg.norm(world[idx] - np.stack(list(keypoints.values())), axis=-1)
        return CompleteResult(pose=world, errors=errors, reached=errors <= tolerance, levels=run)

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


def _chain_matrix() -> npt.NDArray[np.float64]:
    """``[21, 20]``: 1 where a bone lies on the path from the pelvis to a joint."""
    out = np.zeros((NUM_JOINTS, len(BONES)))
    bone_of = {child: b for b, (child, _) in enumerate(BONES)}
    for joint in range(NUM_JOINTS):
        j = joint
        while j in bone_of:
            out[joint, bone_of[j]] = 1.0
            j = BONES[bone_of[j]][1]
    return out


_CHAIN = _chain_matrix()
_LEG = JOINT_INDEX["left_ankle"]


@lru_cache(maxsize=4096)
def _cover(joints: frozenset[str], available: frozenset[str]) -> tuple[str, ...]:
    """Trained sets covering ``joints``: the exact set if trained, else greedily the
    largest trained subsets of the target set (ties by name) until no trained set adds a
    joint. Joints no trained set contains stay uncovered (placed by FABRIK)."""
    key = set_key(joints)
    if key in available:
        return (key,)
    candidates = sorted(
        (k for k in available if set(k.split("+")) <= joints),
        key=lambda k: (-len(k.split("+")), k),
    )
    chosen: list[str] = []
    covered: set[str] = set()
    for k in candidates:
        members = set(k.split("+"))
        if members - covered:
            chosen.append(k)
            covered |= members
    return tuple(chosen)
