"""The answers' ``handedness_warning`` of a pose whose left and right look mirrored
(``/v1/solve``'s start pose in the pose form, each item of a batch, each columnar row): a
pose sent in left-handed coordinates (x mirrored, as Unity's) was solved without a word,
where the character form says so (``sides_warning``, :mod:`core.sides`). One definition:
:func:`core.sides.facing_score` below :data:`core.sides.SWAPPED_BELOW` (its toes and bent
knees point backwards from the way its hips and shoulders face it), of a start pose that
stands upright (:mod:`service.upright`: one lying down says nothing of its sides).

Measured (2026-12-07, ``data/poses.npz``): no pose of the TEST split (26,458) or of the
held-out bodies (86,635: ReActIdle, the child-sized skeletons, CMU subjects) scores below
it (their lowest -0.14 and 0.49); their x-mirrored images do but for 29 and 2 (65 and 18
unwarned with those lying down, of whose sides nothing is said). A lone pose
is scored by :func:`_score_one` in ~4 us (``facing_score`` of one pose: ~43 us; a batch's,
~0.36 us a pose at 1,024), the same number to 1e-15, and by ``facing_score`` itself where
it lies that near the threshold. The solve is answered as asked.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from core.sides import KNEE_WEIGHT, SWAPPED_BELOW, facing_score
from core.skeleton import JOINT_INDEX
from service.upright import LEAN, leans

F64 = npt.NDArray[np.floating[Any]]

_PELVIS, _NECK = JOINT_INDEX["pelvis"], JOINT_INDEX["neck"]
#: hips, shoulders, knees, ankles, feet: each left, right
_JOINTS = [
    JOINT_INDEX[f"{side}_{j}"]
    for j in ("hip", "shoulder", "knee", "ankle", "foot")
    for side in ("left", "right")
]
#: how near the threshold a lone pose's own score is checked by ``facing_score`` itself
_NEAR = 1e-9

WORDS = (
    "pose: its left and right look mirrored: read as its joints' names say, its toes and bent "
    "knees point backwards from the way its hips and shoulders face it (a pose in left-handed "
    "coordinates, x mirrored as Unity's, or its sides swapped), which the networks read as a "
    "body seen from behind and solved so; negate every x (targets too) of a left-handed "
    "capture, or swap its left_ and right_ joints"
)


def handedness_warnings(poses: F64) -> list[str | None]:
    """The ``handedness_warning`` of each start pose of ``poses`` (``[B, 21, 3]``, world),
    in one numpy pass (a batch's items, the columnar form's rows)."""
    scores = facing_score(np.asarray(poses, dtype=np.float64))
    out: list[str | None] = [None] * len(poses)
    low = scores < SWAPPED_BELOW
    if low.any():
        for b in np.flatnonzero(low).tolist():
            out[b] = _said(poses[b])
    return out


def handedness_warning(pose: F64) -> str | None:
    """The ``handedness_warning`` of one start pose (``[21, 3]``, world): as
    :func:`handedness_warnings` says it, in ~4 us."""
    score = _score_one(pose)
    if abs(score - SWAPPED_BELOW) <= _NEAR:
        return handedness_warnings(pose[None])[0]
    return _said(pose) if score < SWAPPED_BELOW else None


def _said(pose: F64) -> str | None:
    """The words, for a pose that scores below the threshold, unless it lies down."""
    return WORDS if float(leans(pose[_NECK] - pose[_PELVIS])) <= LEAN else None


def _score_one(pose: F64) -> float:
    """:func:`core.sides.facing_score` of one pose ``[21, 3]``, in Python floats."""
    (lh, rh, (lsx, _, lsz), (rsx, _, rsz), lk, rk, la, ra, lf, rf) = pose[_JOINTS].tolist()
    sx, sz = lh[0] - rh[0] + lsx - rsx, lh[2] - rh[2] + lsz - rsz
    norm = math.hypot(sz, sx)
    if not norm > 0.0:
        return 0.0
    ax, az = -sz / norm, sx / norm
    total = 0.0
    for (hx, hy, hz), (kx, ky, kz), (nx, ny, nz), (fx, _, fz) in ((lh, lk, la, lf),
                                                                   (rh, rk, ra, rf)):  # fmt: skip
        tx, tz = fx - nx, fz - nz
        thx, thy, thz = kx - hx, ky - hy, kz - hz
        lx, ly, lz = nx - hx, ny - hy, nz - hz
        leg = math.sqrt(thx * thx + thy * thy + thz * thz) + math.sqrt(
            (nx - kx) ** 2 + (ny - ky) ** 2 + (nz - kz) ** 2
        )
        flat = math.hypot(tx, tz)
        toes = (tx * ax + tz * az) / flat if flat > 1e-9 * leg else 0.0
        line = math.sqrt(lx * lx + ly * ly + lz * lz)
        ux, uy, uz = (lx / line, ly / line, lz / line) if line > 0.0 else (0.0, 0.0, 0.0)
        along = thx * ux + thy * uy + thz * uz
        knees = ((thx - along * ux) * ax + (thz - along * uz) * az) / leg if leg > 0.0 else 0.0
        total += toes + KNEE_WEIGHT * knees
    return total / 2
