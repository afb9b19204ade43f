"""Refinement passes (``serving.passes``): each pass solves again from the previous
answer; answers stay bit-identical, FABRIK items are untouched, and on bodies the models
never saw the reach closes."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from core.bodies import body_lengths, random_bodies, rebuild
from core.skeleton import JOINT_INDEX, bone_lengths
from service.engine import Engine, SolveProblem
from tests.conftest import PosePairs

WRISTS = ("left_wrist", "right_wrist")


@pytest.fixture(scope="module")
def engines(models_dir: Path) -> tuple[Engine, Engine]:
    return Engine(models_dir, solve_passes=1), Engine(models_dir, solve_passes=3)


def _problems(
    starts: np.ndarray, goals: np.ndarray, names: tuple[str, ...], **kw: object
) -> list[SolveProblem]:
    idx = np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)
    return [
        SolveProblem(
            pose=s,
            target_idx=idx,
            target_pos=g[idx],
            weights=np.ones(len(idx)),
            n_targets=len(idx),
            **kw,  # type: ignore[arg-type]
        )
        for s, g in zip(starts, goals, strict=True)
    ]


def _other_bodies(real: PosePairs) -> tuple[np.ndarray, np.ndarray]:
    """Real (start, goal) pairs rebuilt on random asymmetric bodies, one per pair."""
    start, goal = real.poses[real.starts[:60]], real.poses[real.goals[:60]]
    bodies = random_bodies(np.random.default_rng(5), len(start), scale=0.25, symmetric=False)
    lengths = body_lengths(goal, bodies)
    return rebuild(start, bodies, lengths), rebuild(goal, bodies, lengths)


def test_a_pass_starts_from_the_previous_answer(
    engines: tuple[Engine, Engine], real_poses: PosePairs
) -> None:
    one, three = engines
    starts, goals = _other_bodies(real_poses)
    probs = _problems(starts[:10], goals[:10], WRISTS, reach="exact")
    by_hand = probs
    for _ in range(2):  # two soft passes with bone lengths kept, then the asked-for one
        soft = [dataclasses.replace(p, reach="soft", preserve_bone_lengths=True) for p in by_hand]
        by_hand = [
            dataclasses.replace(p, pose=r.pose) for p, r in zip(probs, one.solve(soft), strict=True)
        ]
    for want, got in zip(one.solve(by_hand), three.solve(probs), strict=True):
        assert np.array_equal(want.pose, got.pose) and want.solvers == got.solvers


def test_bit_identical_and_fabrik_untouched(
    engines: tuple[Engine, Engine], real_poses: PosePairs
) -> None:
    one, three = engines
    starts, goals = _other_bodies(real_poses)
    mixed = (
        _problems(starts[:15], goals[:15], WRISTS)
        + _problems(starts[15:30], goals[15:30], ("left_wrist",), method="fabrik")
        + _problems(starts[30:45], goals[30:45], ("head", "left_ankle", "right_ankle"))
    )
    batch, again = three.solve(mixed), three.solve(mixed)
    for p, a, b in zip(mixed, batch, again, strict=True):
        (single,) = three.solve([p])
        assert np.array_equal(a.pose, b.pose) and np.array_equal(a.pose, single.pose)
        assert a.max_bone_error <= 1e-5
        if p.method == "fabrik":
            (plain,) = one.solve([p])
            assert np.array_equal(a.pose, plain.pose)


def test_passes_close_the_reach_on_other_bodies(
    engines: tuple[Engine, Engine], real_poses: PosePairs
) -> None:
    """The bone pass gives back the character's lengths and so moves a target the network
    reached with other bones; the next pass asks for it again."""
    one, three = engines
    starts, goals = _other_bodies(real_poses)
    probs = _problems(starts, goals, WRISTS) + _problems(starts, goals, ("left_ankle",))
    reach_one = np.mean([r.errors.mean() for r in one.solve(probs)])
    reach_three = np.mean([r.errors.mean() for r in three.solve(probs)])
    assert reach_three < 0.8 * reach_one, (reach_one, reach_three)
    assert all(
        np.allclose(bone_lengths(r.pose), bone_lengths(p.pose), rtol=1e-5)
        for p, r in zip(probs, three.solve(probs), strict=True)
    )
