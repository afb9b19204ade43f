"""Other bodies from real poses: new bone lengths and joint placements (numpy, batched).

A *body* is a change applied to poses ``[..., 21, 3]``: every bone scaled by its own factor,
and some joints moved along a bone, as another studio would place them (pelvis higher up
the spine, neck lower, collars nearer the midline, ...). The benchmark's stress set uses
these functions; the trainer's augmentation (``trainer/augment.py``, in torch) moves joints
the same way and within the same :data:`PLACEMENT` limits (``augment.joint_shift``), so
both mean the same thing by "another body". Nothing here is random unless a
``numpy.random.Generator`` is passed in.

- :func:`random_bodies` draws bodies (symmetric or not);
- :func:`shift_joints` moves the joints (pose-relative, so it follows any pose);
- :func:`body_lengths` gives a body's exact bone lengths, measured on one reference pose;
- :func:`rebuild` applies a body to poses: shifted joints, then exactly those lengths,
  each bone vector scaled root outwards (every bone keeps its direction, a joint's
  subtree follows it, the root stays where it is).

To give the start and the target pose of an edit the *same* body, measure the lengths on
one of them and pass them to both: ``lengths = body_lengths(start, body)``,
``rebuild(start, body, lengths)``, ``rebuild(target, body, lengths)``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from core.skeleton import (
    BONE_CHILDREN,
    BONE_PARENTS,
    BONES,
    JOINT_INDEX,
    MIRROR,
    NUM_JOINTS,
    PARENTS,
    bone_lengths,
)

F64 = npt.NDArray[np.floating[Any]]

#: Default placement shifts (largest fraction of the bone to move along) of the joints a
#: studio places differently; the others stay where they are.
PLACEMENT: Final[Mapping[str, float]] = {
    "pelvis": 0.5,  # of pelvis -> spine1 (positive: up the spine)
    "neck": 0.3,  # of spine2 -> neck (positive: further from the chest)
    "head": 0.3,  # of neck -> head
    "left_collar": 0.4,  # of spine2 -> collar (negative: towards the midline)
    "right_collar": 0.4,
}

#: The bone (index into ``BONES``) of each mirror-image bone, for symmetric bodies.
_BONE_OF_CHILD = {int(c): b for b, c in enumerate(BONE_CHILDREN)}
_MIRROR_BONE = np.asarray([_BONE_OF_CHILD[MIRROR[int(c)]] for c in BONE_CHILDREN], dtype=np.intp)
_SPINE1 = JOINT_INDEX["spine1"]


@dataclass(frozen=True)
class Body:
    """A change of body, batched like the poses it applies to.

    ``bone_scale`` ``[..., 20]``: factor on each bone's length (``BONES`` order).
    ``shift`` ``[..., 21]``: each joint moves by this fraction of a bone: a non-root joint
    along its parent bone (``j += f * (j - parent)``), the root (pelvis) along its bone to
    spine1 (``pelvis += f * (spine1 - pelvis)``); its children stay where they are.
    """

    bone_scale: F64
    shift: F64

    def __post_init__(self) -> None:
        if np.shape(self.bone_scale)[-1:] != (NUM_JOINTS - 1,):
            raise ValueError(
                f"bone_scale must be [..., {NUM_JOINTS - 1}], got {np.shape(self.bone_scale)}"
            )
        if np.shape(self.shift)[-1:] != (NUM_JOINTS,):
            raise ValueError(f"shift must be [..., {NUM_JOINTS}], got {np.shape(self.shift)}")
        if not (np.all(np.isfinite(self.bone_scale)) and np.all(np.asarray(self.bone_scale) > 0)):
            raise ValueError("bone_scale must be finite and positive")
        if not np.all(np.isfinite(self.shift)):
            raise ValueError("shift must be finite")


def random_bodies(
    rng: np.random.Generator,
    n: int,
    *,
    scale: float = 0.25,
    symmetric: bool = True,
    placement: Mapping[str, float] = PLACEMENT,
) -> Body:
    """``n`` random bodies: each bone scaled by a factor log-uniform in
    ``[1 / (1 + scale), 1 + scale]`` (``scale=0.25``: 0.8 to 1.25, i.e. at least ±20 %),
    the same for a bone and its mirror image if ``symmetric``; each joint of ``placement``
    shifted by a fraction uniform in ``[-limit, limit]`` (mirrored joints alike if
    ``symmetric``)."""
    if n < 0 or scale < 0:
        raise ValueError(f"n and scale must be >= 0, got n={n}, scale={scale}")
    unknown = sorted(set(placement) - set(JOINT_INDEX))
    if unknown:
        raise ValueError(f"placement names unknown joints {unknown}")
    log = np.log1p(scale)
    bone_scale = np.exp(rng.uniform(-log, log, size=(n, NUM_JOINTS - 1)))
    shift = np.zeros((n, NUM_JOINTS))
    for name, limit in placement.items():
        shift[:, JOINT_INDEX[name]] = rng.uniform(-limit, limit, size=n)
    if symmetric:
        # a centre bone is its own mirror; one of each pair takes the other's value
        first = np.arange(NUM_JOINTS - 1) <= _MIRROR_BONE
        bone_scale = np.where(first, bone_scale, bone_scale[:, _MIRROR_BONE])
        joints = np.arange(NUM_JOINTS)
        shift = np.where(joints <= np.asarray(MIRROR), shift, shift[:, list(MIRROR)])
    return Body(bone_scale=bone_scale, shift=shift)


def shift_joints(positions: F64, shift: F64) -> F64:
    """Move each joint by ``shift`` ``[..., 21]`` (see :class:`Body`); children stay put.
    All moves are computed from the input pose, so their order does not matter."""
    pos = np.asarray(positions, dtype=np.float64)
    f = np.asarray(shift, dtype=np.float64)[..., :, None]
    away = pos - pos[..., [max(p, 0) for p in PARENTS], :]  # joint - parent (root: 0)
    away[..., 0, :] = pos[..., _SPINE1, :] - pos[..., 0, :]  # the root moves up the spine
    return np.asarray(pos + f * away)


def body_lengths(reference: F64, body: Body) -> F64:
    """The bone lengths ``[..., 20]`` of ``body`` built from the pose ``reference``: its
    bones after the joint shifts, times ``body.bone_scale``."""
    return np.asarray(bone_lengths(shift_joints(reference, body.shift)) * body.bone_scale)


def rebuild(positions: F64, body: Body, lengths: F64 | None = None) -> F64:
    """Poses ``[..., 21, 3]`` with ``body`` applied: joints shifted, then every bone given
    exactly ``lengths`` ``[..., 20]`` (default: :func:`body_lengths` of each pose itself):
    root outwards, ``new[child] = new[parent] + length * unit(old[child] - old[parent])``,
    so every bone keeps its direction. The root keeps its shifted position. Bones of zero
    length in the input cannot be given a direction: they raise ``ValueError``."""
    moved = shift_joints(positions, body.shift)
    if lengths is None:
        lengths = bone_lengths(moved) * body.bone_scale
    lengths = np.asarray(lengths, dtype=np.float64)
    vectors = moved[..., BONE_CHILDREN, :] - moved[..., BONE_PARENTS, :]
    norms = np.linalg.norm(vectors, axis=-1, keepdims=True)
    if not np.all(norms > 0):
        raise ValueError("a bone of zero length has no direction to keep")
    vectors = vectors / norms * lengths[..., :, None]
    batch = np.broadcast_shapes(moved.shape[:-2], vectors.shape[:-2])
    out = np.broadcast_to(moved, (*batch, NUM_JOINTS, 3)).copy()
    for b, (child, parent) in enumerate(BONES):  # parents come first
        out[..., child, :] = out[..., parent, :] + vectors[..., b, :]
    return out
