"""`pose-trainer evaluate`: accuracy of the served pipeline on the TEST split.

Everything runs through :class:`service.engine.Engine` in-process (the exact code the
service runs), never through the training graphs. Problems are built from whole test
clips the models never saw:

* B1 edits -- a start and a target pose of the same clip, 0.2-1 s apart (the pelvis
  floor projection of both is already at the origin in the canonical dataset, as in the
  training pairs); targets are the target pose's joints, for each default single joint,
  the trained pairs and the five end effectors composed.
* B2 completion -- a whole pose from the key points of each completion level.
* B3 random subsets of 1-6 solver joints (composition beyond the trained sets).
* B4 drag paths -- targets follow a real clip frame by frame; every solve starts from the
  previous result.
* B5 stress -- unreachable targets, targets inside the body, tall/small characters and
  a character far from the origin facing -X.

Metrics are in centimetres unless stated. :func:`render_report` turns the results (a
JSON-able dict) into the markdown report that ``make bench`` and this command write; the
speed sections are filled in by ``bench`` when it ran.
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core import kinematics
from core.geometry import yaw_matrix
from core.rest import rest_pose
from core.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, bone_lengths, chain_to_root
from service.engine import Engine, SolveProblem
from trainer.data.dataset import FPS, PoseDataset, load_dataset
from trainer.pairs import partner_ranges, sample_partners

F64 = npt.NDArray[np.floating[Any]]
IntArray = npt.NDArray[np.intp]
Json = dict[str, Any]

#: Methods compared on every edit set, in table order.
METHODS: tuple[str, ...] = ("identity", "fabrik", "neural_raw", "neural_bone", "neural_exact")
METHOD_LABEL: dict[str, str] = {
    "identity": "identity",
    "fabrik": "FABRIK",
    "neural_raw": "neural raw",
    "neural_bone": "neural + bone pass",
    "neural_exact": "neural + exact reach",
    "rest_fabrik": "rest pose + FABRIK",  # B2 baseline
    "neural": "completion",  # B2
}
#: Engine options (method, preserve_bone_lengths, reach) of each solving method.
METHOD_OPTIONS: dict[str, tuple[str, bool, str]] = {
    "fabrik": ("fabrik", True, "soft"),
    "neural_raw": ("neural", False, "soft"),
    "neural_bone": ("neural", True, "soft"),
    "neural_exact": ("neural", True, "exact"),
}
METHOD_COLOUR: dict[str, str] = {
    "identity": "#9e9e9e",
    "fabrik": "#ff7f0e",
    "neural_raw": "#aec7e8",
    "neural_bone": "#1f77b4",
    "neural_exact": "#2ca02c",
    "rest_fabrik": "#ff7f0e",  # B2 baseline
    "neural": "#1f77b4",  # B2 completion
}
END_EFFECTORS: tuple[str, ...] = ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")
FIVE = "5 end effectors"
FLOOR_JOINTS: tuple[str, ...] = ("left_ankle", "left_foot", "right_ankle", "right_foot")
TOLERANCE = 1e-3  # metres, the service's default
MIN_GAP, MAX_GAP = int(0.2 * FPS), int(1.0 * FPS)  # B1 pair distance in frames
CM = 100.0


@dataclass(frozen=True)
class EvalConfig:
    """Sample sizes (per set) and seeds; the defaults fit ``make bench`` in minutes."""

    edits: int = 1000  # B1 edits (the same pose pairs for every target set)
    random_edits: int = 500  # B3 edits per subset size
    random_max: int = 6
    completions: int = 500  # B2 items per completion level
    paths: int = 16  # B4 drag paths ...
    path_frames: int = 90  # ... of this many frames (3 s)
    stress: int = 200  # B5 items per stress case
    #: composition ablation: (label, Engine keyword arguments)
    strategies: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = (
        ("sequential (paper)", (("composition", "sequential"),)),
        ("sequential, 2 passes", (("composition", "sequential"), ("composition_passes", 2))),
        ("re-encode, 0 projections", (("composition_projections", 0),)),
        ("re-encode, 1 projection (default)", (("composition_projections", 1),)),
        ("re-encode, 2 projections", (("composition_projections", 2),)),
    )
    determinism: int = 200
    seed: int = 0
    chunk: int = 2048  # neural items per Engine.solve call


#: A seconds-long configuration for tests and smoke runs.
QUICK = EvalConfig(
    edits=8,
    random_edits=3,
    random_max=3,
    completions=3,
    paths=2,
    path_frames=6,
    stress=4,
    strategies=(
        ("sequential (paper)", (("composition", "sequential"),)),
        ("re-encode, 1 projection (default)", (("composition_projections", 1),)),
    ),
    determinism=4,
)


# --------------------------------------------------------------------------------------
# Problems
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Edits:
    """N edit problems: start poses, target joints/positions and (if any) the real pose."""

    start: F64  # [N, 21, 3]
    joints: list[IntArray]  # per item, K_i target joint indices
    targets: list[F64]  # per item, [K_i, 3]
    goal: F64 | None = None  # [N, 21, 3] the real pose the targets come from

    def __len__(self) -> int:
        return int(self.start.shape[0])

    def take(self, n: int) -> Edits:
        return Edits(
            self.start[:n],
            self.joints[:n],
            self.targets[:n],
            None if self.goal is None else self.goal[:n],
        )

    def mapped(self, fn: Callable[[F64], F64]) -> Edits:
        """The same problems with every position mapped by ``fn`` (``[..., 3]``)."""
        return Edits(
            fn(self.start),
            self.joints,
            [fn(t) for t in self.targets],
            None if self.goal is None else fn(self.goal),
        )


def _idx(names: Sequence[str]) -> IntArray:
    return np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)


def test_split(dataset: PoseDataset) -> PoseDataset:
    test = dataset.subset(dataset.split_mask("test"))
    if len(test) == 0:
        raise ValueError("the dataset's test split is empty")
    return test


def sample_pairs(test: PoseDataset, n: int, rng: np.random.Generator) -> tuple[IntArray, IntArray]:
    """``n`` (start, target) frame pairs of the same clip, 0.2-1 s apart (trainer.pairs)."""
    lo, hi = partner_ranges(test.clip, test.frame, MAX_GAP)
    starts: list[IntArray] = []
    goals: list[IntArray] = []
    have = 0
    for _ in range(64):
        anchors = rng.integers(0, len(test), size=max(2 * (n - have), 16)).astype(np.int64)
        partners = sample_partners(lo, hi, anchors, rng, frame=test.frame, min_gap=MIN_GAP)
        ok = partners != anchors
        starts.append(anchors[ok].astype(np.intp))
        goals.append(partners[ok].astype(np.intp))
        have += int(ok.sum())
        if have >= n:
            break
    a, b = np.concatenate(starts)[:n], np.concatenate(goals)[:n]
    if len(a) < n:
        raise ValueError(f"could only sample {len(a)} of {n} test pairs")
    return a, b


def edits_from_pairs(
    test: PoseDataset, a: IntArray, b: IntArray, joint_sets: Sequence[IntArray]
) -> Edits:
    start = test.positions[a].astype(np.float64)
    goal = test.positions[b].astype(np.float64)
    joints = [np.asarray(j, dtype=np.intp) for j in joint_sets]
    return Edits(start, joints, [goal[i, j] for i, j in enumerate(joints)], goal)


def b1_sets(engine: Engine) -> dict[str, tuple[str, ...]]:
    """B1 target sets: every trained single joint, every trained pair, the five composed."""
    solvers = engine.manifest.solvers()
    singles = {k: tuple(e.joints) for k, e in solvers.items() if len(e.joints) == 1}
    multi = {k: tuple(e.joints) for k, e in solvers.items() if len(e.joints) > 1}
    return {**singles, **multi, FIVE: END_EFFECTORS}


def solver_joints(engine: Engine) -> list[str]:
    """Joints with a trained single-joint solver (the B3 pool)."""
    return [e.joints[0] for e in engine.manifest.solvers().values() if len(e.joints) == 1]


# --------------------------------------------------------------------------------------
# Solving
# --------------------------------------------------------------------------------------
def problems(edits: Edits, method: str) -> list[SolveProblem]:
    engine_method, preserve, reach = METHOD_OPTIONS[method]
    return [
        SolveProblem(
            pose=edits.start[i],
            target_idx=edits.joints[i],
            target_pos=edits.targets[i],
            weights=np.ones(len(edits.joints[i])),
            n_targets=len(edits.joints[i]),
            method=engine_method,
            preserve_bone_lengths=preserve,
            reach=reach,
            tolerance=TOLERANCE,
        )
        for i in range(len(edits))
    ]


def solve(engine: Engine, edits: Edits, method: str, chunk: int = 2048) -> F64:
    """Solved poses ``[N, 21, 3]`` (world, as given) of one method."""
    if method == "identity":
        return edits.start.copy()
    probs = problems(edits, method)
    out: list[F64] = []
    for s in range(0, len(probs), chunk):
        out.extend(r.pose for r in engine.solve(probs[s : s + chunk]))
    return np.stack(out) if out else np.zeros((0, NUM_JOINTS, 3))


# --------------------------------------------------------------------------------------
# Metrics
# --------------------------------------------------------------------------------------
def _chain(joints: IntArray) -> IntArray:
    names = {JOINT_NAMES[int(j)] for j in joints}
    chain = {c for n in names for c in chain_to_root(n)} - names
    return _idx(sorted(chain, key=JOINT_INDEX.__getitem__))


def _root_reach(start: F64) -> tuple[F64, F64]:
    """``[N, 21]`` shortest and longest distance from the root (pelvis) at which each joint
    can be placed with the root held: the reach shell of its chain of bones."""
    from core.skeleton import PARENTS

    lengths = np.linalg.norm(start[:, 1:] - start[:, list(PARENTS[1:])], axis=-1)
    longest = np.zeros(start.shape[:2])
    biggest = np.zeros(start.shape[:2])
    for joint in range(1, NUM_JOINTS):  # parents precede children
        bone = lengths[:, joint - 1]
        longest[:, joint] = longest[:, PARENTS[joint]] + bone
        biggest[:, joint] = np.maximum(biggest[:, PARENTS[joint]], bone)
    shortest = np.maximum(0.0, 2 * biggest - longest)
    return shortest, longest


def per_item(edits: Edits, poses: F64) -> dict[str, F64]:
    """Per-item metrics (cm; bone error relative): reach (per target, flattened) and
    whether the target is surely reachable (inside its chain's reach shell around the START
    pelvis, i.e. reachable even with the pelvis held; the pelvis itself always is), mpjpe /
    untargeted / chain (vs the real pose), drift (untargeted vs start), bone, floor."""
    n = len(edits)
    root = JOINT_INDEX["pelvis"]
    shortest, longest = _root_reach(edits.start)
    dist = [np.linalg.norm(t - edits.start[i, root], axis=-1) for i, t in enumerate(edits.targets)]
    reachable = [
        (j == root) | ((d <= longest[i, j] - 1e-6) & (d >= shortest[i, j] + 1e-6))
        for i, (j, d) in enumerate(zip(edits.joints, dist, strict=True))
    ]
    diff_goal = None if edits.goal is None else np.linalg.norm(poses - edits.goal, axis=-1)
    drift_all = np.linalg.norm(poses - edits.start, axis=-1)
    reach, mpjpe, untargeted, chain, drift = [], [], [], [], []
    for i in range(n):
        j = edits.joints[i]
        reach.append(np.linalg.norm(poses[i, j] - edits.targets[i], axis=-1))
        free = np.ones(NUM_JOINTS, dtype=bool)
        free[j] = False
        drift.append(drift_all[i, free].mean() if free.any() else np.nan)
        if diff_goal is not None:
            mpjpe.append(diff_goal[i].mean())
            untargeted.append(diff_goal[i, free].mean() if free.any() else np.nan)
            c = _chain(j)
            chain.append(diff_goal[i, c].mean() if len(c) else np.nan)
    start_len = bone_lengths(edits.start)
    bone = np.abs(bone_lengths(poses) / start_len - 1.0).max(axis=-1)
    floor = np.maximum(0.0, -poses[:, _idx(FLOOR_JOINTS), 1].min(axis=-1))
    nan = np.full(n, np.nan)
    return {
        "reach": np.concatenate(reach) * CM if reach else np.zeros(0),
        "reachable": np.concatenate(reachable).astype(np.float64) if reach else np.zeros(0),
        "mpjpe": np.asarray(mpjpe) * CM if mpjpe else nan,
        "untargeted": np.asarray(untargeted) * CM if untargeted else nan,
        "chain": np.asarray(chain) * CM if chain else nan,
        "drift": np.asarray(drift) * CM,
        "bone": bone,
        "floor": floor * CM,
        "finite": np.isfinite(poses).all(axis=(-1, -2)).astype(np.float64),
    }


def _mean(x: F64) -> float | None:
    x = x[np.isfinite(x)]
    return float(x.mean()) if x.size else None


def _pct(x: F64, q: float) -> float | None:
    x = x[np.isfinite(x)]
    return float(np.percentile(x, q)) if x.size else None


def summarise(m: dict[str, F64]) -> Json:
    reach = m["reach"]
    ok = m["reachable"] > 0.5
    return {
        "n": int(m["bone"].shape[0]),
        "reach_mean": _mean(reach),
        "reach_median": _pct(reach, 50),
        "reach_p95": _pct(reach, 95),
        "reach_max": _pct(reach, 100),
        "reach_within_1cm": float(np.mean(reach <= 1.0) * 100) if reach.size else None,
        "reach_within_1mm": float(np.mean(reach <= 0.1) * 100) if reach.size else None,
        "reachable_pct": float(np.mean(ok) * 100) if reach.size else None,
        "reachable_reach_max": float(reach[ok].max()) if ok.any() else None,
        "reachable_within_1mm": float(np.mean(reach[ok] <= 0.1) * 100) if ok.any() else None,
        "mpjpe": _mean(m["mpjpe"]),
        "mpjpe_median": _pct(m["mpjpe"], 50),
        "untargeted": _mean(m["untargeted"]),
        "chain": _mean(m["chain"]),
        "drift": _mean(m["drift"]),
        "bone_max": float(np.max(m["bone"])) if m["bone"].size else None,
        "floor_mean": _mean(m["floor"]),
        "floor_over_1cm": float(np.mean(m["floor"] > 1.0) * 100) if m["floor"].size else None,
        "finite": float(np.mean(m["finite"]) * 100) if m["finite"].size else None,
    }


# --------------------------------------------------------------------------------------
# The evaluation
# --------------------------------------------------------------------------------------
@dataclass
class Accuracy:
    """Results (JSON-able) plus the per-item arrays the plots need."""

    results: Json
    mpjpe: dict[str, dict[str, F64]] = field(default_factory=dict)  # set -> method -> items
    samples: list[Json] = field(default_factory=list)  # for the sample-poses figure
    paths: Json = field(default_factory=dict)  # B4 per-step curves


def _log(msg: str) -> None:
    print(f"[evaluate {time.strftime('%H:%M:%S')}] {msg}", flush=True)


def run_methods(
    engine: Engine, edits: Edits, methods: Sequence[str], chunk: int
) -> tuple[dict[str, F64], dict[str, float]]:
    poses: dict[str, F64] = {}
    seconds: dict[str, float] = {}
    for method in methods:
        t0 = time.perf_counter()
        poses[method] = solve(engine, edits, method, chunk)
        seconds[method] = time.perf_counter() - t0
    return poses, seconds


def _sample(name: str, edits: Edits, poses: dict[str, F64], rng_pick: int) -> Json:
    """The most visible edit among the first items (largest target displacement)."""
    n = min(len(edits), 64)
    moved = [
        float(np.linalg.norm(edits.targets[i] - edits.start[i, edits.joints[i]], axis=-1).mean())
        for i in range(n)
    ]
    i = int(np.argsort(moved)[-1 - rng_pick % max(1, min(3, n))])
    return {
        "name": name,
        "start": edits.start[i],
        "joints": edits.joints[i],
        "targets": edits.targets[i],
        "goal": None if edits.goal is None else edits.goal[i],
        "fabrik": poses["fabrik"][i],
        "neural": poses["neural_bone"][i],
    }


def eval_edit_sets(
    engine: Engine, sets: dict[str, Edits], cfg: EvalConfig, acc: Accuracy, bench: str
) -> Json:
    out: Json = {}
    for name, edits in sets.items():
        poses, seconds = run_methods(engine, edits, METHODS, cfg.chunk)
        out[name] = {}
        acc.mpjpe[f"{bench} {name}"] = {}
        for method in METHODS:
            m = per_item(edits, poses[method])
            out[name][method] = {**summarise(m), "seconds": round(seconds[method], 3)}
            acc.mpjpe[f"{bench} {name}"][method] = m["mpjpe"]
        _log(
            f"{bench} {name}: MPJPE "
            + ", ".join(f"{k} {out[name][k]['mpjpe']:.2f}" for k in METHODS)
        )
        if name in ("left_wrist", "left_wrist+right_wrist", FIVE, "4 joints"):
            acc.samples.append(_sample(f"{bench} {name}", edits, poses, len(acc.samples)))
    return out


def b3_edits(
    test: PoseDataset, pool: list[str], cfg: EvalConfig, rng: np.random.Generator
) -> dict[str, Edits]:
    sets: dict[str, Edits] = {}
    for k in range(1, min(cfg.random_max, len(pool)) + 1):
        a, b = sample_pairs(test, cfg.random_edits, rng)
        joint_sets = [
            np.sort(_idx([pool[int(j)] for j in rng.choice(len(pool), size=k, replace=False)]))
            for _ in range(len(a))
        ]
        sets[f"{k} joint{'s' if k > 1 else ''}"] = edits_from_pairs(test, a, b, joint_sets)
    return sets


def pooled(sets: dict[str, Edits], names: Sequence[str]) -> Edits:
    chosen = [sets[n] for n in names]
    goals = [e.goal for e in chosen if e.goal is not None]
    return Edits(
        np.concatenate([e.start for e in chosen]),
        [j for e in chosen for j in e.joints],
        [t for e in chosen for t in e.targets],
        np.concatenate(goals) if len(goals) == len(chosen) else None,
    )


def eval_completion(engine: Engine, test: PoseDataset, cfg: EvalConfig, acc: Accuracy) -> Json:
    """B2: a pose from key points only; baseline: the rest pose FABRIK'd onto them."""
    rng = np.random.default_rng(cfg.seed + 2)
    ref = engine.reference_lengths
    rest = np.asarray(kinematics.bone_pass(rest_pose(), ref), dtype=np.float64)
    out: Json = {}
    for level, entry in enumerate(engine.manifest.completion_levels(), start=1):
        rows = rng.choice(len(test), size=min(cfg.completions, len(test)), replace=False)
        real = test.positions[rows].astype(np.float64)
        key = _idx(entry.joints)
        neural, base, seconds = [], [], 0.0
        for pose in real:
            t0 = time.perf_counter()
            res = engine.complete({j: pose[JOINT_INDEX[j]] for j in entry.joints}, None)
            seconds += time.perf_counter() - t0
            neural.append(res.pose)
            start = rest + (pose[JOINT_INDEX["pelvis"]] - rest[JOINT_INDEX["pelvis"]])
            fab = kinematics.fabrik(
                start,
                ref,
                key,
                pose[key],
                tolerance=TOLERANCE,
                max_iterations=engine.fabrik_max_iterations,
            )
            base.append(np.asarray(fab.positions, dtype=np.float64))
        edits = Edits(real, [key] * len(real), [p[key] for p in real], real)
        name = f"level {level} ({len(entry.joints)} points)"
        out[name] = {"joints": list(entry.joints), "ms_per_call": seconds / len(real) * 1e3}
        acc.mpjpe[f"B2 {name}"] = {}
        for method, poses in (("rest_fabrik", np.stack(base)), ("neural", np.stack(neural))):
            m = per_item(edits, poses)
            s = summarise(m)
            # bone error here is vs the real skeleton (completion does not know it)
            s["bone_vs_real_mean"] = float(
                np.mean(np.abs(bone_lengths(poses) / bone_lengths(real) - 1.0))
            )
            out[name][method] = s
            acc.mpjpe[f"B2 {name}"][method] = m["mpjpe"]
        _log(f"B2 {name}: MPJPE neural {out[name]['neural']['mpjpe']:.2f} cm")
    return out


