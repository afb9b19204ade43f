"""Per-item accuracy metrics of solved edits and their summaries (centimetres unless
stated; bone-length error is relative to the start pose)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from bench.edits import CM, FLOOR_JOINTS, Edits, joint_idx
from core.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS, bone_lengths, chain_to_root

F64 = npt.NDArray[np.floating[Any]]
IntArray = npt.NDArray[np.intp]
Json = dict[str, Any]


def chain_of(joints: IntArray) -> IntArray:
    """The untargeted joints between each target joint and the pelvis."""
    names = {JOINT_NAMES[int(j)] for j in joints}
    chain = {c for n in names for c in chain_to_root(n)} - names
    return joint_idx(sorted(chain, key=JOINT_INDEX.__getitem__))


def root_reach(start: F64) -> tuple[F64, F64]:
    """``[N, 21]`` shortest and longest distance from the root (pelvis) at which each joint
    can be placed with the root held: the reach shell of its chain of bones."""
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
    shortest, longest = root_reach(edits.start)
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
            c = chain_of(j)
            chain.append(diff_goal[i, c].mean() if len(c) else np.nan)
    start_len = bone_lengths(edits.start)
    bone = np.abs(bone_lengths(poses) / start_len - 1.0).max(axis=-1)
    floor = np.maximum(0.0, -poses[:, joint_idx(FLOOR_JOINTS), 1].min(axis=-1))
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
    """The summary row of one method on one set (the keys the report tables read)."""
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


#: Resamples of :func:`paired_interval` and their seed (the interval is the same every run).
BOOTSTRAP_ROUNDS = 2000
BOOTSTRAP_SEED = 0


def paired_interval(a: F64, b: F64, level: float = 0.95) -> tuple[float, float, float]:
    """The mean of ``a - b`` over the same items (e.g. two methods' MPJPE on one edit set)
    and its ``level`` percentile bootstrap interval: whether one method's lower mean is a
    real difference or within what the sample of edits allows. Seeded; ties give (0, 0, 0)."""
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    if d.size == 0:
        return math.nan, math.nan, math.nan
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    means = d[rng.integers(0, d.size, size=(BOOTSTRAP_ROUNDS, d.size))].mean(axis=1)
    tail = (1.0 - level) / 2 * 100
    lo, hi = np.percentile(means, [tail, 100 - tail])
    return float(d.mean()), float(lo), float(hi)
