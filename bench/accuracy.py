"""Accuracy of the served pipeline on the TEST split: B1-B5, determinism and the
composition ablation.

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

Metrics are in centimetres unless stated. The results are a JSON-able dict that
:mod:`bench.report` renders; :class:`Accuracy` also keeps the per-item arrays the plots
need.
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

from bench.edits import (
    CM,
    COMPOSED5,
    END_EFFECTORS,
    FIVE,
    FLOOR_JOINTS,
    LIMBS5,
    METHODS,
    TOLERANCE,
    Edits,
    b1_sets,
    edits_from_pairs,
    joint_idx,
    pooled,
    sample_pairs,
    solve,
    solver_joints,
    test_split,
)
from bench.metrics import per_item, summarise
from core import kinematics
from core.geometry import yaw_matrix
from core.rest import rest_pose
from core.skeleton import JOINT_INDEX, NUM_JOINTS, bone_lengths
from service.engine import Engine
from trainer.data.dataset import FPS, PoseDataset, load_dataset

F64 = npt.NDArray[np.floating[Any]]
Json = dict[str, Any]
#: Methods of the B5 stress tables.
STRESS_METHODS: tuple[str, ...] = ("fabrik", "neural_raw", "neural_bone", "neural_exact")


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


@dataclass
class Accuracy:
    """Results (JSON-able) plus the per-item arrays the plots need."""

    results: Json
    mpjpe: dict[str, dict[str, F64]] = field(default_factory=dict)  # set -> method -> items
    samples: list[Json] = field(default_factory=list)  # for the sample-poses figure
    paths: Json = field(default_factory=dict)  # B4 per-step curves


def _log(msg: str) -> None:
    print(f"[bench {time.strftime('%H:%M:%S')}] {msg}", flush=True)


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
            np.sort(joint_idx([pool[int(j)] for j in rng.choice(len(pool), size=k, replace=False)]))
            for _ in range(len(a))
        ]
        sets[f"{k} joint{'s' if k > 1 else ''}"] = edits_from_pairs(test, a, b, joint_sets)
    return sets


def eval_completion(engine: Engine, test: PoseDataset, cfg: EvalConfig, acc: Accuracy) -> Json:
    """B2: a pose from key points only; baseline: the rest pose FABRIK'd onto them."""
    rng = np.random.default_rng(cfg.seed + 2)
    ref = engine.reference_lengths
    rest = np.asarray(kinematics.bone_pass(rest_pose(), ref), dtype=np.float64)
    out: Json = {}
    for level, entry in enumerate(engine.manifest.completion_levels(), start=1):
        rows = rng.choice(len(test), size=min(cfg.completions, len(test)), replace=False)
        real = test.positions[rows].astype(np.float64)
        key = joint_idx(entry.joints)
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


#: B4's extra row: neural + bone pass with the turn search off (edits it would search).
NO_TURN = "neural_bone_no_turn"


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
        idx = joint_idx(names)
        free = np.setdiff1d(np.arange(NUM_JOINTS), idx)
        out[set_name] = {}
        methods = ["fabrik", "neural_bone", "neural_exact"]
        if engine.turn_search.searches("neural", len(idx), pinned=False):
            methods.append(NO_TURN)  # what the turn search does to a drag
        for method in methods:
            t0 = time.perf_counter()
            traj = np.empty_like(seg)
            traj[:, 0] = seg[:, 0]
            as_method, turn = ("neural_bone", False) if method == NO_TURN else (method, None)
            for t in range(1, length):
                step = Edits(traj[:, t - 1], [idx] * len(rows), list(seg[:, t][:, idx]))
                traj[:, t] = solve(engine, step, as_method, cfg.chunk, turn)
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


def eval_stress(engine: Engine, base: Edits, cfg: EvalConfig) -> Json:
    """B5. ``base`` are B1 five-end-effector edits (canonical)."""
    rng = np.random.default_rng(cfg.seed + 5)
    n = min(cfg.stress, len(base))
    canon = base.take(n)
    methods = STRESS_METHODS
    ref_poses, _ = run_methods(engine, canon, methods, cfg.chunk)
    out: Json = {"canonical": {m: summarise(per_item(canon, ref_poses[m])) for m in methods}}

    # characters of another size, and one far away facing -X: the same problems
    rest = rest_pose()
    heights = np.asarray(
        [
            stand[JOINT_INDEX["head"], 1] - stand[joint_idx(FLOOR_JOINTS), 1].min()
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

    def pick(lj: str, rj: str) -> npt.NDArray[np.intp]:
        return np.where(left, JOINT_INDEX[lj], JOINT_INDEX[rj])

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
    """Composition strategies on B1's pairs with five targets no trained set covers whole
    (``b1_five``: ``LIMBS5``) and on B3's subsets of 2 or more joints."""
    out: Json = {}
    for label, kwargs in cfg.strategies:
        engine = Engine(models_dir, threads=1, **dict(kwargs))
        inert, why = engine.inert_settings()
        if inert:  # the same answers as without those settings here
            _log(f"ablation {label}: left out, {inert} do nothing ({why})")
            continue
        row: Json = {}
        for name, edits in ((f"B1 {COMPOSED5}", b1_five), ("B3 2+ joints", b3)):
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
    models_dir: Path,
    dataset_path: Path,
    cfg: EvalConfig | None = None,
    data: PoseDataset | None = None,
) -> Accuracy:
    """Run B1-B5, determinism and the composition ablation; returns results + plot data.
    ``data``: ``dataset_path`` already read (read here if not given)."""
    cfg = cfg or EvalConfig()
    t_start = time.perf_counter()
    engine = Engine(models_dir, threads=1)
    test = test_split(load_dataset(dataset_path) if data is None else data)
    rng = np.random.default_rng(cfg.seed)
    acc = Accuracy(results={})
    res = acc.results
    res["config"] = asdict(cfg)
    res["models"] = {
        "dir": str(models_dir),
        "version": engine.version,
        "composition_passes": engine.composition_passes,
        "composition": engine.composition,
        "composition_projections": engine.projections,
        "delta": engine.serving.delta,
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
    b1 = {name: edits_from_pairs(test, a, b, [joint_idx(j)] * len(a)) for name, j in sets.items()}
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
    limbs = edits_from_pairs(test, a, b, [joint_idx(LIMBS5)] * len(a))
    res["ablation"] = eval_ablation(models_dir, limbs, pooled(b3, multi), cfg)
    res["ablation_fabrik"] = {  # the baseline on the composed five (an info goal row)
        f"B1 {COMPOSED5}": summarise(per_item(limbs, solve(engine, limbs, "fabrik", cfg.chunk)))
    }
    timings["ablation"] = time.perf_counter() - t0

    timings["total"] = time.perf_counter() - t_start
    res["seconds"] = {k: round(v, 1) for k, v in timings.items()}
    return acc
