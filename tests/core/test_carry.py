"""The carry below targets (core.carry) on real poses, and its compiled kernel
(core.compiled_limbs.carry_item) against it."""

from __future__ import annotations

import numpy as np
import pytest

from core import compiled
from core.carry import carry_anchors, carry_below
from core.compiled_limbs import carry_item
from core.skeleton import JOINT_INDEX, bone_lengths
from tests.conftest import PosePairs


def _idx(*names: str) -> list[int]:
    return [JOINT_INDEX[n] for n in names]


def test_anchors_are_the_branches_below_targeted_joints() -> None:
    j = JOINT_INDEX
    a = carry_anchors(_idx("left_elbow"))
    assert a[j["left_wrist"]] == j["left_elbow"]
    assert (np.flatnonzero(a >= 0) == [j["left_wrist"]]).all()
    a = carry_anchors(_idx("right_knee"))
    assert a[j["right_ankle"]] == a[j["right_foot"]] == j["right_knee"]
    assert (a >= 0).sum() == 2
    # a target below another: only what hangs below the lower one is carried
    a = carry_anchors(_idx("left_knee", "left_ankle"))
    assert (np.flatnonzero(a >= 0) == [j["left_foot"]]).all()
    assert a[j["left_foot"]] == j["left_ankle"]
    # the whole arm hangs below a targeted spine joint, the other branches do not
    a = carry_anchors(_idx("spine2", "left_wrist"))
    assert a[j["head"]] == j["spine2"] and a[j["right_wrist"]] == j["spine2"]
    assert a[j["left_elbow"]] == -1 and a[j["left_knee"]] == -1
    # the root carries nothing (dragging the pelvis moves the whole body by itself); leaves
    # (wrists, feet, the head) have nothing below them
    assert (carry_anchors(_idx("pelvis")) == -1).all()
    assert (carry_anchors(_idx("left_wrist", "right_wrist", "head", "left_foot")) == -1).all()


@pytest.fixture(scope="module")
def answers(real_poses: PosePairs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Starts, lengths and stand-in answers (each goal put on its start's bone lengths)."""
    start = real_poses.poses[real_poses.starts]
    lens = np.ascontiguousarray(bone_lengths(start))
    goal = real_poses.poses[real_poses.goals]
    answer = compiled.bone_pass_batch(np.ascontiguousarray(goal), lens, start, True)
    return start, lens, answer


@pytest.mark.parametrize("names", [("left_elbow",), ("right_knee",), ("spine2", "left_wrist")])
def test_carry_turns_the_branch_with_the_bone(
    answers: tuple[np.ndarray, np.ndarray, np.ndarray], names: tuple[str, ...]
) -> None:
    start, lens, answer = answers
    targets = _idx(*names)
    carried = np.flatnonzero(carry_anchors(targets) >= 0)
    rest = np.setdiff1d(np.arange(21), carried)
    assert np.array_equal(carry_below(answer, start, lens, targets, 0.0), answer)
    full = carry_below(answer, start, lens, targets, 1.0)
    half = carry_below(answer, start, lens, targets, 0.5)
    for out in (full, half):
        assert np.abs(bone_lengths(out) / lens - 1.0).max() < 1e-12
        assert np.array_equal(out[:, rest], answer[:, rest])  # nothing else moves
        assert np.abs(out[:, carried] - answer[:, carried]).max() > 0.01
    # weight 1: the branch is the start's, rigidly (its distances to the anchor kept)
    a = carry_anchors(targets)[carried]
    d0 = np.linalg.norm(start[:, carried] - start[:, a], axis=-1)
    d1 = np.linalg.norm(full[:, carried] - full[:, a], axis=-1)
    assert np.abs(d1 - d0).max() < 1e-12
    # half-way: each carried joint ends between the network's place and the rigid one
    gap = np.linalg.norm(full[:, carried] - answer[:, carried], axis=-1)
    assert np.all(np.linalg.norm(half[:, carried] - answer[:, carried], axis=-1) <= gap + 1e-12)


def test_compiled_carry_matches_numpy(answers: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
    start, lens, answer = answers
    scratch = np.empty((21, 3))
    ints = np.empty(21, np.int64), np.empty(21, np.int64), np.empty((5, 3))
    for names in [("left_elbow",), ("left_knee", "right_elbow"), ("spine2",), ("pelvis",)]:
        targets = _idx(*names)
        tidx = np.asarray(targets + [0] * (4 - len(targets)), dtype=np.int64)
        for weight in (0.25, 0.5, 1.0):
            ref = carry_below(answer, start, lens, targets, weight)
            got = answer.copy()
            for b in range(len(got)):
                carry_item(got[b], start[b], lens[b], tidx, len(targets), weight, scratch, *ints)
            assert np.abs(got - ref).max() < 1e-12
    # degenerate: an elbow on its shoulder; a forearm opposite the rigid one (the mix cancels
    # only if the upper arm has not turned, so this checks the fallbacks agree, not a case)
    bad = answer[:2].copy()
    e, s, w = JOINT_INDEX["left_elbow"], JOINT_INDEX["left_shoulder"], JOINT_INDEX["left_wrist"]
    bad[0, e] = bad[0, s]
    bad[1, w] = bad[1, e] - (start[1, w] - start[1, e])
    ref = carry_below(bad, start[:2], lens[:2], [e], 0.5)
    got = bad.copy()
    for b in range(2):
        carry_item(got[b], start[b], lens[b], np.asarray([e]), 1, 0.5, scratch, *ints)
    assert np.all(np.isfinite(got)) and np.abs(got - ref).max() < 1e-12
    # nothing to turn by: the forearm keeps the answer's direction, at its length
    forearm = lens[0, w - 1]
    assert abs(np.linalg.norm(got[0, w] - got[0, e]) - forearm) < 1e-12
