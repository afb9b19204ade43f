"""The canonical rest pose (T-pose): the one definition of its offsets, in metres."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.skeleton import BONE_CHILDREN, JOINT_NAMES, NUM_JOINTS, PARENTS

F64 = npt.NDArray[np.float64]

#: Offset of each joint from its parent in the canonical T-pose (metres, +Y up, faces
#: +Z, left = +X), by name. Left/right are mirror images (x -> -x).
_REST_OFFSETS: dict[str, tuple[float, float, float]] = {
    "spine1": (0.0, 0.12, -0.01),
    "spine2": (0.0, 0.25, 0.0),
    "neck": (0.0, 0.17, 0.0),
    "head": (0.0, 0.12, 0.03),
    "left_collar": (0.07, 0.11, 0.0),
    "left_shoulder": (0.12, 0.02, 0.0),
    "left_elbow": (0.27, 0.0, 0.0),
    "left_wrist": (0.25, 0.0, 0.0),
    "left_hip": (0.09, -0.07, 0.0),
    "left_knee": (0.0, -0.40, 0.0),
    "left_ankle": (0.0, -0.40, -0.02),
    "left_foot": (0.0, -0.05, 0.13),
}
_REST_PELVIS_HEIGHT = 0.95


def _offset(name: str) -> tuple[float, float, float]:
    if name in _REST_OFFSETS:
        return _REST_OFFSETS[name]
    if name.startswith("right_"):
        x, y, z = _REST_OFFSETS["left_" + name[len("right_") :]]
        return (-x, y, z)
    raise KeyError(name)


def _build_rest_pose() -> F64:
    pose = np.zeros((NUM_JOINTS, 3), dtype=np.float64)
    for j, parent in enumerate(PARENTS):
        if parent < 0:
            pose[j] = (0.0, _REST_PELVIS_HEIGHT, 0.0)
        else:
            pose[j] = pose[parent] + np.asarray(_offset(JOINT_NAMES[j]), dtype=np.float64)
    pose.flags.writeable = False
    return pose


_REST: F64 = _build_rest_pose()  # read-only constant


def _rest_dirs() -> F64:
    out = np.zeros((NUM_JOINTS, 3), dtype=np.float64)
    for j, parent in enumerate(PARENTS):
        if parent >= 0:
            d = _REST[j] - _REST[parent]
            out[j] = d / np.linalg.norm(d)
    out.flags.writeable = False
    return out


#: Unit direction of each joint's bone (from its parent) in the rest pose, per joint.
REST_DIRS = _rest_dirs()


def rest_pose() -> F64:
    """The canonical T-pose, ``[21, 3]`` float64 metres (a fresh, writable copy).

    Pelvis at 0.95 m above the floor, facing +Z, arms along +-X. Built from ``PARENTS``
    and per-joint-name bone offsets; used as the fallback direction of degenerate bones.
    """
    return np.array(_REST, dtype=np.float64)


def rest_lengths() -> F64:
    """Bone lengths of :func:`rest_pose`, ``[20]`` in ``BONES`` order."""
    return np.asarray(
        np.linalg.norm(_REST[BONE_CHILDREN] - _REST[[PARENTS[c] for c in BONE_CHILDREN]], axis=-1)
    )
