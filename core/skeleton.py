"""The canonical skeleton: the one definition of joint names, parents and frame.

Every model, endpoint and test refers to joints through this module; nothing else
hard-codes joint indices.

Frame conventions (glTF): metres, +Y up, right-handed, the character faces +Z, so its
left side is +X.
"""

from __future__ import annotations

from typing import Any, Final, TypeVar

import numpy as np
import numpy.typing as npt

#: Joint names in the canonical order (the order of every ``[..., 21, 3]`` array).
JOINT_NAMES: Final[tuple[str, ...]] = (
    "pelvis",
    "spine1",
    "spine2",
    "neck",
    "head",
    "left_collar",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "right_collar",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "left_hip",
    "left_knee",
    "left_ankle",
    "left_foot",
    "right_hip",
    "right_knee",
    "right_ankle",
    "right_foot",
)

#: Parent of each joint, by name (the root has ``None``).
PARENT_NAMES: Final[dict[str, str | None]] = {
    "pelvis": None,
    "spine1": "pelvis",
    "spine2": "spine1",
    "neck": "spine2",
    "head": "neck",
    "left_collar": "spine2",
    "left_shoulder": "left_collar",
    "left_elbow": "left_shoulder",
    "left_wrist": "left_elbow",
    "right_collar": "spine2",
    "right_shoulder": "right_collar",
    "right_elbow": "right_shoulder",
    "right_wrist": "right_elbow",
    "left_hip": "pelvis",
    "left_knee": "left_hip",
    "left_ankle": "left_knee",
    "left_foot": "left_ankle",
    "right_hip": "pelvis",
    "right_knee": "right_hip",
    "right_ankle": "right_knee",
    "right_foot": "right_ankle",
}

NUM_JOINTS: Final[int] = len(JOINT_NAMES)
JOINT_INDEX: Final[dict[str, int]] = {name: i for i, name in enumerate(JOINT_NAMES)}
ROOT: Final[str] = "pelvis"

#: Parent index of each joint; -1 for the root. Parents always precede children, so
#: the canonical order is a topological order (root outwards).
PARENTS: Final[tuple[int, ...]] = tuple(
    -1 if PARENT_NAMES[n] is None else JOINT_INDEX[str(PARENT_NAMES[n])] for n in JOINT_NAMES
)

#: Bones as (child, parent) index pairs, one per non-root joint, in topological order.
BONES: Final[tuple[tuple[int, int], ...]] = tuple(
    (child, parent) for child, parent in enumerate(PARENTS) if parent >= 0
)
BONE_CHILDREN: Final[npt.NDArray[np.intp]] = np.array([c for c, _ in BONES], dtype=np.intp)
BONE_PARENTS: Final[npt.NDArray[np.intp]] = np.array([p for _, p in BONES], dtype=np.intp)


def _mirror_name(name: str) -> str:
    if name.startswith("left_"):
        return "right_" + name[len("left_") :]
    if name.startswith("right_"):
        return "left_" + name[len("right_") :]
    return name


#: Index of each joint's mirror image (left <-> right); centre joints map to themselves.
MIRROR: Final[tuple[int, ...]] = tuple(JOINT_INDEX[_mirror_name(n)] for n in JOINT_NAMES)

#: The six base key points of key-point completion (Cascadeur's scheme 1).
BASE_KEYPOINTS: Final[tuple[str, ...]] = (
    "pelvis",
    "neck",
    "left_wrist",
    "right_wrist",
    "left_ankle",
    "right_ankle",
)

#: Frame conventions, as served by ``GET /v1/skeleton`` and written into the manifest.
FRAME: Final[dict[str, str]] = {
    "units": "metres",
    "up": "+Y",
    "forward": "+Z",
    "left": "+X",
    "handedness": "right",
    "convention": "glTF",
}

#: Joints whose horizontal layout defines the facing direction (left minus right).
FACING_PAIRS: Final[tuple[tuple[str, str], ...]] = (
    ("left_hip", "right_hip"),
    ("left_shoulder", "right_shoulder"),
)


def _depths() -> tuple[int, ...]:
    depth: list[int] = []
    for parent in PARENTS:
        depth.append(0 if parent < 0 else depth[parent] + 1)
    return tuple(depth)


#: Depth of each joint below the root (pelvis = 0).
DEPTH: Final[tuple[int, ...]] = _depths()


def _subtrees() -> npt.NDArray[np.bool_]:
    out = np.eye(NUM_JOINTS, dtype=np.bool_)
    for k in range(NUM_JOINTS):  # parents come first: a joint's row already holds its own
        p = PARENTS[k]
        while p >= 0:
            out[p, k] = True
            p = PARENTS[p]
    return out


#: ``[21, 21]``: True where joint ``k`` is joint ``j`` or hangs below it (``[j, k]``).
SUBTREE: Final[npt.NDArray[np.bool_]] = _subtrees()


