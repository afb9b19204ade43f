"""``core.reach.polish`` on a real character: it meets what it can, leaves a pose it cannot
improve untouched, and never loses a pin for a target."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.bvh import read_bvh
from core.bvh_write import pose_of, skeleton_of
from core.characters import F64, Pose, Skeleton, forward_kinematics
from core.characters_maps import JointMap, resolve_map
from core.compiled_reach import descend_into
from core.reach import polish
from core.skeleton import JOINT_INDEX
from tests.character_files import FILES

WRIST, ANKLES = JOINT_INDEX["left_wrist"], (JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"])


@pytest.fixture(scope="module")
def bandai(bvh_files: dict[str, Path]) -> tuple[Skeleton, Pose, JointMap]:
    path = bvh_files["bandai"]
    bvh = read_bvh(path)
    skel = skeleton_of(bvh)
    pose = pose_of(bvh, FILES["bandai"][3])
    return skel, pose, resolve_map(skel)


def _points(skel: Skeleton, pose: Pose, jmap: JointMap) -> F64:
    g_rot, g_pos = forward_kinematics(skel, pose)
    return jmap.points(g_rot, g_pos)


def _edit(bandai: tuple[Skeleton, Pose, JointMap]) -> tuple[Pose, F64, float, list[Any]]:
    """A copy of the pose, its points, a tolerance (~1/500 of the trunk) and both ankles
    pinned where they are."""
    skel, pose, jmap = bandai
    pose = pose.copy()
    pts = _points(skel, pose, jmap)
    tol = 1e-3 * float(np.linalg.norm(pts[JOINT_INDEX["head"]] - pts[0]))
    return pose, pts, tol, [(a, pts[a]) for a in ANKLES]


def test_a_reachable_wrist_is_met_and_the_pins_held(
    bandai: tuple[Skeleton, Pose, JointMap],
) -> None:
    skel, _, jmap = bandai
    pose, pts, tol, pins = _edit(bandai)
    goal = pts[WRIST] + 0.2 * (pts[JOINT_INDEX["head"]] - pts[WRIST])
    changed = polish(skel, pose, jmap, [(WRIST, goal)], pins, tol, 0)
    after = _points(skel, pose, jmap)
    assert np.linalg.norm(after[WRIST] - goal) <= 0.1 * tol
    assert all(np.linalg.norm(after[a] - p) <= 0.1 * tol for a, p in pins)
    assert changed  # the arm turned
    # the same call gives the same bits (the compiled steps: no BLAS, no threads)
    twice, _, _, _ = _edit(bandai)
    assert polish(skel, twice, jmap, [(WRIST, goal)], pins, tol, 0) == changed
    assert twice.rotations.tobytes() == pose.rotations.tobytes()
    assert twice.translations.tobytes() == pose.translations.tobytes()
    # a pose that already meets them is left bit for bit
    again = pose.copy()
    assert polish(skel, again, jmap, [(WRIST, after[WRIST])], pins, tol, 0) == set()
    np.testing.assert_array_equal(again.rotations, pose.rotations)


def test_an_unreachable_wrist_comes_nearer_but_no_pin_is_lost(
    bandai: tuple[Skeleton, Pose, JointMap],
) -> None:
    skel, _, jmap = bandai
    pose, pts, tol, pins = _edit(bandai)
    goal = pts[WRIST] + np.array([0.0, 0.0, 1.0]) * 10 * float(np.ptp(pts, axis=0).max())
    before = float(np.linalg.norm(pts[WRIST] - goal))
    polish(skel, pose, jmap, [(WRIST, goal)], pins, tol, 0)
    after = _points(skel, pose, jmap)
    assert float(np.linalg.norm(after[WRIST] - goal)) < before
    assert all(np.linalg.norm(after[a] - p) <= tol for a, p in pins)


def test_a_skeleton_with_nothing_to_turn_is_left_as_it_is(
    bandai: tuple[Skeleton, Pose, JointMap],
) -> None:
    """No rotatable joint and no root to move (a file of position channels only): nothing
    to do, no error (an empty step's maximum raised before)."""
    skel, pose, jmap = bandai
    frozen = dataclasses.replace(skel, rotatable=(False,) * skel.size)
    pose = pose.copy()
    pts = _points(frozen, pose, jmap)
    assert polish(frozen, pose, jmap, [(WRIST, pts[WRIST] + 0.1)], [], 1e-3, None) == set()


def test_a_turn_that_moves_nothing_does_not_stall_the_steps() -> None:
    """A review's find: the Jacobian of a joint turned about its own bone is rank-deficient,
    and once the damping has fallen below the rounding of JᵀJ a Cholesky pivot is not
    positive; the kernel refused such steps and stopped short (this chain, its tip turned
    2.5 rad about the root: 18 steps, 1.37 off). It now solves them again with more
    damping and reaches the tip's goal."""
    parents = np.array([-1, 0, 1], np.int64)
    rotations = np.repeat(np.eye(3)[None], 3, axis=0)
    translations = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    angle = 2.5  # the tip (two bones along x) to turn about z; a turn about x moves nothing
    goals = np.array([[2 * np.cos(angle), 2 * np.sin(angle), 0.0], [1.0, 0.0, 0.0]])
    misses = np.linalg.norm(translations.cumsum(axis=0)[[2, 1]] - goals, axis=1)
    descend_into(
        parents, rotations, translations, np.array([2, 1], np.int64), np.zeros((2, 3)), goals,
        np.array([1.0, 0.02]), np.array([0], np.int64), np.ones((1, 2)), -1, 2e-5, 1.0, 1, 1,
        1e-6, 30, 0.1, 5, 0.01, misses,
    )  # fmt: skip
    assert misses[0] < 1e-3, misses


def test_a_far_target_s_swing_of_an_arm_does_not_stall_a_pin() -> None:
    """Found with ``python -m bench.pins --characters``: a wrist dragged far out of reach
    asks its arm for turns of tens of radians, and the step cut to the largest turn (0.1
    rad) shrank the spine's turn that brings a pinned neck back with it: the steps stalled
    with the neck 9 cm off here (42 mm on a real file, both ankles pinned too). Where
    targets and pins pull together, the step of a damping raised until it fits is tried
    too; it turns the spine and brings the pin back. Weights as in the pins-first phase."""
    parents = np.array([-1, 0, 1, 1, 3, 4], np.int64)  # root, spine, neck; an arm off the spine
    rotations = np.repeat(np.eye(3)[None], 6, axis=0)
    translations = np.array(
        [[0, 0, 0], [0, 0.5, 0], [0, 0.5, 0], [0.2, 0.4, 0], [0.3, 0, 0], [0.3, 0, 0]], float
    )
    spine, neck = translations[:2].sum(axis=0), translations[:3].sum(axis=0)
    c, s = np.cos(0.2), np.sin(0.2)  # the neck's pin: its place turned 0.2 rad about the spine
    pinned = spine + np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ (neck - spine)
    goals = np.array([[20.0, 0.0, 0.0], pinned])  # the hand 19 m out of reach
    hand = translations[[0, 1, 3, 4, 5]].sum(axis=0)
    misses = np.linalg.norm(np.array([hand, neck]) - goals, axis=1)
    descend_into(
        parents, rotations, translations, np.array([5, 2], np.int64), np.zeros((2, 3)), goals,
        np.array([0.1, 30.0]), np.array([1, 3, 4], np.int64),
        np.array([[1.0, 1.0], [1.0, 0.0], [1.0, 0.0]]), -1, 0.1, 1.0, 2, 1, 1e-3, 30, 0.1, 5,
        0.01, misses,
    )  # fmt: skip
    assert misses[1] < 1e-3, misses


def test_polish_canonical_holds_both_wrists_under_a_far_pelvis_with_the_bones_kept() -> None:
    """The canonical skeleton as a body of its own bones (``polish_canonical``, the engine's
    pin polish): both wrists pinned where they are and the pelvis asked 1 m away and down,
    out of what the arms allow. The wrists stay within the tolerance, the pelvis comes
    nearer, every bone keeps its length; where the pins already hold and nothing is asked,
    there is nothing to do."""
    from core.reach import polish_canonical
    from core.rest import rest_pose
    from core.skeleton import bone_lengths

    pose = rest_pose()
    wrists = [(j, pose[j].copy()) for j in (JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"])]
    pelvis = JOINT_INDEX["pelvis"]
    goal = pose[pelvis] + np.array([0.0, -0.6, 0.8])
    got = polish_canonical(pose, [(pelvis, goal)], wrists, 1e-3, True)
    assert got is not None
    assert max(float(np.linalg.norm(got[j] - g)) for j, g in wrists) <= 1e-3
    assert np.linalg.norm(got[pelvis] - goal) < np.linalg.norm(pose[pelvis] - goal) - 0.05
    np.testing.assert_allclose(bone_lengths(got), bone_lengths(pose), rtol=0, atol=1e-9)
    assert polish_canonical(pose, [], wrists, 1e-3, True) is None


def test_the_steps_keep_every_local_rotation_a_rotation_down_a_long_chain() -> None:
    """An audit's find (a character with 7-22 joints from pelvis to chest: pinned wrists
    5-104 mm off as written): a step took a world turn into its parent's frame as ``Pᵀ T P``,
    and with ``P`` a product of earlier steps each local rotation took up twice its parent's
    drift from orthonormal, so the drift grew with the depth and the steps (this chain:
    31 off a rotation after one phase). The steps measured their misses on those matrices,
    not on the rotations written back. Now the turn is built about the axis taken into the parent's
    frame: a rotation to rounding, whatever the depth."""
    n = 24  # a chain of short bones along y, each turned a few seeded degrees
    parents = np.arange(-1, n - 1, dtype=np.int64)
    rng = np.random.default_rng(0)
    angles = rng.uniform(-0.1, 0.1, (n, 3))
    rotations = np.ascontiguousarray([_turn(a) for a in angles])
    translations = np.tile([0.0, 0.05, 0.0], (n, 1))
    translations[0] = 0.0
    goals = np.array([[0.9, 0.2, 0.4], [0.0, 0.3, 0.0]])  # the tip out of reach; a pin
    tips = np.array([n - 1, 6], np.int64)
    _, g_pos = _chain_fk(parents, rotations, translations)
    misses = np.linalg.norm(g_pos[tips] - goals, axis=1)
    movable = np.arange(n, dtype=np.int64)
    above = np.array([[1.0, 1.0 if m <= 6 else 0.0] for m in range(n)])
    taken = descend_into(
        parents, rotations, translations, tips, np.zeros((2, 3)), goals, np.array([1.0, 30.0]),
        movable, above, -1, 0.1, 1.0, 2, 1, 1e-3, 30, 0.1, 5, 0.01, misses,
    )  # fmt: skip
    assert taken > 10
    drift = np.abs(np.einsum("jab,jcb->jac", rotations, rotations) - np.eye(3)).max()
    assert drift <= 1e-12, drift
    # the misses it reports are those of the rotations it returns
    _, g_pos = _chain_fk(parents, rotations, translations)
    np.testing.assert_allclose(np.linalg.norm(g_pos[tips] - goals, axis=1), misses, atol=1e-12)


def _turn(v: F64) -> F64:
    """The rotation of rotation vector ``v`` (numpy: Rodrigues)."""
    angle = float(np.linalg.norm(v))
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]]) / angle
    out: F64 = np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
    return out


