"""FABRIK's answer where the critic finds the networks' answer unlike a real body
(``serving.critic_fabrik``, :mod:`service.fallback`, docs/generalisation-3.md item 55): off
in the shipped models; when on, such an edit gets exactly FABRIK's answer, every other
edit exactly the networks', a batch the same as its edits one by one, and never an answer
FABRIK could not reach its targets with."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX
from service.engine import Engine
from service.fallback import STEP
from service.problems import SolveProblem
from service.turns import implausibility
from tests.conftest import PosePairs, edit_problems, on_random_bodies

MARGIN = 0.005


@pytest.fixture(scope="module")
def engines(models_dir: Path) -> tuple[Engine, Engine]:
    return Engine(models_dir), Engine(models_dir, serving={"critic_fabrik": MARGIN})


@pytest.fixture(scope="module")
def problems(real_poses: PosePairs) -> list[SolveProblem]:
    """Real edits on random bodies: lone joints, both wrists, the 5 end effectors, soft
    and exact."""
    start, goal = on_random_bodies(real_poses, 5)
    sets = [("head",), ("left_elbow",), ("right_knee",), ("left_wrist", "right_wrist"),
            ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")]  # fmt: skip
    soft = [p for names in sets for p in edit_problems(start, goal, names)]
    return soft + [dataclasses.replace(p, reach="exact") for p in soft[: len(soft) // 2]]


def test_off_in_the_shipped_models(engines: tuple[Engine, Engine], client: Any) -> None:
    assert engines[0].serving.critic_fabrik == engines[0].manifest.serving.critic_fabrik == 0.0
    assert client.get("/v1/models").json()["critic_fabrik"] == 0.0


def test_an_edit_the_critic_doubts_gets_fabriks_answer_and_no_other_changes(
    engines: tuple[Engine, Engine], problems: list[SolveProblem]
) -> None:
    plain, critic = engines
    before, after = plain.solve(problems), critic.solve(problems)
    fabrik = plain.solve([dataclasses.replace(p, method="fabrik") for p in problems])
    switched = [i for i, r in enumerate(after) if r.solvers[-1:] == [STEP]]
    assert 0 < len(switched) < len(problems) // 4, len(switched)
    floors = np.zeros(1)
    for i, (b, a, f) in enumerate(zip(before, after, fabrik, strict=True)):
        if i in switched:
            trained = [s for s in b.solvers if s in plain.manifest.solvers()]
            assert np.array_equal(a.pose, f.pose) and a.solvers == [*trained, STEP]
            assert bool(np.all(a.errors <= problems[i].tolerance))
            ours = implausibility(plain, b.pose[None], floors)[0]
            theirs = implausibility(plain, f.pose[None], floors)[0]
            assert theirs + MARGIN < ours
            assert a.max_bone_error <= 1e-5
        else:
            assert np.array_equal(a.pose, b.pose) and a.solvers == b.solvers
    # a batch answers as its edits one by one (the lean path of a lone edit included)
    for i in [*switched[:3], 0, 1]:
        alone = critic.solve([problems[i]])[0]
        assert np.array_equal(alone.pose, after[i].pose) and alone.solvers == after[i].solvers


def test_never_fabriks_answer_where_fabrik_cannot_reach(
    engines: tuple[Engine, Engine], problems: list[SolveProblem]
) -> None:
    """A target 3 m above the head: FABRIK's chain cannot reach it from where the body
    stands, so however doubtful the networks' answer, it stays theirs."""
    engine = Engine(engines[0].models_dir, serving={"critic_fabrik": 1e-9})
    head = JOINT_INDEX["head"]
    far = [
        dataclasses.replace(p, target_pos=p.pose[[head]] + [0.0, 3.0, 0.0], target_idx=[head],
                            weights=np.ones(1), n_targets=1)
        for p in problems[:20]
    ]  # fmt: skip
    assert all(r.solvers[-1:] != [STEP] for r in engine.solve(far))
    near = engine.solve(problems[:40])  # the same margin does switch edits FABRIK reaches
    assert any(r.solvers[-1:] == [STEP] for r in near)


def test_pins_bones_not_kept_and_soft_ik_stay_the_networks(
    engines: tuple[Engine, Engine], problems: list[SolveProblem]
) -> None:
    """FABRIK's answer must hold the pins too (checked on targets and pins alike); an
    edit without the bone pass, or asked to ease into full stretch (``soft_ik``: a switch
    is no smooth answer), is never switched, however doubtful."""
    plain = engines[0]
    doubtful = Engine(plain.models_dir, serving={"critic_fabrik": 1e-9})
    ankles = [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]
    pinned = []
    for p in problems[:40]:
        if any(j in ankles for j in p.target_idx):
            continue
        idx = np.concatenate([p.target_idx, ankles])
        pos = np.concatenate([p.target_pos, p.pose[ankles]])
        pinned.append(dataclasses.replace(p, target_idx=idx, target_pos=pos,
                                          weights=np.ones(len(idx))))  # fmt: skip
    pins = doubtful.solve(pinned)
    assert any(r.solvers[-1:] == [STEP] for r in pins)
    for p, r in zip(pinned, pins, strict=True):
        if r.solvers[-1:] == [STEP]:
            assert bool(np.all(r.pin_errors <= p.tolerance)) and bool(np.all(r.reached))
    for option in ({"preserve_bone_lengths": False}, {"soft_ik": 0.01}):
        asked = [dataclasses.replace(p, **option) for p in problems[:40]]  # type: ignore[arg-type]
        assert all(r.solvers[-1:] != [STEP] for r in doubtful.solve(asked)), option
