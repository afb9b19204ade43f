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
nothing (feet splayed, legs straight). :func:`mirrored` lets the rest pose decide where
it scores beyond :data:`REST_DECIDES` either way (most rests score +1: toes ahead, legs
straight), else the frame, below :data:`SWAPPED_BELOW`. Of the 548,404 frames of
``data/poses.npz`` (five studios' bodies, the right way round) 24 score below that alone
(CMU dance, whose rests decide); the swapped images of 262 would not. Read through the BVH
route, 1,260 frames of five studios' files get no warning as they are and every one a
warning with its sides swapped (``python scripts/figures/sides.py``, 2026-12-07).
"""

from __future__ import annotations

from collections.abc import Collection
from typing import Final

import numpy as np

from core.characters import F64
from core.characters_maps import JointMap
from core.geometry import across
from core.skeleton import JOINT_INDEX
from core.text import quoted

#: the knees' forwardness (their offset from the hip-ankle line along the facing, over the
#: leg's length: ~0.1 for a body standing at ease) against the toes' (a cosine)
KNEE_WEIGHT: Final[float] = 10.0
#: a frame's score below which its sides are swapped, where the rest pose says nothing
SWAPPED_BELOW: Final[float] = -0.5
#: a rest pose's score beyond which (either way) it alone says which side is which
REST_DECIDES: Final[float] = 0.5

#: the canonical joints of a side
_SIDED = tuple(c for c in JOINT_INDEX if c.startswith(("left_", "right_")))
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
    side: F64 = np.asarray(across(points), dtype=np.float64)
    ahead = np.stack([-side[..., 2], np.zeros_like(side[..., 0]), side[..., 0]], -1)
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


def mirrored(rest: F64, frame: F64, upright: tuple[bool, bool] = (True, True)) -> str | None:
    """Where a character's sides are swapped, what says so: "its rest pose", whose score
    decides alone beyond :data:`REST_DECIDES` either way (one rig, one answer for all its
    frames: frames alone called a correctly named CMU dance file swapped in 17 of its 2,314
    frames, a review, 2026-12-07), else "this frame, ..." below :data:`SWAPPED_BELOW` (a rest
    with its feet splayed, Bandai-Namco's); None where they are as named (each ``[21, 3]``,
    +Y up). ``upright``: whether the rest pose and the frame stand up along +Y as read; one
    that does not (an up axis not its own: a body lying down) says nothing (a Z-up rig's
    rest read +Y up was called swapped)."""
    own, now = facing_score(np.stack([rest, frame])).tolist()
    if upright[0] and abs(own) > REST_DECIDES:
        return "its rest pose" if own < 0.0 else None
    if upright[1] and now < SWAPPED_BELOW:
        return "this frame, its rest pose saying nothing"
    return None


def read_sides(
    rest: F64, frame: F64, jmap: JointMap, given: Collection[str] = (),
    upright: tuple[bool, bool] = (True, True),
) -> tuple[JointMap, str | None]:  # fmt: skip
    """The map to solve with, and the answers' ``sides_warning``, of a character whose
    rest pose and frame map to ``rest`` and ``frame`` (each ``[21, 3]``, +Y up) by ``jmap``
    (``given``: the canonical joints the client's ``joint_map`` names; ``upright``:
    :func:`mirrored`'s): where they are
    :func:`mirrored`, the map swapped (:meth:`JointMap.swapped`: every joint keeps its name,
    the body is solved as the body it is; entries the client gave for centre joints are
    their own mirror images), each saying so; kept where the client named a side joint in
    its map, or where the rig's own joints carry the canonical side names (``left_wrist``:
    swapped, every such name would read two ways), saying that; else ``jmap`` and None."""
    if (why := mirrored(rest, frame, upright)) is None:
        return jmap, None
    named = jmap.describe()
    left, right = quoted(named["left_hip"]), quoted(named["right_hip"])
    seen = (
        "read as its joints' names say, its toes and bent knees point backwards from the way "
        f"its hips and shoulders face it (in {why})"
    )
    told = any(c in given for c in _SIDED)
    if told or any(named[c] in JOINT_INDEX for c in _SIDED):
        by = "the joint_map given says" if told else "its names say"
        return jmap, (
            f"joint_map: this body's left and right look swapped: {seen}; solved as {by}, "
            "which the networks read as a body seen from behind: swap the "
            f"left_ and right_ entries of joint_map if the body's own left hip is {right}"
        )
    return jmap.swapped(), (
        f"joint_map: this body's left and right joints are named for the other side: {seen}; "
        f"solved as the body it is, {left} its right hip and {right} its left, and so on for "
        "every limb (the answer's joint_map). Its joints keep their names; a canonical name "
        "(left_wrist) names the body's own side. To solve its sides as named, give joint_map "
        "its left_ and right_ entries"
    )