def _chain_fk(parents: Any, rotations: F64, translations: F64) -> tuple[F64, F64]:
    n = len(parents)
    skel = Skeleton(
        tuple(f"j{i}" for i in range(n)), tuple(int(p) for p in parents), translations.copy(),
        (True,) * n, (False,) * n,
    )  # fmt: skip
    return forward_kinematics(skel, Pose(rotations, translations))


#: a polish's edits of the Bandai-Namco frame: (canonical joint, move in units of the
#: trunk along x, y, z, both ankles pinned?)
_GROUND_EDITS = [
    ("pelvis", (0.1, -0.15, 0.05), True),
    ("pelvis", (-0.1, 0.0, 0.1), False),
    ("head", (0.15, -0.05, 0.1), True),
    ("right_wrist", (0.1, 0.1, -0.15), False),
    ("left_wrist", (-0.2, 0.1, 0.1), True),
]


def _ground_edits(
    skel: Skeleton, pose: Pose, jmap: JointMap, root: int
) -> list[tuple[Pose, set[int], float]]:
    """Each of :data:`_GROUND_EDITS` polished from ``pose`` (the root's translation
    ``root``): the new pose, the joints changed and the target's miss."""
    out = []
    for joint, move, pinned in _GROUND_EDITS:
        new, pts, tol, pins = _edit((skel, pose, jmap))
        trunk = float(np.linalg.norm(pts[JOINT_INDEX["head"]] - pts[0]))
        goal = pts[JOINT_INDEX[joint]] + trunk * np.array(move)
        target = [(JOINT_INDEX[joint], goal)]
        changed = polish(skel, new, jmap, target, pins if pinned else [], tol, root)
        miss = float(np.linalg.norm(_points(skel, new, jmap)[JOINT_INDEX[joint]] - goal))
        out.append((new, changed, miss))
    return out


