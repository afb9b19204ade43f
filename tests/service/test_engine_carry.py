"""The carry below targets in the engine (``serving.carry``): only the branch below a
targeted joint changes, bone lengths and exact reach hold, answers stay bit-identical,
and on bodies the models never saw the branch lands nearer the real pose."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX
from service.engine import Engine
from service.problems import SolveProblem
from tests.conftest import PosePairs, on_random_bodies

ELBOW, WRIST = JOINT_INDEX["left_elbow"], JOINT_INDEX["left_wrist"]


@pytest.fixture(scope="module")
def engines(models_dir: Path) -> tuple[Engine, Engine]:
    kw = {"passes": 1, "retry_reach": 0.0}  # one pass, no retry: the carry alone
    return Engine(models_dir, serving={"carry": 0.0, **kw}), Engine(models_dir, serving=kw)


@pytest.fixture(scope="module")
def pairs(real_poses: PosePairs) -> tuple[np.ndarray, np.ndarray]:
    """Real (start, goal) pairs rebuilt on random asymmetric bodies, one per pair."""
    return on_random_bodies(real_poses, 7)


def _problems(
    starts: np.ndarray, goals: np.ndarray, names: tuple[str, ...], reach: str = "soft"
) -> list[SolveProblem]:
    idx = np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)
    return [
        SolveProblem(pose=s, target_idx=idx, target_pos=g[idx], weights=np.ones(len(idx)),
                     n_targets=len(idx), reach=reach)  # type: ignore[arg-type]
        for s, g in zip(starts, goals, strict=True)
    ]  # fmt: skip


def test_shipped_models_carry(engines: tuple[Engine, Engine]) -> None:
    assert engines[1].serving.carry == engines[1].manifest.serving.carry > 0.0
    with pytest.raises(ValueError, match="carry"):
        Engine(engines[0].models_dir, serving={"carry": 1.5})


def test_only_the_branch_below_the_target_moves(
    engines: tuple[Engine, Engine], pairs: tuple[np.ndarray, np.ndarray]
) -> None:
    plain, carried = engines
    start, goal = pairs
    probs = _problems(start[:40], goal[:40], ("left_elbow",))
    a = np.stack([r.pose for r in plain.solve(probs)])
    b = np.stack([r.pose for r in carried.solve(probs)])
    others = np.setdiff1d(np.arange(21), [WRIST])
    assert np.array_equal(a[:, others], b[:, others])
    assert np.abs(a[:, WRIST] - b[:, WRIST]).max() > 0.01
    # the forearm keeps its length: the wrist turned about the elbow
    fore = np.linalg.norm(start[:40, WRIST] - start[:40, ELBOW], axis=-1)
    assert np.abs(np.linalg.norm(b[:, WRIST] - b[:, ELBOW], axis=-1) / fore - 1).max() < 1e-9


def test_carry_lands_nearer_the_real_pose(
    engines: tuple[Engine, Engine], pairs: tuple[np.ndarray, np.ndarray]
) -> None:
    """Knee and elbow edits on bodies never trained on: what hangs below the dragged joint
    (ankle and foot, wrist) ends nearer the real goal pose with the carry than without."""
    start, goal = pairs
    for names, below in ((("left_knee",), ("left_ankle", "left_foot")), (("right_elbow",),
                         ("right_wrist",))):  # fmt: skip
        idx = [JOINT_INDEX[n] for n in below]
        errs = []
        for engine in engines:
            out = np.stack([r.pose for r in engine.solve(_problems(start, goal, names))])
            errs.append(float(np.linalg.norm(out[:, idx] - goal[:, idx], axis=-1).mean()))
        assert errs[1] < errs[0], (names, errs)


def test_exact_reach_bones_and_bit_identical(
    engines: tuple[Engine, Engine], pairs: tuple[np.ndarray, np.ndarray]
) -> None:
    carried = engines[1]
    start, goal = pairs
    mixed = (
        _problems(start[:12], goal[:12], ("right_knee",), reach="exact")
        + _problems(start[12:24], goal[12:24], ("left_elbow", "right_ankle"))
        + _problems(start[24:36], goal[24:36], ("head", "left_elbow"), reach="exact")
    )
    batch = carried.solve(mixed)
    missed = []
    for p, r in zip(mixed, batch, strict=True):
        assert r.max_bone_error <= 1e-5
        if p.reach == "exact":
            assert np.array_equal(r.reached, r.errors <= p.tolerance)
            if not r.reached.all():
                missed.append(float(r.errors.max()))
        (single,) = carried.solve([p])
        assert np.array_equal(single.pose, r.pose)
    # every exact target met but one of the 24 edits, whose polish and FABRIK fallback both
    # stall short of it (since the models of docs/generalisation-3.md item 50: a head and a
    # left elbow on a random body, 1.9 mm, flagged not reached; all met before)
    assert len(missed) <= 1 and max(missed, default=0.0) < 2.5e-3, missed
