"""The compiled kernels (core.compiled, core.compiled_fabrik) against the numpy reference
(core.kinematics, core.geometry) on real poses: same answers to 1e-12, same iteration
counts, and bit-identical answers run to run and whatever the batch."""

from __future__ import annotations

import numpy as np
import pytest

from core import compiled, compiled_fabrik, kinematics
from core.geometry import canonical_transform
from core.rest import rest_lengths, rest_pose
from core.skeleton import JOINT_INDEX, bone_lengths
from tests.conftest import PosePairs

SETS = (
    ("left_wrist",),
    ("left_wrist", "right_wrist"),
    ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"),
    ("left_elbow", "left_wrist", "spine2"),
)


def _idx(names: tuple[str, ...]) -> np.ndarray:
    return np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)


def test_bone_pass_matches_numpy(real_poses: PosePairs) -> None:
    start = real_poses.poses[real_poses.starts]
    lens = np.ascontiguousarray(bone_lengths(real_poses.poses[real_poses.goals]))
    noisy = start + np.random.default_rng(0).normal(0.0, 0.03, start.shape)
    got = compiled.bone_pass_batch(noisy, lens, start, True)
    ref = kinematics.bone_pass(noisy, lens, reference=start)
    assert np.abs(got - ref).max() < 1e-12
    assert np.abs(bone_lengths(got) / lens - 1.0).max() < 1e-12
    # a degenerate bone (child on its parent) falls back to the reference's direction
    noisy[0, JOINT_INDEX["left_wrist"]] = noisy[0, JOINT_INDEX["left_elbow"]]
    got = compiled.bone_pass_batch(noisy[:1], lens[:1], start[:1], True)
    ref = kinematics.bone_pass(noisy[:1], lens[:1], reference=start[:1])
    assert np.all(np.isfinite(got)) and np.abs(got - ref).max() < 1e-12


def test_prepare_matches_the_geometry(real_poses: PosePairs) -> None:
    rng = np.random.default_rng(1)
    poses = real_poses.poses[real_poses.starts]
    yaw = rng.uniform(-np.pi, np.pi, len(poses))
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.zeros((len(poses), 3, 3))
    rot[:, 0, 0], rot[:, 0, 2], rot[:, 1, 1], rot[:, 2, 0], rot[:, 2, 2] = c, s, 1, -s, c
    world = np.einsum("bij,bkj->bki", rot, poses) + rng.uniform(-5, 5, (len(poses), 1, 3))
    idx = np.tile(_idx(SETS[1]).astype(np.int64), (len(poses), 1))
    tpos = np.ascontiguousarray(world[np.arange(len(poses))[:, None], idx] + 0.05)
    n = len(poses)
    canon, *_, tcan, _, _ = compiled.prepare(
        np.ascontiguousarray(world), np.zeros(n), idx, tpos, np.full(n, 2), np.ones(n, bool),
        np.ones((1, 20)) / 20, np.ones(1), True, 1.0,
    )  # fmt: skip
    frame = canonical_transform(world)
    assert np.abs(canon - frame.to_canonical(world)).max() < 1e-12
    assert np.abs(tcan - frame.to_canonical(tpos)).max() < 1e-12


