"""A few-target edit's pelvis held near the start's (``serving.keep_pelvis``): the
networks' move of the pelvis loses ``keep_pelvis`` metres of its length before the bone
pass, in edits of fewer than ``turn_min_targets`` targets none of which is on the pelvis;
other edits are answered as without it, bit for bit; lengths hold; batch = single."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX
from service.engine import Engine
from service.problems import SolveProblem, SolveResult
from tests.conftest import PosePairs, on_random_bodies

PELVIS = JOINT_INDEX["pelvis"]
ONE_PASS = {"solve_passes": 1, "retry_reach": 0.0}


@pytest.fixture(scope="module")
def pairs(real_poses: PosePairs) -> tuple[np.ndarray, np.ndarray]:
    """Real (start, goal) pairs rebuilt on random asymmetric bodies, one per pair."""
    return on_random_bodies(real_poses, 13)


def _problems(starts: np.ndarray, goals: np.ndarray, names: tuple[str, ...]) -> list[SolveProblem]:
    idx = np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)
    return [
        SolveProblem(
            pose=s, target_idx=idx, target_pos=g[idx], weights=np.ones(len(idx)), n_targets=len(idx)
        )
        for s, g in zip(starts, goals, strict=True)
    ]


def _moves(results: list[SolveResult], starts: np.ndarray) -> np.ndarray:
    """How far each answer's pelvis lies from its start's (m)."""
    poses = np.stack([r.pose for r in results])
    return np.asarray(np.linalg.norm(poses[:, PELVIS] - starts[:, PELVIS], axis=-1))


def test_the_pelvis_move_loses_keep_pelvis_of_its_length(
    models_dir: Path, pairs: tuple[np.ndarray, np.ndarray], client: Any
) -> None:
    r = 0.005
    off, near, held = (Engine(models_dir, keep_pelvis=x, **ONE_PASS) for x in (0.0, r, 1.0))
    assert client.get("/v1/models").json()["keep_pelvis"] == off.manifest.serving.keep_pelvis
    start, goal = pairs
    for names in (("left_elbow",), ("head", "right_knee")):
        probs = _problems(start, goal, names)
        move = [_moves(e.solve(probs), start) for e in (off, near, held)]
        assert 0.1 < np.mean(move[0] > r) < 0.9  # the networks move it, some of it farther
        # one pass, no retry: the same network answer, its pelvis move shortened by r
        np.testing.assert_allclose(move[1], np.maximum(move[0] - r, 0.0), atol=1e-9)
        assert move[2].max() < 1e-9
        for e in (near, held):
            assert max(r.max_bone_error for r in e.solve(probs)) <= 1e-5
    # exact reach still reaches: its FABRIK polish starts from the held pose
    exact = [dataclasses.replace(p, reach="exact") for p in _problems(start, goal, ("left_wrist",))]
    assert all(r.errors.max() <= p.tolerance for p, r in zip(exact, held.solve(exact), strict=True))


def test_edits_on_the_pelvis_or_of_many_targets_are_as_without_it(
    models_dir: Path, pairs: tuple[np.ndarray, np.ndarray]
) -> None:
    off, held = (Engine(models_dir, keep_pelvis=r) for r in (0.0, 1.0))
    start, goal = pairs
    ends = ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")
    for names in (("pelvis",), ("pelvis", "left_wrist"), ends):
        probs = _problems(start[:24], goal[:24], names)
        for a, b in zip(off.solve(probs), held.solve(probs), strict=True):
            assert np.array_equal(a.pose, b.pose)


def test_a_mixed_batch_answers_each_item_as_alone(
    models_dir: Path, pairs: tuple[np.ndarray, np.ndarray]
) -> None:
    engine = Engine(models_dir, keep_pelvis=0.02)
    start, goal = pairs
    probs = [
        p
        for names in (("left_elbow",), ("pelvis",), ("left_wrist", "right_ankle"))
        for p in _problems(start[:6], goal[:6], names)
    ]
    for p, r in zip(probs, engine.solve(probs), strict=True):
        assert np.array_equal(engine.solve([p])[0].pose, r.pose)