def test_a_ground_root_above_the_hips_is_left_as_it_was(
    bandai: tuple[Skeleton, Pose, JointMap],
) -> None:
    """Bandai-Namco's ``joint_Root`` sits on the floor above ``Hips`` and is the identity in
    every frame; the hips carry their own position channels. An audit found 14 of 24
    ordinary edits turning it, by up to 10.9 degrees (the polish turned every joint above
    a target or pin). The pelvis's joint turns and carries the body, so the root is left
    bit for bit and the targets are still met: the same edits with the hips unable to turn
    (nothing below can turn the body) do turn it."""
    skel, pose, jmap = bandai
    ground, hips = skel.names.index("joint_Root"), skel.names.index("Hips")
    assert jmap.joints[0] == hips and skel.parents[hips] == ground and skel.translatable[hips]
    tol = _edit(bandai)[2]
    for new, changed, miss in _ground_edits(skel, pose, jmap, hips):
        assert changed and ground not in changed and miss <= tol
        assert new.rotations[ground].tobytes() == pose.rotations[ground].tobytes()
        assert new.translations[ground].tobytes() == pose.translations[ground].tobytes()
    # a rig whose hips cannot turn: the root's turn is what turns the body
    stiff = dataclasses.replace(skel, rotatable=tuple(j != hips for j in range(skel.size)))
    turned = [ground in changed for _, changed, _ in _ground_edits(stiff, pose, jmap, hips)]
    assert any(turned), turned


def test_a_reference_root_carrying_the_body_moves_but_does_not_turn(
    bandai: tuple[Skeleton, Pose, JointMap],
) -> None:
    """A UE-style rig: the root at the floor carries the position channels and the hips
    only turn (the Bandai skeleton read so). The root's translation moves the pelvis; its
    rotation is left bit for bit (an audit's UE-style rig turned 2.8 degrees on a pinned
    pelvis drag), every target still met."""
    skel, pose, jmap = bandai
    ground = skel.names.index("joint_Root")
    rig = dataclasses.replace(skel, translatable=tuple(j == ground for j in range(skel.size)))
    tol = _edit(bandai)[2]
    moved = False
    for new, changed, miss in _ground_edits(rig, pose, jmap, ground):
        assert miss <= tol
        assert new.rotations[ground].tobytes() == pose.rotations[ground].tobytes()
        moved |= ground in changed
    assert moved