def indices(names: list[str] | tuple[str, ...]) -> list[int]:
    """Joint indices for names; raises ``KeyError`` naming the first unknown joint."""
    out = []
    for name in names:
        if name not in JOINT_INDEX:
            raise KeyError(name)
        out.append(JOINT_INDEX[name])
    return out


def chain_to_root(joint: str) -> list[str]:
    """Joints strictly between ``joint`` and the root, nearest first (the "chain")."""
    chain: list[str] = []
    parent = PARENT_NAMES[joint]
    while parent is not None and parent != ROOT:
        chain.append(parent)
        parent = PARENT_NAMES[parent]
    return chain


def bone_lengths(positions: npt.NDArray[np.floating]) -> npt.NDArray[np.floating]:
    """Lengths of every bone, ``[..., 21, 3] -> [..., 20]`` in the order of ``BONES``."""
    diff = positions[..., BONE_CHILDREN, :] - positions[..., BONE_PARENTS, :]
    return np.asarray(np.linalg.norm(diff, axis=-1))


def set_key(joints: list[str] | tuple[str, ...] | frozenset[str]) -> str:
    """The manifest key of a target joint set: sorted names joined by '+'."""
    return "+".join(sorted(joints))


_F = TypeVar("_F", bound=np.floating[Any])
_MIRROR_IDX: Final[npt.NDArray[np.intp]] = np.asarray(MIRROR, dtype=np.intp)
_MIRROR_SIGN: Final[npt.NDArray[np.float64]] = np.array([-1.0, 1.0, 1.0])


def flat_columns(joints: npt.ArrayLike) -> npt.NDArray[np.intp]:
    """The columns ``[3k]`` of a flat pose ``[.., 63]`` holding ``joints`` (indices, in
    their order), x, y and z each."""
    idx = np.asarray(joints, dtype=np.intp).reshape(-1)
    out: npt.NDArray[np.intp] = (3 * idx[:, None] + np.arange(3, dtype=np.intp)).reshape(-1)
    return out


#: :func:`mirrored_flat`: column ``c`` of a flat mirror image is column ``MIRROR_COLUMNS[c]``
#: of the pose times ``MIRROR_SIGNS[c]`` (x of each joint negated).
MIRROR_COLUMNS: Final[npt.NDArray[np.intp]] = flat_columns(_MIRROR_IDX)
MIRROR_SIGNS: Final[npt.NDArray[np.float64]] = np.tile(_MIRROR_SIGN, len(MIRROR))
_FLAT_SIGNS: Final[dict[np.dtype[Any], npt.NDArray[Any]]] = {
    np.dtype(t): MIRROR_SIGNS.astype(t) for t in (np.float32, np.float64)
}


def mirrored(poses: npt.NDArray[_F]) -> npt.NDArray[_F]:
    """Left <-> right of ``poses [..., 21, 3]`` in a frame whose x axis is the body's side
    (the canonical frame): each joint takes its mirror joint's place, x negated. Exact in
    any float type, and its own inverse."""
    out: npt.NDArray[_F] = poses[..., _MIRROR_IDX, :] * _MIRROR_SIGN.astype(poses.dtype)
    return out


def mirrored_flat(poses: npt.NDArray[_F]) -> npt.NDArray[_F]:
    """:func:`mirrored` of flat poses ``[B, 63]`` (one gather of columns and one product,
    where the ``[..., 21, 3]`` form reshapes both ways): the same numbers."""
    sign = _FLAT_SIGNS.get(poses.dtype)
    out: npt.NDArray[_F] = poses.take(MIRROR_COLUMNS, axis=1) * (
        MIRROR_SIGNS.astype(poses.dtype) if sign is None else sign
    )
    return out


def mirror_key(key: str) -> str:
    """The key of a target set's mirror image (``set_key`` of its joints' mirrors)."""
    return set_key([JOINT_NAMES[MIRROR[JOINT_INDEX[j]]] for j in key.split("+")])


def mirror_target_columns(
    joints: npt.ArrayLike, theirs: npt.ArrayLike
) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.float64]]:
    """How the targets of a set ``joints`` are asked of its mirror set ``theirs`` (each
    in its solver's input order): the flat columns ``[3k]`` of ``joints``, the flat
    columns whose mirror images are ``theirs``' targets in their order, and the signs
    ``[3k]`` that take them there (x negated)."""
    other = np.asarray(MIRROR, dtype=np.intp)[np.asarray(theirs, dtype=np.intp)]
    return flat_columns(joints), flat_columns(other), MIRROR_SIGNS[: 3 * len(other)].copy()


def _trunk() -> frozenset[int]:
    kids = np.bincount([p for p in PARENTS if p >= 0], minlength=NUM_JOINTS)
    out: set[int] = set()
    for joint in np.flatnonzero(kids >= 2).tolist():
        while joint >= 0:
            out.add(joint)
            joint = PARENTS[joint]
    return frozenset(out)


#: The trunk: every joint with several children (a sub-base) and all its ancestors
#: (the pelvis, the spine up to the chest).
TRUNK: frozenset[int] = _trunk()
