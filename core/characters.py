"""A character in its own skeleton: joints, rest offsets, local rotations and FK (numpy).

Conventions (the contract; ``docs/characters.md`` says the same):

- **Quaternions** are ``[x, y, z, w]`` (scalar last, as glTF), active rotations of
  a right-handed frame; any non-zero length is accepted and normalised.
- **Local rotation** of a joint: its frame relative to its parent's frame. World rotation
  ``G[j] = G[parent] @ R[j]``; world position ``P[j] = P[parent] + G[parent] @ T[j]``
  where ``T[j]`` is the joint's rest offset (or, on BVH joints with position channels, the
  values of those channels). The root's ``P`` is the root position, ``G`` its rotation.
- **Units and up axis** are the client's: :data:`UNITS` gives metres per unit, :data:`UP_AXES`
  the rotation taking the up axis to +Y (the service's frame). Nothing here converts: the
  solve converts the 21 mapped points on their way to and from the engine.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from core import compiled_characters
from core.text import near_name, quoted, shown
from core.units import UNITS, UP_AXES

F64 = npt.NDArray[np.float64]


class CharacterError(ValueError):
    """A skeleton, pose or joint map that cannot be used; the message says what and why.
    ``location``: the field, where the message's own prefix cannot say it plainly (a
    client's joint name, which may hold spaces, colons or capitals)."""

    def __init__(self, detail: str, location: str | None = None) -> None:
        super().__init__(detail)
        self.location = location


@dataclass(frozen=True)
class Skeleton:
    """A character's joints in topological order (every parent precedes its children)."""

    names: tuple[str, ...]
    parents: tuple[int, ...]  # -1 for a root
    offsets: F64  # [J, 3] rest offset from the parent, in the character's units
    rotatable: tuple[bool, ...]  # may the solve change this joint's local rotation?
    translatable: tuple[bool, ...]  # does the pose carry this joint's own translation?
    index: dict[str, int] = field(default_factory=dict, repr=False, compare=False)
    parent_array: npt.NDArray[np.int64] = field(init=False, repr=False, compare=False)
    _rest: F64 = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        self.index.update({n: i for i, n in enumerate(self.names)})
        object.__setattr__(self, "parent_array", np.asarray(self.parents, dtype=np.int64))
        rest = np.zeros((len(self.names), 3))
        for j, p in enumerate(self.parents):
            rest[j] = self.offsets[j] if p < 0 else rest[p] + self.offsets[j]
        object.__setattr__(self, "_rest", rest)

    @property
    def size(self) -> int:
        return len(self.names)

    def children(self, j: int) -> list[int]:
        return [k for k, p in enumerate(self.parents) if p == j]

    def is_ancestor(self, a: int, b: int) -> bool:
        """True if ``a`` is ``b`` or one of its ancestors."""
        while b >= 0:
            if b == a:
                return True
            b = self.parents[b]
        return False

    def rest_positions(self) -> F64:
        """World positions of the rest pose (identity rotations, offsets as given): a copy
        of the ones summed once when the skeleton was built (a joint map asks a dozen
        times per request)."""
        return self._rest.copy()


@dataclass
class Pose:
    """Local rotations ``[J, 3, 3]`` and local translations ``[J, 3]`` of one frame."""

    rotations: F64
    translations: F64

    def copy(self) -> Pose:
        return Pose(self.rotations.copy(), self.translations.copy())


def build_skeleton(
    names: Sequence[str],
    parents: Sequence[str | None],
    offsets: Sequence[Sequence[float]],
    *,
    rotatable: Sequence[bool] | None = None,
    translatable: Sequence[bool] | None = None,
    where: str = "skeleton.joints",
) -> tuple[Skeleton, list[int]]:
    """Validate joints given in any order by parent *name*; return the skeleton (sorted
    parents-first) and, for each of its joints, the index of that joint in the input.

    Raises :class:`CharacterError` on an empty skeleton, an empty or duplicate name, an
    unknown parent, a cycle, no root, or an offset that is not 3 finite numbers."""
    n = len(names)
    if n == 0:
        raise CharacterError(f"{where}: the skeleton has no joints")
    seen: dict[str, int] = {}
    for i, name in enumerate(names):
        if not name:
            raise CharacterError(f"{where}[{i}].name: empty joint name")
        if name in seen:
            raise CharacterError(
                f"{where}[{i}].name: duplicate joint name {quoted(name)} "
                f"(also joints[{seen[name]}])"
            )
        seen[name] = i
    off = np.zeros((n, 3))
    for i, o in enumerate(offsets):
        if len(o) != 3:
            raise CharacterError(f"{where}[{i}].offset: expected 3 numbers, got {len(o)}")
        off[i] = o
        if not np.isfinite(off[i]).all():
            raise CharacterError(f"{where}[{i}].offset: not finite: {list(o)}")
    parent_of: list[int] = []
    for i, p in enumerate(parents):
        if p is None:
            parent_of.append(-1)
        elif p not in seen:
            near = near_name(p, names) if isinstance(p, str) else None
            meant = "" if near is None else f" (did you mean {quoted(near)}?)"
            raise CharacterError(f"{where}[{i}].parent: unknown joint {quoted(p)}{meant}")
        elif p == names[i]:
            raise CharacterError(f"{where}[{i}].parent: joint {quoted(p)} is its own parent")
        else:
            parent_of.append(seen[p])
    roots = [i for i, pi in enumerate(parent_of) if pi < 0]
    if not roots:
        raise CharacterError(f"{where}: no root joint (every joint has a parent: a cycle)")
    # topological order by depth-first walk from the roots
    kids: dict[int, list[int]] = {}
    for i, pi in enumerate(parent_of):
        kids.setdefault(pi, []).append(i)
    order: list[int] = []
    stack = list(reversed(roots))
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(kids.get(j, [])))
    if len(order) != n:
        stuck = sorted(set(range(n)) - set(order))
        raise CharacterError(
            f"{where}: parent cycle through joints {shown([names[i] for i in stuck])} "
            "(they never reach a root)"
        )
    rank = {j: r for r, j in enumerate(order)}
    rot = [True] * n if rotatable is None else list(rotatable)
    tra = [p < 0 for p in parent_of] if translatable is None else list(translatable)
    skel = Skeleton(
        names=tuple(names[j] for j in order),
        parents=tuple(-1 if parent_of[j] < 0 else rank[parent_of[j]] for j in order),
        offsets=off[order],
        rotatable=tuple(rot[j] for j in order),
        translatable=tuple(tra[j] for j in order),
    )
    return skel, order


