"""The compiled hinge step (``core.compiled_hinges``, called by ``core.hinges.keep_hinges``)
against the numpy steps it replaced, kept here as the reference, on real files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from core.bvh import read_bvh
from core.bvh_write import pose_of, skeleton_of
from core.characters import Pose, Skeleton, forward_kinematics, matrix_to_quat
from core.characters_maps import JointMap, resolve_map
from core.hinges import _STILL, LIMBS, MAX_LEAN, MIN_BEND, _applies, keep_hinges

F64 = np.ndarray


def _turn(axis: F64, angle: float) -> F64:
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.asarray(np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k))


def _angle(axis: F64, a: F64, b: F64) -> float:
    pa, pb = a - (a @ axis) * axis, b - (b @ axis) * axis
    return float(np.arctan2(axis @ np.cross(pa, pb), pa @ pb))


def _hinge(axis: F64, v: F64, bone: F64, want: F64) -> tuple[float, float] | None:
    c = float(axis @ bone)
    s2 = 1.0 - c * c
    if s2 < 1e-12:
        return None
    c1, c2 = float(v @ axis), float(want @ bone)
    base = (c1 - c2 * c) / s2 * axis + (c2 - c1 * c) / s2 * bone
    rest = float(v @ v) - float(base @ base)
    if rest < 0.0:
        return None
    n, gamma = np.cross(axis, bone), np.sqrt(rest / s2)
    best = None
    for x in (base + gamma * n, base - gamma * n):
        t, f = _angle(axis, v, x), -_angle(bone, want, x)
        if t > 0.0 and (best is None or abs(f) < abs(best[1])):
            best = (t, f)
    return best


def _places(skel: Skeleton, jmap: JointMap, joint: int) -> bool:
    for anchor in jmap.anchors:
        if anchor.joint == joint and np.any(anchor.offset != 0):
            return True
        if anchor.joint != joint and skel.is_ancestor(joint, anchor.joint):
            return True
    return False


def _reference(skel: Skeleton, before: Pose, pose: Pose, jmap: JointMap, changed: set[int]
               ) -> set[int]:  # fmt: skip
    """``keep_hinges`` as numpy steps (the code before the kernel, 73e7718)."""
    out: set[int] = set()
    anchor = [a.joint for a in jmap.anchors]
    limbs = [
        (top, mid, end)
        for top, mid, end in LIMBS
        if _applies(skel, jmap, anchor[top], anchor[mid], top, mid, changed)
    ]
    if not limbs:
        return out
    quats = matrix_to_quat(before.rotations[[jmap.anchors[mid].joint for _, mid, _ in limbs]])
    g_rot, g_pos = forward_kinematics(skel, pose)
    points = jmap.points(g_rot, g_pos)
    for (top, mid, end), q in zip(limbs, quats, strict=True):
        upper, hinge = jmap.anchors[top].joint, jmap.anchors[mid].joint
        if 2.0 * float(np.arctan2(np.linalg.norm(q[:3]), q[3])) < MIN_BEND:
            continue
        axis = q[:3] / np.linalg.norm(q[:3])
        top_at, at = g_pos[upper], g_pos[hinge]
        length = float(np.linalg.norm(at - top_at))
        parent = g_rot[skel.parents[hinge]]
        lower = points[end] - at
        v = g_rot[hinge].T @ lower
        if length <= 0.0 or abs(float(axis @ v)) > np.sin(MAX_LEAN) * float(np.linalg.norm(v)):
            continue
        bone = (at - top_at) / length
        got = _hinge(axis, v, parent.T @ bone, parent.T @ lower)
        if got is None:
            continue
        trial = pose.copy()
        twist = _turn(bone, got[1])
        above = skel.parents[upper]
        turned = twist @ g_rot[upper]
        trial.rotations[upper] = turned if above < 0 else g_rot[above].T @ turned
        trial.rotations[hinge] = _turn(axis, got[0])
        held = twist @ g_rot[skel.parents[hinge]] @ trial.rotations[hinge]
        for c in skel.children(hinge):
            if skel.rotatable[c] and _places(skel, jmap, c):
                trial.rotations[c] = held.T @ g_rot[c]
        g2_rot, g2_pos = forward_kinematics(skel, trial)
        points2 = jmap.points(g2_rot, g2_pos)
        if float(np.abs(points2 - points).max()) > _STILL * (length + float(np.linalg.norm(lower))):
            continue
        moved = (trial.rotations != pose.rotations).any(axis=(1, 2))
        out |= {int(j) for j in np.flatnonzero(moved)}
        pose.rotations = trial.rotations
        g_rot, g_pos, points = g2_rot, g2_pos, points2
    return out


def test_compiled_hinges_are_the_numpy_steps(bvh_files: dict[str, Path]) -> None:
    """Every file, three frames, the limbs' joints turned by up to 25 degrees as an answer
    turns them: the compiled step's rotations within 1e-12 of the numpy steps', the same
    joints reported, limbs bent and twisted on most files, the same bytes on a second run,
    and ``before`` untouched."""
    rng = np.random.default_rng(5)
    bent_files = 0
    for name, path in bvh_files.items():
        bvh = read_bvh(path)
        skel = skeleton_of(bvh)
        jmap = resolve_map(skel, None)
        limb_joints = sorted({jmap.anchors[j].joint for limb in LIMBS for j in limb[:2]})
        for frame in (0, bvh.num_frames // 3, 2 * bvh.num_frames // 3):
            before = pose_of(bvh, frame)
            answer = before.copy()
            kicks = Rotation.from_rotvec(rng.normal(0.0, 0.25, (len(limb_joints), 3))).as_matrix()
            answer.rotations[limb_joints] = kicks @ answer.rotations[limb_joints]
            frozen = before.rotations.copy()
            got, want = answer.copy(), answer.copy()
            changed = set(range(skel.size))
            turned = keep_hinges(skel, before, got, jmap, changed)
            assert turned == _reference(skel, before, want, jmap, changed), (name, frame)
            np.testing.assert_allclose(got.rotations, want.rotations, rtol=0, atol=1e-12)
            again = answer.copy()
            assert keep_hinges(skel, before, again, jmap, changed) == turned
            assert again.rotations.tobytes() == got.rotations.tobytes()
            assert before.rotations.tobytes() == frozen.tobytes()
            bent_files += bool(turned)
    assert bent_files >= len(bvh_files), bent_files  # most frames bend a limb
