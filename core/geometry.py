"""Batched pose geometry over ``[..., 21, 3]`` arrays (numpy only, no state).

Canonical frame: the pelvis projected onto the floor plane (y = 0) sits at the origin
and the character faces +Z (its left is +X). The same functions serve the dataset
builder and the service, so training data and requests are canonicalised alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core.skeleton import FACING_PAIRS, JOINT_INDEX

FloatArray = npt.NDArray[np.floating]

_LEFT = [JOINT_INDEX[left] for left, _ in FACING_PAIRS]
_RIGHT = [JOINT_INDEX[right] for _, right in FACING_PAIRS]
_PELVIS = JOINT_INDEX["pelvis"]


def yaw_matrix(yaw: FloatArray) -> FloatArray:
    """Rotation matrices about +Y by ``yaw`` radians, ``[...] -> [..., 3, 3]``."""
    return _rotation_from_forward(np.sin(yaw), np.cos(yaw))


def rotation_about(axis: npt.ArrayLike, angle: float) -> FloatArray:
    """The rotation by ``angle`` (radians) about the unit ``axis`` (Rodrigues), ``[3, 3]``
    (``core.compiled_hinges`` has the compiled one)."""
    a = np.asarray(axis, dtype=np.float64)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    out: FloatArray = np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
    return out


def perpendicular(v: FloatArray) -> FloatArray:
    """A direction across each unit ``v`` ``[..., 3]``: the axis least along it, without
    its part along ``v`` (not of unit length; ``core.rigid``'s compiled frame has its own)."""
    axis = np.eye(3)[np.argmin(np.abs(v), axis=-1)]
    out: FloatArray = axis - np.sum(axis * v, axis=-1, keepdims=True) * v
    return out


def _rotation_from_forward(fx: FloatArray, fz: FloatArray) -> FloatArray:
    """The yaw rotation taking +Z to the unit floor direction (fx, 0, fz)."""
    out = np.zeros((*np.shape(fx), 3, 3))
    out[..., 0, 0] = fz
    out[..., 0, 2] = fx
    out[..., 1, 1] = 1.0
    out[..., 2, 0] = -fx
    out[..., 2, 2] = fz
    return out


@dataclass(frozen=True)
class RigidTransform:
    """World = rotation @ canonical + translation (per pose; batched)."""

    rotation: FloatArray  # [..., 3, 3]
    translation: FloatArray  # [..., 3]

    def to_world(self, canonical: FloatArray) -> FloatArray:
        """``[..., J, 3]`` canonical -> world."""
        out = np.einsum("...ij,...kj->...ki", self.rotation, canonical)
        return np.asarray(out + self.translation[..., None, :])

    def to_canonical(self, world: FloatArray) -> FloatArray:
        """``[..., J, 3]`` world -> canonical."""
        local = world - self.translation[..., None, :]
        return np.asarray(np.einsum("...ji,...kj->...ki", self.rotation, local))


def facing_transform(fx: FloatArray, fz: FloatArray, translation: FloatArray) -> RigidTransform:
    """The transform of a canonical frame facing the unit floor direction (fx, 0, fz), its
    origin at ``translation`` (e.g. rebuilt from ``core.compiled.prepare``'s outputs)."""
    return RigidTransform(rotation=_rotation_from_forward(fx, fz), translation=translation)


def across(positions: FloatArray) -> FloatArray:
    """A pose's left minus right ``[..., 3]``, summed over the hips and the shoulders: its
    facing is this turned a quarter about +Y (:func:`canonical_transform`)."""
    out: FloatArray = (positions[..., _LEFT, :] - positions[..., _RIGHT, :]).sum(axis=-2)
    return out


def canonical_transform(positions: FloatArray) -> RigidTransform:
    """The transform that maps the canonical pose back to the given world pose.

    The facing is the floor direction of (left - right summed over hips and shoulders) x up;
    a pose with no horizontal left-right extent (lying on its side) keeps yaw 0."""
    side = across(positions)
    fx, fz = -side[..., 2], side[..., 0]
    norm = np.hypot(fx, fz)
    flat = norm < 1e-12
    safe = np.where(flat, 1.0, norm)
    fx = np.where(flat, 0.0, fx / safe)
    fz = np.where(flat, 1.0, fz / safe)
    translation = positions[..., _PELVIS, :].copy()
    translation[..., 1] = 0.0
    return facing_transform(fx, fz, translation)


def transform_yaw(transform: RigidTransform) -> FloatArray:
    """The facing angle (radians about +Y, 0 = facing +Z) of a transform's rotation, so that
    ``yaw_matrix(transform_yaw(t))`` equals ``t.rotation``."""
    return np.asarray(np.arctan2(transform.rotation[..., 0, 2], transform.rotation[..., 0, 0]))


def canonicalise(positions: FloatArray) -> FloatArray:
    """Move the floor projection of the pelvis to the origin and turn to face +Z."""
    return canonical_transform(positions).to_canonical(positions)


def symmetry_views(
    points: FloatArray, mirror_of: npt.ArrayLike, yaws: int, mirror: bool
) -> FloatArray:
    """Views of floor-centred ``points [K, 3]`` under the floor symmetries of a body:
    turned about +Y by ``2 pi k / yaws`` (k = 0 .. yaws-1), then, if ``mirror``, the same
    turns of their mirror image (x -> -x, point i taking the place of its mirror
    ``mirror_of[i]``). ``[V, K, 3]``, V = yaws (x 2 with ``mirror``); view 0 is ``points``.
    :func:`unview` takes answers in each view's frame back to the first."""
    turns = yaw_matrix(2.0 * np.pi * np.arange(yaws) / yaws)  # [Y, 3, 3]
    sides = [points]
    if mirror:
        sides.append(points[np.asarray(mirror_of)] * _FLIP)
    return np.concatenate([np.einsum("yij,kj->yki", turns, s) for s in sides])


def unview(poses: FloatArray, mirror_of: npt.ArrayLike, yaws: int, mirror: bool) -> FloatArray:
    """The inverse of :func:`symmetry_views` on answers ``[V, J, 3]`` (``mirror_of``: each
    joint's mirror joint): each turned back, the mirrored ones mirrored back."""
    turns = yaw_matrix(2.0 * np.pi * np.arange(yaws) / yaws)
    sides = poses.reshape(2 if mirror else 1, yaws, *poses.shape[1:])
    back = np.stack([np.einsum("yji,ykj->yki", turns, s) for s in sides])  # R^T p
    if mirror:
        back[1] = back[1][:, np.asarray(mirror_of)] * _FLIP
    return np.asarray(back.reshape(poses.shape))


_FLIP = np.array([-1.0, 1.0, 1.0])
