"""Edit problems for the accuracy benchmark, and solving them through the service engine.

An edit is a start pose, target joints with their positions, and (when the targets come
from a real frame) the real pose they come from. Problems are drawn from the dataset's
TEST split (whole clips no model saw) or, for :mod:`bench.heldout`, from bodies kept out
of training. Everything is solved by :class:`service.engine.Engine` in-process, the code
the service runs, with the options of :data:`METHOD_OPTIONS`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from core.skeleton import JOINT_INDEX, NUM_JOINTS
from service.engine import Engine
from service.problems import SolveProblem
from trainer.data.dataset import FPS, PoseDataset
from trainer.pairs import partner_ranges, sample_partners

F64 = npt.NDArray[np.floating[Any]]
IntArray = npt.NDArray[np.intp]

#: Methods compared on every edit set, in table order.
METHODS: tuple[str, ...] = ("identity", "fabrik", "neural_raw", "neural_bone", "neural_exact")
METHOD_LABEL: dict[str, str] = {
    "identity": "identity",
    "fabrik": "FABRIK",
    "neural_raw": "neural raw",
    "neural_bone": "neural + bone pass",
    "neural_exact": "neural + exact reach",
    "neural_bone_no_turn": "neural + bone pass, no turn search",  # B4
    "rest_fabrik": "rest pose + FABRIK",  # B2 baseline
    "neural": "completion",  # B2
    "completion": "completion",  # held-out 6-point completion
    "completion_lengths": "completion, bone lengths given",
}
#: Engine options (method, preserve_bone_lengths, reach) of each solving method.
METHOD_OPTIONS: dict[str, tuple[str, bool, str]] = {
    "fabrik": ("fabrik", True, "soft"),
    "neural_raw": ("neural", False, "soft"),
    "neural_bone": ("neural", True, "soft"),
    "neural_exact": ("neural", True, "exact"),
}
END_EFFECTORS: tuple[str, ...] = ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")
FIVE = "5 end effectors"
#: Five targets no trained set covers whole (several solvers composed): the composition
#: ablation and issue 14's composed timing.
LIMBS5 = ("head", "left_elbow", "right_elbow", "left_knee", "right_knee")
COMPOSED5 = "head, elbows, knees"
FLOOR_JOINTS: tuple[str, ...] = ("left_ankle", "left_foot", "right_ankle", "right_foot")
TOLERANCE = 1e-3  # metres, the service's default
MIN_GAP, MAX_GAP = int(0.2 * FPS), int(1.0 * FPS)  # pair distance in frames (0.2-1 s)
CM = 100.0


def short(name: str) -> str:
    """A set name shortened for tables and plot labels."""
    return (
        name.replace("left_", "L ")
        .replace("right_", "R ")
        .replace("+", " + ")
        .replace("end effectors", "end eff.")
    )


def joint_idx(names: Sequence[str]) -> IntArray:
    """Joint indices of ``names`` (canonical skeleton) as an index array."""
    return np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)


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


def pooled(sets: dict[str, Edits], names: Sequence[str]) -> Edits:
    """The edits of several sets as one."""
    chosen = [sets[n] for n in names]
    goals = [e.goal for e in chosen if e.goal is not None]
    return Edits(
        np.concatenate([e.start for e in chosen]),
        [j for e in chosen for j in e.joints],
        [t for e in chosen for t in e.targets],
        np.concatenate(goals) if len(goals) == len(chosen) else None,
    )


def test_split(dataset: PoseDataset) -> PoseDataset:
    test = dataset.subset(dataset.split_mask("test"))
    if len(test) == 0:
        raise ValueError("the dataset's test split is empty")
    return test


def sample_pairs(data: PoseDataset, n: int, rng: np.random.Generator) -> tuple[IntArray, IntArray]:
    """``n`` (start, target) row pairs of the same clip, 0.2-1 s apart (``trainer.pairs``,
    the training pair sampler). Rows must be sorted by (clip, frame), as in the dataset."""
    if len(data) == 0:
        raise ValueError("no frames to sample edits from")
    lo, hi = partner_ranges(data.clip, data.frame, MAX_GAP)
    starts: list[IntArray] = []
    goals: list[IntArray] = []
    have = 0
    for _ in range(64):
        anchors = rng.integers(0, len(data), size=max(2 * (n - have), 16)).astype(np.int64)
        partners = sample_partners(lo, hi, anchors, rng, frame=data.frame, min_gap=MIN_GAP)
        ok = partners != anchors
        starts.append(anchors[ok].astype(np.intp))
        goals.append(partners[ok].astype(np.intp))
        have += int(ok.sum())
        if have >= n:
            break
    a, b = np.concatenate(starts)[:n], np.concatenate(goals)[:n]
    if len(a) < n:
        raise ValueError(f"could only sample {len(a)} of {n} frame pairs 0.2-1 s apart")
    return a, b


def edits_from_pairs(
    test: PoseDataset, a: IntArray, b: IntArray, joint_sets: Sequence[IntArray]
) -> Edits:
    """Canonical edits (B1): rows ``a`` are the start poses, rows ``b`` the real poses."""
    start = test.positions[a].astype(np.float64)
    goal = test.positions[b].astype(np.float64)
    joints = [np.asarray(j, dtype=np.intp) for j in joint_sets]
    return Edits(start, joints, [goal[i, j] for i, j in enumerate(joints)], goal)


def b1_sets(engine: Engine) -> dict[str, tuple[str, ...]]:
    """B1 target sets: every trained single joint, every trained pair, the five end
    effectors (one trained solver, or composed where the models have none for them)."""
    solvers = engine.manifest.solvers()
    singles = {k: tuple(e.joints) for k, e in solvers.items() if len(e.joints) == 1}
    multi = {
        k: tuple(e.joints)
        for k, e in solvers.items()
        if len(e.joints) > 1 and set(e.joints) != set(END_EFFECTORS)  # that one is FIVE
    }
    return {**singles, **multi, FIVE: END_EFFECTORS}


def solver_joints(engine: Engine) -> list[str]:
    """Joints with a trained single-joint solver (the B3 pool)."""
    return [e.joints[0] for e in engine.manifest.solvers().values() if len(e.joints) == 1]


def problems(
    edits: Edits, method: str, turn_search: bool | None = None, soft_ik: float = 0.0
) -> list[SolveProblem]:
    """The engine problems of ``edits`` for one solving method (``METHOD_OPTIONS``;
    ``turn_search``: the option of every problem, None: the models' default; ``soft_ik``:
    every problem's)."""
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
            turn_search=turn_search,
            soft_ik=soft_ik,
        )
        for i in range(len(edits))
    ]


def solve(
    engine: Engine, edits: Edits, method: str, chunk: int = 2048,
    turn_search: bool | None = None, soft_ik: float = 0.0,
) -> F64:  # fmt: skip
    """Solved poses ``[N, 21, 3]`` (world, as given) of one method."""
    if method == "identity":
        return edits.start.copy()
    probs = problems(edits, method, turn_search, soft_ik)
    out: list[F64] = []
    for s in range(0, len(probs), chunk):
        out.extend(r.pose for r in engine.solve(probs[s : s + chunk]))
    return np.stack(out) if out else np.zeros((0, NUM_JOINTS, 3))
