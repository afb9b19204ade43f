"""``serving.turn_gate`` (service.turns): an edit that may search its turn searches only if
its targets lie at least that far across from their joints; nearer, it is solved from its
start, bit for bit as without a search, on the lone-edit path too."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX
from service.engine import Engine
from service.problems import SolveProblem, _Items
from service.turns import searching, target_motion, turned
from tests.conftest import PosePairs

FIVE = ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")
IDX = np.asarray([JOINT_INDEX[n] for n in FIVE], dtype=np.intp)
GATE = 0.1


@pytest.fixture(scope="module")
def engines(models_dir: Path) -> tuple[Engine, Engine, Engine]:
    """No search, the search for every edit, the gated search."""
    return (
        Engine(models_dir, serving={"turn_yaws": 1}),
        Engine(models_dir, serving={"turn_gate": 0.0}),
        Engine(models_dir, serving={"turn_gate": GATE}),
    )


def _problems(starts: np.ndarray, goals: np.ndarray) -> list[SolveProblem]:
    return [
        SolveProblem(pose=s, target_idx=IDX, target_pos=g[IDX], weights=np.ones(5), n_targets=5)
        for s, g in zip(starts, goals, strict=True)
    ]


def _items(problems: list[SolveProblem]) -> _Items:
    return _Items.of_arrays(
        np.stack([p.pose for p in problems]), np.stack([p.target_idx for p in problems]),
        np.stack([p.target_pos for p in problems]), counts=None, n_targets=None,
        weights=None, fabrik=False, preserve_bone_lengths=True, exact=False, tolerance=1e-3,
        floor=0.0, carry=0.5, turn_search=True, mirror=True,
    )  # fmt: skip


def test_target_motion(real_poses: PosePairs) -> None:
    """How far across the targets lie from their joints: heights do not count, a
    target's own joint only (a padded item of fewer targets beside a wider one: its own)."""
    start = real_poses.poses[real_poses.starts[:8]]
    rows = np.arange(len(start))
    moved = _items(_problems(start, start + np.array([0.3, 0.7, -0.4])))
    np.testing.assert_allclose(target_motion(start, moved, rows), 0.5, atol=1e-12)
    assert not target_motion(start, _items(_problems(start, start)), rows).any()
    quarter = _items(_problems(start, turned(start, np.pi / 2)))
    got = target_motion(start, quarter, rows)
    arm = np.linalg.norm((start[:, IDX] - start[:, :1])[..., [0, 2]], axis=-1)  # from the pelvis
    np.testing.assert_allclose(got, np.sqrt(2.0) * arm.mean(axis=1), atol=1e-9)


def test_gated_edits_solve_from_their_start(
    engines: tuple[Engine, Engine, Engine], real_poses: PosePairs
) -> None:
    """Edits whose targets stay about where the start has them (the start's own joints, a
    few cm off) skip the search: the gated engine answers them bit for bit as the engine
    without a search, alone and in a batch; a goal turned a quarter round still searches
    and turns as the ungated search does."""
    plain, full, gated = engines
    rng = np.random.default_rng(3)
    start = real_poses.poses[real_poses.starts[:12]]
    near = start + rng.normal(0.0, 0.02, start.shape)
    probs = _problems(start, near)
    assert searching(gated, _items(probs)).size == 0
    assert searching(full, _items(probs)).size == len(probs)
    batch, want = gated.solve(probs), plain.solve(probs)
    for p, a, b in zip(probs, batch, want, strict=True):
        (alone,) = gated.solve([p])  # the lone-edit path
        assert np.array_equal(a.pose, b.pose) and a.solvers == b.solvers
        assert np.array_equal(alone.pose, a.pose) and alone.solvers == a.solvers
    far = turned(real_poses.poses[real_poses.goals[:12]], np.pi / 2)
    turned_probs = _problems(start, far)
    assert searching(gated, _items(turned_probs)).size == len(turned_probs)
    for a, b in zip(gated.solve(turned_probs), full.solve(turned_probs), strict=True):
        assert np.array_equal(a.pose, b.pose) and a.solvers == b.solvers
    assert sum(a.solvers[-1] == "turn 90" for a in gated.solve(turned_probs)) >= 6


def test_the_gate_scales_with_the_body(
    engines: tuple[Engine, Engine, Engine], real_poses: PosePairs
) -> None:
    """The gate is at the networks' body size, as the search's margin: the same edits on
    a body twice or half as big are gated alike."""
    gated = engines[2]
    rng = np.random.default_rng(4)
    start = real_poses.poses[real_poses.starts[:40]]
    goal = turned(start, 0.0) + rng.normal(0.0, 0.06, start.shape)
    ref = searching(gated, _items(_problems(start, goal)))
    assert 0 < ref.size < len(start)  # some on either side of the gate
    for k in (2.0, 0.5):
        got = searching(gated, _items(_problems(start * k, goal * k)))
        np.testing.assert_array_equal(got, ref)
