"""The rigid pairs (core.rigid): the hips and the collars the answer squeezed turned to the
start's angle, compiled kernel against the numpy reference on real poses, and the engine's
``serving.keep_pairs`` on bodies the models never saw."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core import kinematics
from core.rigid import PAIRS, SQUEEZED, keep_pairs, keep_pairs_item
from core.skeleton import JOINT_INDEX, SUBTREE, bone_lengths
from service.engine import Engine
from service.problems import SolveProblem
from tests.conftest import PosePairs, on_random_bodies


def _width(p: np.ndarray, left: int, right: int) -> np.ndarray:
    out: np.ndarray = np.linalg.norm(p[..., left, :] - p[..., right, :], axis=-1)
    return out


@pytest.fixture(scope="module")
def moved(real_poses: PosePairs) -> tuple[np.ndarray, np.ndarray]:
    """(start, answer-like) pairs: each start with noise, bone lengths put back."""
    start = real_poses.poses[real_poses.starts]
    noisy = start + np.random.default_rng(3).normal(0.0, 0.04, start.shape)
    return start, kinematics.bone_pass(noisy, bone_lengths(start), reference=start)


def test_pairs_take_the_start_width_and_keep_every_bone(
    moved: tuple[np.ndarray, np.ndarray],
) -> None:
    """A pair the noise squeezed below ``SQUEEZED`` of its width takes the start's width,
    facing as the answer had it, its limbs moved as one piece; the others are untouched."""
    start, answer = moved
    out = keep_pairs(answer, start)
    for top, left, right in PAIRS:
        ratio = _width(answer, left, right) / _width(start, left, right)
        sq = ratio < SQUEEZED
        assert sq.sum() >= 10 and (~sq).sum() >= 10  # the noise squeezed some, not all
        kept = _width(out[sq], left, right) / _width(start[sq], left, right)
        assert np.abs(kept - 1.0).max() < 1e-9
        assert np.array_equal(out[~sq][:, SUBTREE[left] | SUBTREE[right]],
                              answer[~sq][:, SUBTREE[left] | SUBTREE[right]])  # fmt: skip
        # the pair faces as the answer had it: the same across direction
        across = out[sq, left] - out[sq, right]
        was = answer[sq, left] - answer[sq, right]
        cos = np.sum(across * was, axis=-1) / np.linalg.norm(across, axis=-1)
        assert np.allclose(cos / np.linalg.norm(was, axis=-1), 1.0, atol=1e-12)
        # the top stays; a limb below a moved joint moves as one piece
        assert np.array_equal(out[:, top], answer[:, top])
        kids = np.flatnonzero(SUBTREE[left])[1:]
        assert np.allclose(out[:, kids] - out[:, [left]], answer[:, kids] - answer[:, [left]])
    assert np.abs(bone_lengths(out) / bone_lengths(answer) - 1.0).max() < 1e-12


def test_compiled_kernel_matches_numpy(moved: tuple[np.ndarray, np.ndarray]) -> None:
    start, answer = moved
    ref = keep_pairs(answer, start)
    got = np.ascontiguousarray(answer.copy())
    for b in range(len(got)):
        keep_pairs_item(got[b], np.ascontiguousarray(start[b]))
    assert np.abs(got - ref).max() < 1e-12
    again = np.ascontiguousarray(answer.copy())
    for b in range(len(again)):
        keep_pairs_item(again[b], np.ascontiguousarray(start[b]))
    assert np.array_equal(again, got)  # bit-identical run to run


def test_a_pair_drawn_straight_across_in_the_start_is_turned_back_too(
    moved: tuple[np.ndarray, np.ndarray],
) -> None:
    """Some skeletons draw the hips (or the collars) on one straight line through their top
    (40 % of the held-out ReActIdle frames): the pair's frame in the start had no second
    axis, and a squeezed pair was left as it was. A pelvis dragged over pinned feet on those
    bodies came back with its hips folded to 0.15-0.47 of their width (28 of 100 ReActIdle
    poses, a ``/tmp`` script). It is now laid straight across again, along the answer's
    own across direction, numpy and compiled alike."""
    start, answer = moved
    straight = start.copy()
    for top, left, right in PAIRS:  # the pair laid on one line through its top, its bones kept
        across = straight[:, left] - straight[:, right]
        across /= np.linalg.norm(across, axis=-1, keepdims=True)
        for joint, sign in ((left, 1.0), (right, -1.0)):
            bone = np.linalg.norm(straight[:, joint] - straight[:, top], axis=-1, keepdims=True)
            shift = straight[:, top] + sign * bone * across - straight[:, joint]
            straight[:, SUBTREE[joint]] += shift[:, None, :]
    out = keep_pairs(answer, straight)
    got = np.ascontiguousarray(answer.copy())
    for b in range(len(got)):
        keep_pairs_item(got[b], np.ascontiguousarray(straight[b]))
    assert np.abs(got - out).max() < 1e-12
    for _, left, right in PAIRS:
        sq = _width(answer, left, right) < SQUEEZED * _width(straight, left, right)
        assert sq.sum() >= 10
        kept = _width(out[sq], left, right) / _width(straight[sq], left, right)
        assert np.abs(kept - 1.0).max() < 1e-9  # (before: left squeezed, 0.2-0.8)


def test_a_degenerate_pair_is_left_as_it_is(moved: tuple[np.ndarray, np.ndarray]) -> None:
    start, answer = moved
    flat = answer[:1].copy()
    pelvis, left = JOINT_INDEX["pelvis"], JOINT_INDEX["left_hip"]
    flat[0, left] = flat[0, pelvis]  # a zero-length hip bone
    out = keep_pairs(flat, start[:1])
    got = np.ascontiguousarray(flat[0].copy())
    keep_pairs_item(got, np.ascontiguousarray(start[0]))
    hips = [left, JOINT_INDEX["right_hip"], JOINT_INDEX["right_knee"]]
    assert np.array_equal(out[0, hips], flat[0, hips])
    assert np.array_equal(got[hips], flat[0, hips])
    assert np.isfinite(out).all()


def test_the_engine_keeps_a_new_body_width(models_dir: Path, real_poses: PosePairs) -> None:
    """``serving.keep_pairs`` (on for the shipped models since mx1-cf785d658788): of the soft
    answers (no pins) on bodies the models never saw that the retry's FABRIK polish did not
    finish (it turns each hip on its own: docs/generalisation-serving-2.md item 45), those
    whose networks squeezed a pair (5 hips and 2 collars of 25 here, down to 61 % of their
    width) are turned back: no pair ends below ``SQUEEZED`` of its width by more than 1 %."""
    starts, goals = on_random_bodies(real_poses, 11)
    idx = np.asarray([JOINT_INDEX["head"], JOINT_INDEX["left_wrist"]], dtype=np.intp)
    problems = [
        SolveProblem(pose=s, target_idx=idx, target_pos=g[idx], weights=np.ones(2), n_targets=2)
        for s, g in zip(starts, goals, strict=True)
    ]
    kept = Engine(models_dir)
    assert kept.serving.keep_pairs
    results = kept.solve(problems)
    answers = np.stack([r.pose for r in results])
    plain = np.asarray(["fabrik-polish" not in r.solvers for r in results])
    plain_engine = Engine(models_dir, serving={"keep_pairs": False})
    off = np.stack([r.pose for r in plain_engine.solve(problems)])
    assert plain.sum() >= len(problems) // 2
    for _, left, right in PAIRS:
        was = _width(off[plain], left, right) / _width(starts[plain], left, right)
        ratio = _width(answers[plain], left, right) / _width(starts[plain], left, right)
        assert (was < SQUEEZED).sum() >= 2  # the networks squeeze a new body's pairs
        assert ratio.min() > SQUEEZED - 0.01  # (the steps after it move a hip a little)
    again = np.stack([r.pose for r in kept.solve(problems[:5])])
    assert np.array_equal(again, answers[:5])  # batch vs single: the same bits