def forward_kinematics(skel: Skeleton, pose: Pose) -> tuple[F64, F64]:
    """World rotations ``[J, 3, 3]`` and positions ``[J, 3]`` of every joint (compiled:
    :mod:`core.compiled_characters`)."""
    return compiled_characters.forward_kinematics(
        skel.parent_array, pose.rotations, pose.translations
    )


# --------------------------------------------------------------------------------------
# Rotations
# --------------------------------------------------------------------------------------
def quat_to_matrix(q: npt.ArrayLike) -> F64:
    """``[..., 4]`` quaternions ``[x, y, z, w]`` (normalised here, whatever their length:
    one whose squared components overflow or underflow is first divided by its largest
    component) -> ``[..., 3, 3]``."""
    a = np.asarray(q, dtype=np.float64)
    with np.errstate(over="ignore", under="ignore"):
        n = np.linalg.norm(a, axis=-1, keepdims=True)
    odd = ~(np.isfinite(n) & (n > 1e-150))
    if odd.any():
        m = np.max(np.abs(a), axis=-1, keepdims=True)
        a = np.where(odd, a / np.where(m > 0, m, 1.0), a)
        n = np.linalg.norm(a, axis=-1, keepdims=True)
    a = a / n
    x, y, z, w = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    rows = (
        (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def matrix_to_quat(m: F64) -> F64:
    """``[..., 3, 3]`` rotation matrices -> unit quaternions ``[x, y, z, w]`` with w >= 0:
    each of the rotation nearest its matrix, so a slightly non-orthonormal input (a
    product of many rotations) gives the quaternion of its best rotation, not of its drift
    (compiled: :func:`core.compiled_characters.matrix_quats_into`)."""
    return compiled_characters.matrix_quats(np.asarray(m, dtype=np.float64))


def _cross(a: F64, b: F64) -> F64:
    """``np.cross`` of two 3-vectors, the same products and differences (its general
    form costs ~10 µs a call in its axis handling)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def swing(a: F64, b: F64) -> F64:
    """The minimal rotation taking the direction of ``a`` to the direction of ``b``; none
    (the identity) where either has no direction (zero length)."""
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if not (na > 0.0 and nb > 0.0):
        return np.eye(3)
    ua, ub = a / na, b / nb
    axis = _cross(ua, ub)
    s = float(np.linalg.norm(axis))
    c = float(np.dot(ua, ub))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        # opposite: half a turn about any axis perpendicular to a
        perp = _cross(ua, np.eye(3)[int(np.argmin(np.abs(ua)))])
        perp /= np.linalg.norm(perp)
        return np.asarray(2.0 * np.outer(perp, perp) - np.eye(3))
    k = axis / s
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.asarray(np.eye(3) + s * kx + (1.0 - c) * (kx @ kx))


def twist_angle(delta: F64, axis: F64) -> float:
    """Angle (radians) of the twist of rotation ``delta`` about ``axis`` (swing-twist split)."""
    q = matrix_to_quat(delta)
    k = axis / np.linalg.norm(axis)
    along = float(np.dot(q[:3], k))
    return float(2.0 * np.arctan2(abs(along), q[3]))


def units_scale(units: str | float) -> float:
    """Metres per unit for a unit name or a positive number; ``CharacterError`` otherwise."""
    if isinstance(units, str):
        if units not in UNITS:
            raise CharacterError(
                f"unknown units {quoted(units)}; use one of {sorted(UNITS)} or a number"
            )
        return UNITS[units]
    value = float(units)
    if not np.isfinite(value) or value <= 0:
        raise CharacterError(f"units must be a positive number of metres per unit, got {units}")
    return value


def up_rotation(up: str) -> F64:
    if up not in UP_AXES:
        raise CharacterError(f"unknown up axis {quoted(up)}; use one of {sorted(UP_AXES)}")
    return UP_AXES[up]


def as_f64(a: Any) -> F64:
    return np.asarray(a, dtype=np.float64)