@pytest.mark.parametrize("names", SETS)
@pytest.mark.parametrize("polish", [False, True])
@pytest.mark.parametrize("pin", [False, True])
def test_fabrik_and_polish_match_numpy(
    real_poses: PosePairs, names: tuple[str, ...], polish: bool, pin: bool
) -> None:
    idx = _idx(names)
    if pin:
        idx = np.append(idx, JOINT_INDEX["right_ankle" if "left_wrist" in names else "pelvis"])
        idx = np.unique(idx)
    k = len(idx)
    pinned = np.arange(k) == k - 1 if pin else np.zeros(k, dtype=bool)
    starts = real_poses.poses[real_poses.starts][:60]
    goals = real_poses.poses[real_poses.goals][:60][:, idx].copy()
    goals[:, pinned] = starts[:, idx[pinned]]
    lens = np.ascontiguousarray(bone_lengths(starts))
    pose, _ = _against_numpy(polish, starts, lens, goals, idx, pinned, 1e-4, 64)
    plans = compiled_fabrik.packed_plans(idx, np.ones(k), pinned)
    # each item alone: the same bits in a batch of one, and from one run to the next
    again = compiled_fabrik.solve_batch(
        polish, np.ascontiguousarray(starts[3:4]), lens[3:4], np.ascontiguousarray(goals[3:4]),
        np.full(1, 1e-4), 64, plans.local_ints, plans.local_floats, plans.has_local,
        plans.ints, plans.floats, pinned, True, False,
    )  # fmt: skip
    assert np.array_equal(again[0][0], pose[3])


@pytest.mark.parametrize(
    ("pin", "joint"),
    [
        ("neck", "left_wrist"),
        ("left_hip", "left_ankle"),
        ("left_knee", "pelvis"),
        ("left_ankle", "head"),
        ("left_wrist", "left_elbow"),
        ("left_shoulder", "spine2"),
    ],
)
@pytest.mark.parametrize("polish", [False, True])
def test_pins_off_the_legs_match_numpy(
    real_poses: PosePairs, pin: str, joint: str, polish: bool
) -> None:
    """A pin the start has left (moved whole, as a network's answer may be) and a far
    target: the pinned sub-base centroid, the start brought back within the pin's shell
    and the pins' own progress, compiled as in numpy."""
    idx = _idx((joint, pin))
    pinned = np.asarray([False, True])
    rng = np.random.default_rng(5)
    poses = real_poses.poses[real_poses.starts][:40]
    goals = poses[:, idx].copy()
    d = rng.normal(size=(len(poses), 3))
    goals[:, 0] += d / np.linalg.norm(d, axis=1, keepdims=True)
    starts = poses + 0.25 * rng.normal(size=(len(poses), 1, 3))
    _, errs = _against_numpy(polish, starts, bone_lengths(poses), goals, idx, pinned)
    assert errs[:, 1].max() <= 1e-3  # the pin held


