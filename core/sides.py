"""Whether a character's left and right are mirrored: its joints named for the other side.

A rig whose ``Left*`` joints are the body's right ones (named from the viewer's side, or
exported mirrored) is still a body, but the networks read it wrong: its facing comes from
its hips and shoulders, left minus right (:func:`core.geometry.canonical_transform`), so
they see it from behind, its toes and bent knees pointing backwards, a body no capture
holds. Solved so, a Bandai-Namco walk's five end effectors land 2.39 cm from the real pose
instead of 0.88 (``python -m bench.characters`` on the file with ``_L`` and ``_R`` swapped,
``--on-pelvis``, 30 edits; a lone wrist 9.55 against 8.89).

:func:`facing_score` says which way a pose's feet and knees point against the facing its
sides give: about +2 for a standing or walking body (toes ahead: +1; knees bent ahead,
weighted by :data:`KNEE_WEIGHT`), about -2 for the same body with its sides swapped (the
score of a pose with its sides swapped is minus its own), about 0 where feet and legs say
nothing (feet splayed, legs straight). :func:`mirrored` adds the rest pose's score to the
frame's and calls the sides swapped below :data:`SWAPPED_BELOW`. Of the 548,404 frames of
``data/poses.npz`` (five studios' bodies, the right way round) 24 score below it alone (CMU
dance); the swapped images of 262 would not, with a rest pose that says nothing (most rests
score +1: toes ahead, legs straight). Read through the BVH route, 1,260 frames of five
studios' files get no warning as they are and every one a warning with its sides swapped
(``python scripts/figures/sides.py``, 2026-12-07).
"""

from __future__ import annotations

from typing import Final

import numpy as np

from core.characters import F64
from core.characters_maps import JointMap
from core.skeleton import FACING_PAIRS, JOINT_INDEX
from core.text import quoted

#: the knees' forwardness (their offset from the hip-ankle line along the facing, over the
#: leg's length: ~0.1 for a body standing at ease) against the toes' (a cosine)
KNEE_WEIGHT: Final[float] = 10.0
#: the rest pose's score plus the frame's below which the sides are swapped
SWAPPED_BELOW: Final[float] = -0.5

_LEFT = [JOINT_INDEX[left] for left, _ in FACING_PAIRS]
_RIGHT = [JOINT_INDEX[right] for _, right in FACING_PAIRS]
#: the legs' joints: hips, knees, ankles, feet, each [left, right]
_LEGS = tuple([JOINT_INDEX[f"{side}_{j}"] for side in ("left", "right")]
              for j in ("hip", "knee", "ankle", "foot"))  # fmt: skip


def facing_score(points: F64) -> F64:
    """How far the 21 points' toes and knees point along the facing their sides give
    (points ``[..., 21, 3]``, +Y up, any units; the facing is
    :func:`core.geometry.canonical_transform`'s, left minus right over the hips and
    shoulders, turned a quarter about +Y): the mean over the legs of the toes' cosine to
    the facing on the floor plus :data:`KNEE_WEIGHT` times the knee's forwardness, ``[...]``;
    0 for what has no extent (no facing, a toe straight below its ankle, a straight leg)."""
    across = points[..., _LEFT, :].sum(axis=-2) - points[..., _RIGHT, :].sum(axis=-2)
    ahead = np.stack([-across[..., 2], np.zeros_like(across[..., 0]), across[..., 0]], -1)
    ahead = _unit(ahead, np.hypot(ahead[..., 0], ahead[..., 2]))[..., None, :]  # [..., 1, 3]
    hip, knee, ankle, foot = (points[..., j, :] for j in _LEGS)  # each [..., 2, 3]
    toe, thigh, line = foot - ankle, knee - hip, ankle - hip
    leg = _length(thigh) + _length(ankle - knee)
    flat = np.hypot(toe[..., 0], toe[..., 2])
    toes = _dot(_unit(toe, flat), ahead) * (flat > 1e-9 * leg)
    u = _unit(line, _length(line))
    bent = thigh - _dot(thigh, u)[..., None] * u
    knees = _dot(_unit(bent, leg), ahead)  # 0 along a straight leg: its bend is 0
    out: F64 = (toes + KNEE_WEIGHT * knees).mean(axis=-1)
    return out


def _length(v: F64) -> F64:
    out: F64 = np.sqrt((v * v).sum(axis=-1))
    return out


def _dot(a: F64, b: F64) -> F64:
    out: F64 = (a * b).sum(axis=-1)
    return out


def _unit(v: F64, length: F64) -> F64:
    """``v`` over its ``length`` (``[...]``), 0 where that is 0."""
    out: F64 = v / np.where(length > 0.0, length, np.inf)[..., None]
    return out


def mirrored(rest: F64, frame: F64) -> bool:
    """Whether a character's sides are swapped: its rest pose's and the frame's 21 points
    (each ``[21, 3]``, +Y up) together score below :data:`SWAPPED_BELOW`."""
    return bool(facing_score(np.stack([rest, frame])).sum() < SWAPPED_BELOW)


def read_sides(rest: F64, frame: F64, jmap: JointMap) -> tuple[JointMap, str | None]:
    """The map to solve with, and the answers' ``sides_warning``, of a character whose
    rest pose and frame map to ``rest`` and ``frame`` (each ``[21, 3]``, +Y up) by ``jmap``:
    where they are :func:`mirrored`, an automatic map swapped (:meth:`JointMap.swapped`:
    every joint keeps its name, the body is solved as the body it is) and a map the client
    gave kept, each saying so; else ``jmap`` and None."""
    if not mirrored(rest, frame):
        return jmap, None
    named = jmap.describe()
    left, right = quoted(named["left_hip"]), quoted(named["right_hip"])
    seen = (
        "read as its joints' names say, its toes and bent knees point backwards from the way "
        "its hips and shoulders face it (in its rest pose and this frame)"
    )
    if "explicit" in jmap.scheme:
        return jmap, (
            f"joint_map: this body's left and right look swapped: {seen}; solved with the "
            "joint_map given, which the networks read as a body seen from behind: swap its "
            f"left_ and right_ entries if the body's own left hip is {right}"
        )
    return jmap.swapped(), (
        f"joint_map: this body's left and right joints are named for the other side: {seen}; "
        f"solved as the body it is, {left} its right hip and {right} its left, and so on for "
        "every limb (the answer's joint_map). Its joints keep their names; a canonical name "
        "(left_wrist) names the body's own side. To solve its sides as named, give joint_map"
    )