def _contiguous_segments(test: PoseDataset, length: int) -> list[int]:
    """Start rows of every run of ``length`` consecutive frames of one clip."""
    same = (np.diff(test.clip) == 0) & (np.diff(test.frame) == 1)
    ok = np.concatenate([same.astype(np.int64), [0]])
    run = np.zeros(len(test), dtype=np.int64)  # consecutive successors from each row
    for i in range(len(test) - 2, -1, -1):
        run[i] = run[i + 1] + 1 if ok[i] else 0
    return np.flatnonzero(run >= length - 1).tolist()


def eval_paths(engine: Engine, test: PoseDataset, cfg: EvalConfig, acc: Accuracy) -> Json:
    """B4: targets follow a real clip; each solve starts from the previous result."""
    rng = np.random.default_rng(cfg.seed + 4)
    length = cfg.path_frames
    starts = _contiguous_segments(test, length)
    if not starts:
        return {}
    # one segment per distinct clip where possible
    by_clip: dict[int, list[int]] = {}
    for s in starts:
        by_clip.setdefault(int(test.clip[s]), []).append(s)
    clips = rng.permutation(sorted(by_clip))[: cfg.paths]
    rows = [by_clip[int(c)][int(rng.integers(len(by_clip[int(c)])))] for c in clips]
    seg = np.stack([test.positions[r : r + length] for r in rows]).astype(np.float64)
    real_acc = np.linalg.norm(seg[:, 2:] - 2 * seg[:, 1:-1] + seg[:, :-2], axis=-1) * FPS**2
    out: Json = {"paths": len(rows), "frames": length, "real_jitter": float(real_acc.mean())}
    for set_name, names in (("left_wrist", ("left_wrist",)), (FIVE, END_EFFECTORS)):
        idx = _idx(names)
        free = np.setdiff1d(np.arange(NUM_JOINTS), idx)
        out[set_name] = {}
        for method in ("fabrik", "neural_bone", "neural_exact"):
            t0 = time.perf_counter()
            traj = np.empty_like(seg)
            traj[:, 0] = seg[:, 0]
            for t in range(1, length):
                step = Edits(traj[:, t - 1], [idx] * len(rows), list(seg[:, t][:, idx]))
                traj[:, t] = solve(engine, step, method, cfg.chunk)
            seconds = time.perf_counter() - t0
            accel = np.linalg.norm(traj[:, 2:] - 2 * traj[:, 1:-1] + traj[:, :-2], axis=-1)
            accel *= FPS**2
            err = np.linalg.norm(traj - seg, axis=-1) * CM  # [P, T, 21]
            reach = np.linalg.norm(traj[:, 1:, idx] - seg[:, 1:, idx], axis=-1) * CM
            bone = np.abs(bone_lengths(traj) / bone_lengths(seg[:, :1]) - 1.0).max()
            k = max(1, min(10, length // 3))
            untargeted_t = err[:, :, free].mean(axis=(0, 2))
            out[set_name][method] = {
                "jitter": float(accel.mean()),
                "jitter_untargeted": float(accel[:, :, free].mean()),
                "reach_mean": float(reach.mean()),
                "mpjpe": float(err[:, 1:].mean()),
                "untargeted_first": float(untargeted_t[1 : k + 1].mean()),
                "untargeted_last": float(untargeted_t[-k:].mean()),
                "bone_max": float(bone),
                "seconds": round(seconds, 3),
            }
            acc.paths.setdefault(set_name, {})[method] = untargeted_t.tolist()
        _log(
            f"B4 {set_name}: jitter "
            + ", ".join(f"{m} {v['jitter']:.2f}" for m, v in out[set_name].items())
        )
    return out


def _stress_methods() -> tuple[str, ...]:
    return ("fabrik", "neural_raw", "neural_bone", "neural_exact")


def eval_stress(engine: Engine, base: Edits, cfg: EvalConfig) -> Json:
    """B5. ``base`` are B1 five-end-effector edits (canonical)."""
    rng = np.random.default_rng(cfg.seed + 5)
    n = min(cfg.stress, len(base))
    canon = base.take(n)
    methods = _stress_methods()
    ref_poses, _ = run_methods(engine, canon, methods, cfg.chunk)
    out: Json = {"canonical": {m: summarise(per_item(canon, ref_poses[m])) for m in methods}}

    # characters of another size, and one far away facing -X: the same problems
    rest = rest_pose()
    heights = np.asarray(
        [
            stand[JOINT_INDEX["head"], 1] - stand[_idx(FLOOR_JOINTS), 1].min()
            for stand in (kinematics.bone_pass(rest, bl) for bl in bone_lengths(canon.start))
        ]
    )
    rot = yaw_matrix(np.asarray(-np.pi / 2))  # +Z (forward) -> -X
    offset = np.array([50.0, 0.0, -30.0])
    cases: list[tuple[str, Edits, Callable[[F64], F64], str]] = []

    def unscale(s: F64) -> Callable[[F64], F64]:
        return lambda x: np.asarray(x / s[:, None, None])

    for h in (1.9, 1.2):
        s = h / heights
        moved = Edits(
            canon.start * s[:, None, None],
            canon.joints,
            [t * s[i] for i, t in enumerate(canon.targets)],
            None if canon.goal is None else canon.goal * s[:, None, None],
        )
        cases.append(
            (
                f"{h} m character",
                moved,
                unscale(s),
                f"scaled about the origin so the standing head joint is {h} m high",
            )
        )
    cases.append(
        (
            "facing -X at (50, 0, -30) m",
            canon.mapped(lambda x: np.asarray(x @ rot.T + offset)),
            lambda x: np.asarray((x - offset) @ rot),
            "yawed -90 degrees (facing -X) and moved to (50, 0, -30) m",
        )
    )
    for name, moved, back, what in cases:
        poses, _ = run_methods(engine, moved, methods, cfg.chunk)
        out[name] = {"transform": what}
        for m in methods:
            back_poses = back(poses[m])
            s_m = summarise(per_item(canon, back_poses))
            s_m["max_dev_mm"] = float(np.abs(back_poses - ref_poses[m]).max() * 1000)
            s_m["bone_max_world"] = float(
                np.abs(bone_lengths(poses[m]) / bone_lengths(moved.start) - 1.0).max()
            )
            out[name][m] = s_m
        _log(
            f"B5 {name}: max deviation from canonical (mm) "
            + ", ".join(f"{m} {out[name][m]['max_dev_mm']:.3g}" for m in methods)
        )

    # unreachable: a wrist at twice the arm's length from its shoulder
    start = canon.start
    ar = np.arange(n)
    left = rng.integers(0, 2, size=n) == 0
    pick = lambda lj, rj: np.where(left, JOINT_INDEX[lj], JOINT_INDEX[rj])  # noqa: E731
    wrists = pick("left_wrist", "right_wrist")
    elbows = pick("left_elbow", "right_elbow")
    shoulders = pick("left_shoulder", "right_shoulder")
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    arm = np.linalg.norm(start[ar, wrists] - start[ar, elbows], axis=-1) + np.linalg.norm(
        start[ar, elbows] - start[ar, shoulders], axis=-1
    )
    far = start[ar, shoulders] + 2.0 * arm[:, None] * direction
    unreachable = Edits(start, [np.asarray([w]) for w in wrists], [f[None] for f in far])
    # inside the body: a wrist onto spine1, an ankle onto the pelvis (alternating)
    inside_joint = np.where(ar % 2 == 0, wrists, pick("left_ankle", "right_ankle"))
    inside_at = np.where(ar % 2 == 0, JOINT_INDEX["spine1"], JOINT_INDEX["pelvis"])
    inside = Edits(
        start, [np.asarray([j]) for j in inside_joint], [start[i, inside_at[i]][None] for i in ar]
    )
    for name, edits, what in (
        (
            "unreachable (2x arm length)",
            unreachable,
            "a wrist target 2x the arm's length from its shoulder, random direction",
        ),
        (
            "inside the body",
            inside,
            "a wrist onto spine1 or an ankle onto the pelvis (alternating)",
        ),
    ):
        poses, _ = run_methods(engine, edits, methods, cfg.chunk)
        out[name] = {"transform": what}
        for m in methods:
            out[name][m] = summarise(per_item(edits, poses[m]))
        if name.startswith("unreachable"):
            dist = np.linalg.norm(far - start[ar, shoulders], axis=-1) - arm
            out[name]["beyond_arm_cm"] = float(dist.mean() * CM)
        _log(
            f"B5 {name}: reach mean "
            + ", ".join(f"{m} {out[name][m]['reach_mean']:.2f}" for m in methods)
        )
    return out


def eval_determinism(engine: Engine, edits: Edits, cfg: EvalConfig) -> Json:
    """Repeat identical batches and compare bits; also one-by-one vs batched."""
    n = min(cfg.determinism, len(edits))
    sub = edits.take(n)
    out: Json = {"n": n}
    for method in ("fabrik", "neural_bone", "neural_exact"):
        first = solve(engine, sub, method, cfg.chunk)
        again = solve(engine, sub, method, cfg.chunk)
        k = min(n, 32)
        single = np.stack(
            [
                solve(
                    engine, Edits(sub.start[i : i + 1], [sub.joints[i]], [sub.targets[i]]), method
                )[0]
                for i in range(k)
            ]
        )
        out[method] = {
            "repeat_bitwise_equal": bool(np.array_equal(first, again)),
            "single_vs_batch_max_abs_m": float(np.abs(single - first[:k]).max()),
        }
    return out


def eval_ablation(models_dir: Path, b1_five: Edits, b3: Edits, cfg: EvalConfig) -> Json:
    out: Json = {}
    for label, kwargs in cfg.strategies:
        engine = Engine(models_dir, threads=1, **dict(kwargs))
        row: Json = {}
        for name, edits in ((f"B1 {FIVE}", b1_five), ("B3 2+ joints", b3)):
            for method in ("neural_raw", "neural_bone"):
                row[f"{name}|{method}"] = summarise(
                    per_item(edits, solve(engine, edits, method, cfg.chunk))
                )
        out[label] = row
        _log(
            f"ablation {label}: "
            + ", ".join(
                f"{k.split('|')[0]} MPJPE {v['mpjpe']:.2f}"
                for k, v in row.items()
                if k.endswith("neural_bone")
            )
        )
    return out


def model_bytes(engine: Engine) -> Json:
    """Bytes on disk: the two-target (wrists) set and the whole model bundle."""
    m = engine.manifest
    files = {e.file: (engine.models_dir / e.file).stat().st_size for e in m.models}
    ae = [m.autoencoder("encoder").file, m.autoencoder("decoder").file]
    solvers = m.solvers()
    pair = "left_wrist+right_wrist"
    two = ae + ([solvers[pair].file] if pair in solvers else [])
    return {
        "two_target_set": sum(files[f] for f in two),
        "two_target_files": two,
        "solvers_and_autoencoder": sum(files[f] for f in ae)
        + sum(files[e.file] for e in solvers.values()),
        "all_models": sum(files.values()),
        "files": len(files),
    }


def machine() -> Json:
    import onnxruntime

    return {
        "cpus": os.cpu_count(),
        "loadavg": [round(v, 2) for v in os.getloadavg()],
        "python": platform.python_version(),
        "numpy": np.__version__,
        "onnxruntime": onnxruntime.__version__,
        "platform": platform.platform(),
    }


def evaluate_accuracy(
    models_dir: Path, dataset_path: Path, cfg: EvalConfig | None = None
) -> Accuracy:
    """Run B1-B5, determinism and the composition ablation; returns results + plot data."""
    cfg = cfg or EvalConfig()
    t_start = time.perf_counter()
    engine = Engine(models_dir, threads=1)
    test = test_split(load_dataset(dataset_path))
    rng = np.random.default_rng(cfg.seed)
    acc = Accuracy(results={})
    res = acc.results
    res["config"] = asdict(cfg)
    res["models"] = {
        "dir": str(models_dir),
        "version": engine.version,
        "composition_passes": engine.passes,
        "composition": engine.composition,
        "composition_projections": engine.projections,
        "bytes": model_bytes(engine),
    }
    res["dataset"] = {
        "path": str(dataset_path),
        "test_frames": len(test),
        "test_clips": len(np.unique(test.clip)),
    }
    res["machine_start"] = machine()
    timings: Json = {}

    t0 = time.perf_counter()
    a, b = sample_pairs(test, cfg.edits, rng)
    sets = b1_sets(engine)
    b1 = {name: edits_from_pairs(test, a, b, [_idx(j)] * len(a)) for name, j in sets.items()}
    res["B1"] = eval_edit_sets(engine, b1, cfg, acc, "B1")
    timings["B1"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    b3 = b3_edits(test, solver_joints(engine), cfg, np.random.default_rng(cfg.seed + 3))
    res["B3"] = eval_edit_sets(engine, b3, cfg, acc, "B3")
    timings["B3"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    res["B2"] = eval_completion(engine, test, cfg, acc)
    timings["B2"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    res["B4"] = eval_paths(engine, test, cfg, acc)
    timings["B4"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    res["B5"] = eval_stress(engine, b1[FIVE], cfg)
    timings["B5"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    res["determinism"] = eval_determinism(engine, b1[FIVE], cfg)
    timings["determinism"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    multi = [k for k in b3 if not k.startswith("1 ")]
    res["ablation"] = eval_ablation(models_dir, b1[FIVE], pooled(b3, multi), cfg)
    timings["ablation"] = time.perf_counter() - t0

    timings["total"] = time.perf_counter() - t_start
    res["seconds"] = {k: round(v, 1) for k, v in timings.items()}
    return acc


# --------------------------------------------------------------------------------------
# Plots (matplotlib, Agg)
# --------------------------------------------------------------------------------------
def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_reach(results: Json, path: Path) -> None:
    """Mean reach error (log scale) by method and target set, B1 then B3."""
    plt = _plt()
    groups = [("B1", k) for k in results.get("B1", {})] + [("B3", k) for k in results.get("B3", {})]
    fig, ax = plt.subplots(figsize=(max(8.0, 0.75 * len(groups) + 2), 4.8))
    width = 0.8 / len(METHODS)
    for m, method in enumerate(METHODS):
        vals = [results[b][k][method]["reach_mean"] or np.nan for b, k in groups]
        xs = np.arange(len(groups)) + (m - (len(METHODS) - 1) / 2) * width
        ax.bar(
            xs,
            np.maximum(vals, 1e-4),
            width,
            label=METHOD_LABEL[method],
            color=METHOD_COLOUR[method],
        )
    ax.set_yscale("log")
    ax.set_ylim(bottom=1e-3)
    ax.axhline(1.0, color="k", lw=0.6, ls=":")
    ax.set_xticks(np.arange(len(groups)))
    ax.set_xticklabels([f"{b} {_short(k)}" for b, k in groups], rotation=50, ha="right", fontsize=8)
    ax.set_ylabel("mean reach error (cm, log; floor 0.001)")
    ax.set_title("Reach error by method and target set (TEST split; dotted: 1 cm)", pad=28)
    ax.legend(fontsize=8, ncol=5, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    ax.grid(axis="y", which="both", alpha=0.25)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _short(name: str) -> str:
    return (
        name.replace("left_", "L ")
        .replace("right_", "R ")
        .replace("+", " + ")
        .replace("end effectors", "end eff.")
    )


def plot_mpjpe(mpjpe: dict[str, dict[str, F64]], path: Path) -> None:
    """Per-item MPJPE (all joints) distributions for a selection of sets."""
    plt = _plt()
    wanted = [
        k
        for k in mpjpe
        if k.startswith("B1 ")
        and k.split(" ", 1)[1]
        in ("left_wrist", "head", "left_ankle", "left_wrist+right_wrist", FIVE)
    ]
    wanted += [k for k in mpjpe if k.startswith("B3 ")][-2:]
    wanted += [k for k in mpjpe if k.startswith("B2 ")]
    cols = 4
    rows = max(1, -(-len(wanted) // cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.0 * cols, 3.3 * rows), squeeze=False)
    for ax, key in zip(axes.flat, wanted, strict=False):
        methods = list(mpjpe[key])
        data = [v[np.isfinite(v)] for v in mpjpe[key].values()]
        box = ax.boxplot(data, showfliers=False, patch_artist=True, widths=0.6)
        for patch, m in zip(box["boxes"], methods, strict=True):
            patch.set_facecolor(METHOD_COLOUR.get(m, "#cccccc"))
        for med in box["medians"]:
            med.set_color("k")
        ax.set_xticks(range(1, len(methods) + 1))
        ax.set_xticklabels(
            [METHOD_LABEL.get(m, m) for m in methods], rotation=25, ha="right", fontsize=7
        )
        ax.set_title(_short(key), fontsize=9)
        ax.set_ylabel("MPJPE to real pose (cm)", fontsize=8)
        ax.grid(axis="y", alpha=0.25)
    for ax in list(axes.flat)[len(wanted) :]:
        ax.axis("off")
    fig.suptitle("MPJPE distributions (all joints; boxes: quartiles, whiskers 1.5 IQR)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _stick(ax: Any, pose: F64, colour: str, lw: float = 1.6, ls: str = "-") -> None:
    from core.skeleton import BONES

    for child, parent in BONES:
        ax.plot(
            [pose[parent, 0], pose[child, 0]],
            [pose[parent, 1], pose[child, 1]],
            color=colour,
            lw=lw,
            ls=ls,
            solid_capstyle="round",
        )


def plot_samples(samples: list[Json], path: Path) -> None:
    """Like the paper's Figure 3: start + targets, FABRIK, neural, the real pose."""
    plt = _plt()
    titles = ("start pose + targets", "FABRIK", "neural + bone pass", "real target pose")
    fig, axes = plt.subplots(len(samples), 4, figsize=(10, 3.0 * len(samples)), squeeze=False)
    for r, s in enumerate(samples):
        poses = (s["start"], s["fabrik"], s["neural"], s["goal"])
        colours = ("#555555", METHOD_COLOUR["fabrik"], METHOD_COLOUR["neural_bone"], "#2ca02c")
        everything = np.concatenate([p for p in poses if p is not None] + [s["targets"]])
        lo, hi = everything.min(axis=0), everything.max(axis=0)
        cx, span = (lo[0] + hi[0]) / 2, max(hi[0] - lo[0], hi[1] - lo[1]) / 2 + 0.1
        cy = (lo[1] + hi[1]) / 2
        for c, ax in enumerate(axes[r]):
            ax.set_aspect("equal")
            ax.set_xlim(cx - span, cx + span)
            ax.set_ylim(cy - span, cy + span)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.axhline(0.0, color="#bbbbbb", lw=0.6)
            if poses[c] is None:
                continue
            if c in (1, 2):
                _stick(ax, s["start"], "#cccccc", lw=1.0)
            _stick(ax, poses[c], colours[c])
            ax.scatter(
                s["targets"][:, 0],
                s["targets"][:, 1],
                marker="x",
                s=60,
                c="#d62728",
                zorder=5,
                linewidths=2,
            )
            if r == 0:
                ax.set_title(titles[c], fontsize=10)
        axes[r, 0].set_ylabel(_short(s["name"]), fontsize=9)
    fig.suptitle(
        "Sample TEST edits, front view (x right, y up); red x: targets, grey: start pose",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_ablation(results: Json, path: Path) -> None:
    plt = _plt()
    abl = results.get("ablation", {})
    labels = list(abl)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    cols = [(f"B1 {FIVE}", "neural_bone"), ("B3 2+ joints", "neural_bone")]
    width = 0.8 / len(cols)
    x = np.arange(len(labels))
    for i, (key, method) in enumerate(cols):
        reach = [abl[s][f"{key}|{method}"]["reach_mean"] for s in labels]
        mp = [abl[s][f"{key}|{method}"]["mpjpe"] for s in labels]
        name = f"{key} ({METHOD_LABEL[method]})"
        axes[0].bar(x + i * width, reach, width, label=name)
        axes[1].bar(x + i * width, mp, width, label=name)
    axes[0].set_ylabel("mean reach error (cm)")
    axes[1].set_ylabel("MPJPE to real pose (cm)")
    for ax in axes:
        ax.set_xticks(x + width / 2, labels, rotation=20, ha="right", fontsize=7)
        ax.grid(alpha=0.3, axis="y")
    axes[1].legend(fontsize=7)
    fig.suptitle("Composition strategies for target sets no single solver covers")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_paths(paths: Json, path: Path) -> None:
    plt = _plt()
    fig, axes = plt.subplots(
        1, max(1, len(paths)), figsize=(5 * max(1, len(paths)), 3.6), squeeze=False
    )
    for ax, (name, curves) in zip(axes[0], paths.items(), strict=False):
        for method, curve in curves.items():
            ax.plot(
                np.arange(len(curve)) / FPS,
                curve,
                label=METHOD_LABEL[method],
                color=METHOD_COLOUR[method],
            )
        ax.set_title(f"B4 drag path: {_short(name)}", fontsize=10)
        ax.set_xlabel("time along the path (s)")
        ax.set_ylabel("untargeted joints: error to real frame (cm)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def accuracy_plots(acc: Accuracy, out_dir: Path) -> dict[str, str]:
    """Write the accuracy PNGs; returns {key: file name}."""
    out_dir.mkdir(parents=True, exist_ok=True)
    plots = {
        "reach": "reach_error.png",
        "mpjpe": "mpjpe_distributions.png",
        "samples": "sample_poses.png",
        "ablation": "composition_ablation.png",
        "paths": "drag_paths.png",
    }
    plot_reach(acc.results, out_dir / plots["reach"])
    plot_mpjpe(acc.mpjpe, out_dir / plots["mpjpe"])
    if acc.samples:
        plot_samples(acc.samples, out_dir / plots["samples"])
    else:
        del plots["samples"]
    plot_ablation(acc.results, out_dir / plots["ablation"])
    if acc.paths:
        plot_paths(acc.paths, out_dir / plots["paths"])
    else:
        del plots["paths"]
    return plots


# --------------------------------------------------------------------------------------
# Goals and the markdown report
# --------------------------------------------------------------------------------------
def _f(x: Any, digits: int = 2) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return f"{x:,}"
    v = float(x)
    if v != 0 and (abs(v) < 10 ** (-digits) or abs(v) >= 1e6):
        return f"{v:.2e}"
    return f"{v:,.{digits}f}"


def _table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join(["---"] * len(headers)) + "|"]
    for row in rows:
        lines.append("| " + " | ".join(str(c) for c in row) + " |")
    return "\n".join(lines)


def _status(ok: bool | None) -> str:
    return "not measured" if ok is None else ("**met**" if ok else "**not met**")


def goals(results: Json) -> list[tuple[str, str, str, str]]:
    """(goal, target, measured, status) rows, computed from the results only."""
    rows: list[tuple[str, str, str, str]] = []
    b1, b3 = results.get("B1", {}), results.get("B3", {})
    sets = [(f"B1 {k}", v) for k, v in b1.items()] + [(f"B3 {k}", v) for k, v in b3.items()]
    if sets:
        wins = [(n, v["neural_bone"]["mpjpe"], v["fabrik"]["mpjpe"]) for n, v in sets]
        better = [w for w in wins if w[1] < w[2]]
        worst = max(wins, key=lambda w: w[1] / w[2])
        rows.append(
            (
                "Neural + bone pass beats FABRIK in MPJPE to the real pose on every B1 and B3 set",
                "all sets",
                f"{len(better)}/{len(wins)} sets; worst {worst[0]}: "
                f"{worst[1]:.2f} vs {worst[2]:.2f} cm",
                _status(len(better) == len(wins)),
            )
        )
        cw = [
            (n, v["neural_bone"]["chain"], v["fabrik"]["chain"])
            for n, v in sets
            if v["neural_bone"]["chain"] is not None
        ]
        rows.append(
            (
                "(info) chain MPJPE: neural + bone pass below FABRIK",
                "–",
                f"{sum(c[1] < c[2] for c in cw)}/{len(cw)} sets",
                "info",
            )
        )
    if FIVE in b1:
        n5, f5 = b1[FIVE]["neural_bone"]["mpjpe"], b1[FIVE]["fabrik"]["mpjpe"]
        rows.append(
            (
                "5-target composed: neural + bone MPJPE ≤ 0.7 × FABRIK's",
                "≤ 0.70",
                f"{n5:.2f} / {f5:.2f} cm = {n5 / f5:.2f}",
                _status(n5 <= 0.7 * f5),
            )
        )
        r5 = b1[FIVE]["neural_bone"]["reach_mean"]
        rows.append(
            (
                "5-target composed reach error, soft method (neural + bone pass), mean",
                "≤ 2 cm",
                f"{r5:.2f} cm (median {b1[FIVE]['neural_bone']['reach_median']:.2f}, "
                f"p95 {b1[FIVE]['neural_bone']['reach_p95']:.2f})",
                _status(r5 <= 2.0),
            )
        )
    if sets:
        exact = [(n, v["neural_exact"]) for n, v in sets]
        reach_ok = [(n, e) for n, e in exact if e["reachable_reach_max"] is not None]
        worst_n, worst_e = max(reach_ok, key=lambda ne: ne[1]["reachable_reach_max"])
        share = min(e["reachable_within_1mm"] for _, e in reach_ok)
        flagged = float(np.mean([e["reachable_pct"] for _, e in reach_ok]))
        all_max = max(e["reach_max"] for _, e in exact)
        rows.append(
            (
                "Exact reach ≤ 1 mm on reachable targets (B1 + B3; reachable = inside its "
                "chain's reach shell around the start pelvis)",
                "≤ 1 mm",
                f"max {worst_e['reachable_reach_max'] * 10:.3f} mm ({_short(worst_n)}); worst "
                f"set {share:.1f}% within 1 mm; {flagged:.1f}% of targets flagged reachable; "
                f"max over all targets {all_max * 10:.1f} mm",
                _status(worst_e["reachable_reach_max"] <= 0.1 + 1e-9),
            )
        )
        bone = max(
            v[m]["bone_max"] for _, v in sets for m in ("fabrik", "neural_bone", "neural_exact")
        )
        rows.append(
            (
                "Bone-length error (relative, max over B1 + B3, FABRIK and neural + bone/exact)",
                "≤ 1e-5",
                f"{bone:.2e}",
                _status(bone <= 1e-5),
            )
        )
    b2 = results.get("B2", {})
    if b2:
        first = next(iter(b2.values()))
        rows.append(
            (
                "6-point completion MPJPE (level 1)",
                "≤ 4 cm",
                f"{first['neural']['mpjpe']:.2f} cm",
                _status(first["neural"]["mpjpe"] <= 4.0),
            )
        )
    speed = results.get("speed", {})
    lat = {(r["targets"], r["method"]): r for r in speed.get("latency", [])}
    ratios = speed.get("ratio", {})
    if ratios:
        worst_ratio = min(ratios.values())
        rows.append(
            (
                "Neural ≥ 10× faster than FABRIK, one thread (p50 ratio, 1/2/5 targets)",
                "≥ 10×",
                ", ".join(f"{k} targets {v:.1f}×" for k, v in ratios.items()),
                _status(worst_ratio >= 10.0),
            )
        )
    else:
        rows.append(("Neural ≥ 10× faster than FABRIK, one thread", "≥ 10×", "–", _status(None)))
    for k, limit in ((2, 0.1), (5, 0.3)):
        r = lat.get((k, "neural_bone"))
        rows.append(
            (
                f"In-process {k}-target solve with the bone pass, p50 (one thread)",
                f"≤ {limit} ms",
                "–" if r is None else f"{r['p50_ms']:.3f} ms (p99 {r['p99_ms']:.3f})",
                _status(None if r is None else r["p50_ms"] <= limit),
            )
        )
    http = results.get("http", {})
    one = next((r for r in http.get("solve", []) if r["concurrency"] == 1), None)
    rows.append(
        (
            "HTTP /v1/solve on loopback, p50 (concurrency 1)",
            "≤ 2 ms",
            "–" if one is None else f"{one['p50_ms']:.2f} ms",
            _status(None if one is None else one["p50_ms"] <= 2.0),
        )
    )
    batch = http.get("batch")
    rows.append(
        (
            "HTTP /v1/solve/batch throughput",
            "≥ 20,000 poses/s",
            "–" if not batch else f"{batch['poses_per_s']:,.0f} poses/s",
            _status(None if not batch else batch["poses_per_s"] >= 20000),
        )
    )
    return rows


def _edit_tables(block: Json, bench: str) -> list[str]:
    names = list(block)
    out = []
    for metric, title in (
        ("mpjpe", "MPJPE to the real pose, all joints (cm, mean)"),
        ("chain", "Chain MPJPE: untargeted joints between each target and the pelvis (cm)"),
        ("untargeted", "MPJPE of the untargeted joints (cm)"),
        ("reach_mean", "Reach error (cm, mean over targets)"),
    ):
        rows = [[_short(n), *[_f(block[n][m][metric]) for m in METHODS]] for n in names]
        out += [
            f"**{bench} — {title}**",
            "",
            _table(["set", *[METHOD_LABEL[m] for m in METHODS]], rows),
            "",
        ]
    detail_rows = []
    for n in names:
        for m in METHODS:
            s = block[n][m]
            detail_rows.append(
                [
                    _short(n),
                    METHOD_LABEL[m],
                    s["n"],
                    _f(s["reach_mean"]),
                    _f(s["reach_median"]),
                    _f(s["reach_p95"]),
                    _f(s["reach_within_1cm"], 1),
                    f"{_f(s['reachable_pct'], 1)} / {_f(s['reachable_within_1mm'], 1)}",
                    _f(s["mpjpe"]),
                    _f(s["untargeted"]),
                    _f(s["chain"]),
                    _f(s["drift"]),
                    _f(s["bone_max"], 6),
                    _f(s["floor_mean"], 3),
                    _f(s["floor_over_1cm"], 1),
                    _f(s["seconds"], 2),
                ]
            )
    out += [
        f"<details><summary>{bench}: every metric</summary>",
        "",
        _table(
            [
                "set",
                "method",
                "n",
                "reach mean",
                "reach median",
                "reach p95",
                "% ≤ 1 cm",
                "% reachable / of those % ≤ 1 mm",
                "MPJPE",
                "MPJPE untargeted",
                "chain MPJPE",
                "drift from start",
                "max bone err",
                "floor pen. mean (cm)",
                "% floor pen. > 1 cm",
                "solve s (batch)",
            ],
            detail_rows,
        ),
        "",
        "</details>",
        "",
    ]
    return out


def render_report(results: Json, plots: dict[str, str], title: str) -> str:
    """The markdown report: every table is generated from ``results``."""
    md: list[str] = [f"# {title}", ""]
    models, data = results.get("models", {}), results.get("dataset", {})
    mach = results.get("machine_start", {})
    cfg = results.get("config", {})
    md += [
        f"Generated {results.get('generated', '')} by `{results.get('command', '')}`. "
        "Every number below was measured in this one run (nothing is copied from elsewhere).",
        "",
        f"- Models: `{models.get('dir')}` (manifest `{models.get('version')}`; service default "
        f"composition `{models.get('composition')}`, "
        f"{models.get('composition_projections')} projection(s), "
        f"{models.get('composition_passes')} pass(es)).",
        f"- Data: TEST split of `{data.get('path')}`: {_f(data.get('test_frames'))} frames in "
        f"{_f(data.get('test_clips'))} clips never seen in training.",
        f"- Sample sizes: {cfg.get('edits')} B1 edits (the same pose pairs for every set), "
        f"{cfg.get('random_edits')} B3 edits per subset size, {cfg.get('completions')} B2 "
        f"poses per level, {cfg.get('paths')} B4 paths × {cfg.get('path_frames')} frames, "
        f"{cfg.get('stress')} B5 items per case; seed {cfg.get('seed')}.",
        f"- Machine: {mach.get('cpus')} CPUs, load average at start {mach.get('loadavg')} "
        f"(end {results.get('machine_end', {}).get('loadavg')}); Python "
        f"{mach.get('python')}, numpy {mach.get('numpy')}, onnxruntime "
        f"{mach.get('onnxruntime')}.",
        f"- Wall time (s): {results.get('seconds', {})}.",
        "",
        "## Goals",
        "",
        _table(["goal", "target", "measured", "status"], goals(results)),
        "",
        "## Accuracy (TEST split)",
        "",
        "Methods: *identity* returns the start pose; *FABRIK* is the service's "
        "`method=fabrik` (full-body FABRIK from the start pose, no learned prior); "
        "*neural raw* is `preserve_bone_lengths=false`; *neural + bone pass* is the default "
        "(`reach=soft`); *neural + exact reach* is `reach=exact` (FABRIK polish, 1 mm "
        "tolerance). All distances in cm. Bone errors are relative to the start pose's bone "
        "lengths. *Drift* is the mean distance of the untargeted joints from the start pose; "
        "*floor pen.* is how far the lowest ankle/foot joint is below y = 0.",
        "",
    ]
    if "B1" in results:
        md += [
            "### B1 — edits (start and target pose of one clip, 0.2–1 s apart)",
            "",
            "Single-target edits are ambiguous (the rest of the body also moved between the "
            "two frames), so the chain MPJPE is the fairer view there.",
            "",
            *_edit_tables(results["B1"], "B1"),
        ]
        for key, caption in (
            ("reach", "Reach error by method and target set"),
            ("mpjpe", "MPJPE distributions"),
            ("samples", "Sample solved poses"),
        ):
            if key in plots:
                md += [f"![{caption}]({plots[key]})", ""]
    if "B3" in results:
        md += [
            "### B3 — random subsets of 1–6 solver joints (composition beyond trained sets)",
            "",
            *_edit_tables(results["B3"], "B3"),
        ]
    if results.get("B2"):
        rows = []
        for name, lvl in results["B2"].items():
            for m in ("rest_fabrik", "neural"):
                s = lvl[m]
                rows.append(
                    [
                        name,
                        "rest pose + FABRIK" if m == "rest_fabrik" else "completion",
                        s["n"],
                        _f(s["mpjpe"]),
                        _f(s["untargeted"]),
                        f"{_f(s['reach_mean'])} / {_f(s['reach_max'])}",
                        _f(s["bone_vs_real_mean"], 4),
                        _f(s["floor_mean"], 3),
                        _f(lvl["ms_per_call"]) if m == "neural" else "–",
                    ]
                )
        md += [
            "### B2 — completion from key points only",
            "",
            "Key points are the real pose's joints of each completion level (from the "
            "manifest); no bone lengths are given, so the service uses the completion "
            "network's own estimate of the body's proportions. The "
            "baseline FABRIKs the reference rest pose (moved onto the pelvis) onto the "
            "key points.",
            "",
            _table(
                [
                    "level",
                    "method",
                    "n",
                    "MPJPE",
                    "MPJPE non-key joints",
                    "key-point error mean / max",
                    "bone length vs real (mean rel.)",
                    "floor pen. mean",
                    "ms per call",
                ],
                rows,
            ),
            "",
        ]
    if results.get("B4"):
        b4 = results["B4"]
        rows = []
        for name in (k for k in b4 if isinstance(b4[k], dict)):
            for m, s in b4[name].items():
                rows.append(
                    [
                        _short(name),
                        METHOD_LABEL[m],
                        _f(s["jitter"]),
                        _f(s["jitter_untargeted"]),
                        _f(s["reach_mean"], 3),
                        _f(s["mpjpe"]),
                        f"{_f(s['untargeted_first'])} → {_f(s['untargeted_last'])}",
                        _f(s["bone_max"], 6),
                    ]
                )
        md += [
            "### B4 — drag paths",
            "",
            f"{b4['paths']} test clips, {b4['frames']} consecutive frames each (30 fps); "
            "targets follow the clip frame by frame and every solve starts from the previous "
            "result. Jitter = mean joint acceleration |p[t+1] − 2p[t] + p[t−1]| × fps² "
            f"(m/s²); the real clips have {_f(b4['real_jitter'])} m/s². Drift = error of the "
            "untargeted joints to the real frame, first vs last 10 steps.",
            "",
            _table(
                [
                    "targets",
                    "method",
                    "jitter (m/s²)",
                    "jitter untargeted",
                    "reach mean (cm)",
                    "MPJPE (cm)",
                    "untargeted error first → last (cm)",
                    "max bone err",
                ],
                rows,
            ),
            "",
        ]
        if "paths" in plots:
            md += [f"![B4 drift along drag paths]({plots['paths']})", ""]
    if results.get("B5"):
        b5 = results["B5"]
        rows = []
        for case, block in b5.items():
            for m in _stress_methods():
                s = block[m]
                rows.append(
                    [
                        case,
                        METHOD_LABEL[m],
                        _f(s["finite"], 1),
                        _f(s["reach_mean"]),
                        _f(s["mpjpe"]),
                        _f(s.get("max_dev_mm"), 4),
                        _f(s.get("bone_max_world", s["bone_max"]), 6),
                    ]
                )
        notes = [
            f"- *{case}*: {block['transform']}"
            for case, block in b5.items()
            if "transform" in block
        ]
        if "beyond_arm_cm" in b5.get("unreachable (2x arm length)", {}):
            notes.append(
                "- unreachable targets lie on average "
                f"{_f(b5['unreachable (2x arm length)']['beyond_arm_cm'])} cm beyond the "
                "straight arm from the shoulder, so that is roughly the best possible error "
                "without moving the trunk."
            )
        md += [
            "### B5 — stress",
            "",
            f"Base problems: the first {cfg.get('stress')} B1 five-end-effector edits. The "
            "scaled and moved cases are the same problems, so their results are mapped back "
            "to the canonical frame and compared with the canonical run (*max deviation*); "
            "their MPJPE/reach are in canonical-size centimetres.",
            "",
            *notes,
            "",
            _table(
                [
                    "case",
                    "method",
                    "% finite",
                    "reach mean (cm)",
                    "MPJPE (cm)",
                    "max deviation from canonical (mm)",
                    "max bone err",
                ],
                rows,
            ),
            "",
        ]
    if results.get("determinism"):
        det = results["determinism"]
        rows = [
            [METHOD_LABEL[m], _f(v["repeat_bitwise_equal"]), _f(v["single_vs_batch_max_abs_m"], 3)]
            for m, v in det.items()
            if isinstance(v, dict)
        ]
        md += [
            "### Determinism",
            "",
            f"{det['n']} B1 five-target edits solved twice as identical batches (bits "
            "compared), and the first ones also solved one by one.",
            "",
            _table(["method", "repeat bit-identical", "one-by-one vs batch max |Δ| (m)"], rows),
            "",
        ]
    if results.get("ablation"):
        abl = results["ablation"]
        rows = []
        for p, row in abl.items():
            for key in (f"B1 {FIVE}", "B3 2+ joints"):
                for m in ("neural_raw", "neural_bone"):
                    s = row[f"{key}|{m}"]
                    rows.append(
                        [
                            p,
                            key,
                            METHOD_LABEL[m],
                            s["n"],
                            _f(s["reach_mean"]),
                            _f(s["reach_p95"]),
                            _f(s["mpjpe"]),
                            _f(s["chain"]),
                        ]
                    )
        md += [
            "### Composition ablation",
            "",
            "How a target set no single solver covers is served. *sequential (paper)*: "
            "ẑ = S_t3(S_t2(S_t1(z))); *passes*: cycles through that sequence; *re-encode*: "
            "before each later solver, decode, paste the targets solved so far and "
            "re-encode; *projections*: rounds of paste-all-targets and re-encode at the end "
            "(docs/service.md). Same edits as B1 (five end effectors) and B3 (subsets of 2 or "
            "more joints).",
            "",
            _table(
                [
                    "strategy",
                    "set",
                    "method",
                    "n",
                    "reach mean",
                    "reach p95",
                    "MPJPE",
                    "chain MPJPE",
                ],
                rows,
            ),
            "",
        ]
        if "ablation" in plots:
            md += [f"![Composition ablation]({plots['ablation']})", ""]
    md += _speed_sections(results, plots)
    mb = models.get("bytes")
    if mb:
        md += [
            "## Model size on disk",
            "",
            _table(
                ["bundle", "bytes", "kB", "paper"],
                [
                    [
                        "2-target set (" + " + ".join(mb["two_target_files"]) + ")",
                        _f(mb["two_target_set"]),
                        _f(mb["two_target_set"] / 1000, 0),
                        "442 kB",
                    ],
                    [
                        "autoencoder + every solver",
                        _f(mb["solvers_and_autoencoder"]),
                        _f(mb["solvers_and_autoencoder"] / 1000, 0),
                        "826 kB (full body)",
                    ],
                    [
                        f"all {mb['files']} model files (incl. completion)",
                        _f(mb["all_models"]),
                        _f(mb["all_models"] / 1000, 0),
                        "–",
                    ],
                ],
            ),
            "",
        ]
    return "\n".join(md).rstrip() + "\n"


def _speed_sections(results: Json, plots: dict[str, str]) -> list[str]:
    speed, http = results.get("speed"), results.get("http")
    if not speed and not http:
        return ["## Speed", "", "Not measured in this run (run `make bench`).", ""]
    md: list[str] = ["## Speed", ""]
    if results.get("http_error"):
        md += [f"**The HTTP part failed:** `{results['http_error']}`", ""]
    if speed:
        rows = [
            [
                r["targets"],
                _short(r["set"]),
                METHOD_LABEL[r["method"]],
                r["n"],
                _f(r["p50_ms"], 3),
                _f(r["p99_ms"], 3),
                _f(r["mean_ms"], 3),
            ]
            for r in speed["latency"]
        ]
        md += [
            "### In-process latency (one thread)",
            "",
            "`Engine(threads=1).solve([problem])` per call on B1 edits (a different edit "
            "each call), the neural and FABRIK runs interleaved in the same loop.",
            "",
            _table(
                ["targets", "set", "method", "calls", "p50 (ms)", "p99 (ms)", "mean (ms)"], rows
            ),
            "",
            "FABRIK p50 / neural + bone pass p50: "
            + ", ".join(f"{k} targets **{v:.1f}×**" for k, v in speed["ratio"].items()),
            "",
        ]
        if "latency" in plots:
            md += [f"![Latency neural vs FABRIK]({plots['latency']})", ""]
        rows = [
            [
                r["batch"],
                METHOD_LABEL[r["method"]],
                r["items"],
                _f(r["seconds"], 3),
                _f(r["poses_per_s"], 0),
            ]
            for r in speed["throughput"]
        ]
        md += [
            "### In-process batch throughput (one thread)",
            "",
            f"One `Engine.solve` call per batch ({speed.get('throughput_set', '')}).",
            "",
            _table(["batch size", "method", "poses", "seconds", "poses/s"], rows),
            "",
        ]
        if "throughput" in plots:
            md += [f"![Throughput vs batch size]({plots['throughput']})", ""]
    if http:
        rows = [
            [
                r["concurrency"],
                r["requests"],
                r["errors"],
                _f(r["p50_ms"]),
                _f(r["p99_ms"]),
                _f(r["rps"], 0),
                _f(r["seconds"], 1),
            ]
            for r in http["solve"]
        ]
        b = http.get("batch") or {}
        rss = http.get("rss_kb", {})
        md += [
            "### HTTP (uvicorn on loopback)",
            "",
            f"`{http.get('server')}` as a subprocess on 127.0.0.1, one worker "
            "(POSE_ORT_THREADS=1). Load generator: a raw asyncio HTTP/1.1 client in the "
            "benchmark process (bench/http_load.py), closed loop, one kept-alive "
            "connection per unit of concurrency, bounded in "
            f"requests and time ({http.get('limits')}); requests pre-built, answers read "
            "in full (status checked, bodies not parsed). "
            "The client shares the machine's "
            f"{results.get('machine_start', {}).get('cpus')} CPUs with the server.",
            "",
            f"/v1/solve ({http.get('solve_set')}):",
            "",
            _table(
                [
                    "concurrency",
                    "requests",
                    "errors",
                    "p50 (ms)",
                    "p99 (ms)",
                    "requests/s",
                    "seconds",
                ],
                rows,
            ),
            "",
        ]
        if b:
            md += [
                f"/v1/solve/batch: {b['batches']} batches of {b['batch_size']} items at "
                f"concurrency {b['concurrency']}: **{b['poses_per_s']:,.0f} poses/s** "
                f"(p50 {b['p50_ms']:.0f} ms per batch, {b['errors']} errors).",
                "",
            ]
        if rss:
            md += [
                "Service RSS (VmRSS from /proc): "
                + ", ".join(f"{k.replace('_', ' ')} {v / 1024:.1f} MiB" for k, v in rss.items())
                + ".",
                "",
            ]
    return md


def write_json(results: Json, path: Path) -> None:
    import json

    path.write_text(json.dumps(results, indent=1, default=float) + "\n")


def write_accuracy_report(acc: Accuracy, out_dir: Path, command: str) -> Path:
    """``pose-trainer evaluate``: accuracy.md + accuracy.json + the accuracy plots."""
    out_dir.mkdir(parents=True, exist_ok=True)
    acc.results["machine_end"] = machine()
    acc.results["generated"] = time.strftime("%Y-%m-%d %H:%M:%S %Z")
    acc.results["command"] = command
    plots = accuracy_plots(acc, out_dir)
    write_json(acc.results, out_dir / "accuracy.json")
    md = render_report(acc.results, plots, "Marionette accuracy report")
    path = out_dir / "accuracy.md"
    path.write_text(md)
    return path