def _against_numpy(
    polish: bool, starts: np.ndarray, lens: np.ndarray, goals: np.ndarray, idx: np.ndarray,
    pinned: np.ndarray, tol: float = 1e-3, max_it: int = 256, rigid_hips: bool = False,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The compiled FABRIK (``polish``: the polish) of every item, pins ``pinned``, against
    numpy's item by item (1e-12, the same iterations); its poses and errors ``[B, K]``."""
    lens = np.ascontiguousarray(lens)
    plans = compiled_fabrik.packed_plans(idx, np.ones(len(idx)), pinned)
    pose, its, errs, _ = compiled_fabrik.solve_batch(
        polish, np.ascontiguousarray(starts), lens, np.ascontiguousarray(goals),
        np.full(len(starts), tol), max_it, plans.local_ints, plans.local_floats,
        plans.has_local, plans.ints, plans.floats, pinned, True, rigid_hips,
    )  # fmt: skip
    fn = kinematics.polish if polish else kinematics.fabrik
    for b in range(len(starts)):
        ref = fn(starts[b], lens[b], idx, goals[b], tolerance=tol, max_iterations=max_it,
                 pinned=pinned, rigid_hips=rigid_hips)  # fmt: skip
        assert np.abs(ref.positions - pose[b]).max() < 1e-12
        assert ref.iterations == its[b]
        assert np.abs(ref.errors - errs[b]).max() < 1e-12
    return pose, errs


def test_a_root_held_for_its_pins_matches_numpy(
    real_poses: PosePairs, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Both ankles pinned, the head 1 m away, starts a network might give (4 cm of noise):
    where the free root stops with a pin still off, it is held and the legs go on
    (``kinematics._solve``'s ``frozen``), in numpy as compiled; every pin is met."""
    idx = _idx(("head", "left_ankle", "right_ankle"))
    pinned = np.asarray([False, True, True])
    rng = np.random.default_rng(5)
    poses = real_poses.poses[real_poses.starts]
    goals = poses[:, idx].copy()
    starts = poses.copy()
    for b in range(len(poses)):
        d = rng.normal(size=3)
        goals[b, 0] += d / np.linalg.norm(d)
        starts[b] += 0.04 * rng.normal(size=poses.shape[1:])
    held = []
    iterate = kinematics._iterate

    def counting(*args: object) -> object:
        held.append(args[6] is not None and bool(np.any(np.asarray(args[6]))))
        return iterate(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(kinematics, "_iterate", counting)
    _, errs = _against_numpy(False, starts, bone_lengths(poses), goals, idx, pinned)
    assert errs[:, 1:].max() <= 1e-3
    assert any(held)  # the case arose


@pytest.mark.parametrize("polish", [False, True])
def test_rigid_hips_keep_the_hips_apart_and_match_numpy(
    real_poses: PosePairs, polish: bool
) -> None:
    """The pelvis dragged 8-15 cm, both ankles pinned, on real poses: FABRIK as the textbook
    has it turns each hip bone towards its own leg and folds the hips onto one side of the
    pelvis in most answers (an audit, 2026-12-07); with ``rigid_hips`` the hips keep their
    distance to 1e-9 (moved with the pelvis), compiled as in numpy, every pin held."""
    idx = _idx(("pelvis", "left_ankle", "right_ankle"))
    pinned = np.asarray([False, True, True])
    rng = np.random.default_rng(7)
    poses = real_poses.poses[real_poses.starts][:30]
    goals = poses[:, idx].copy()
    d = rng.normal(size=(len(poses), 3)) * [1.0, 0.2, 1.0]
    far = rng.uniform(0.08, 0.15, (len(d), 1))
    goals[:, 0] += d / np.linalg.norm(d, axis=1, keepdims=True) * far
    hips = [JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]]

    def width(p: np.ndarray) -> np.ndarray:
        return np.asarray(np.linalg.norm(p[:, hips[0]] - p[:, hips[1]], axis=-1))

    free, _ = _against_numpy(polish, poses, bone_lengths(poses), goals, idx, pinned)
    rigid, errs = _against_numpy(polish, poses, bone_lengths(poses), goals, idx, pinned,
                                 rigid_hips=True)  # fmt: skip
    assert (width(free) < 0.8 * width(poses)).sum() >= 10
    assert np.abs(width(rigid) - width(poses)).max() < 1e-9
    assert errs[:, 1:].max() <= 1e-3


def test_rigid_hips_hold_in_the_polish_first_stage() -> None:
    """A review's case (2026-12-07): the rest pose, its left knee dragged 37 cm across with
    the right ankle pinned. The polish's first stage (the trunk held) reached it by swinging
    the left hip about the pelvis, the hips at 0.23 of their distance, with ``rigid_hips``
    as without; now the hips stay apart there too, compiled as in numpy."""
    pose = rest_pose()
    idx = _idx(("left_knee", "right_ankle"))
    pinned = np.asarray([False, True])
    goals = pose[idx].copy()
    goals[0] += [-0.37, 0.028, -0.042]
    hips = [JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]]

    def width(p: np.ndarray) -> float:
        return float(np.linalg.norm(p[..., hips[0], :] - p[..., hips[1], :]))

    free = kinematics.polish(pose, rest_lengths(), idx, goals, pinned=pinned, max_iterations=256)
    assert width(free.positions) < 0.5 * width(pose)
    rigid, _ = _against_numpy(True, pose[None], rest_lengths()[None], goals[None], idx, pinned,
                              rigid_hips=True)  # fmt: skip
    assert abs(width(rigid[0]) - width(pose)) < 1e-9
