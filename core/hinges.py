"""Elbows and knees that bend as hinges stay hinges (numpy; the last step of
:func:`core.retarget.retarget`).

The retarget aims each bone by its swing alone, so the upper arm (thigh) keeps its twist
and the forearm (shin) reaches its solved place by whatever turn of the elbow (knee) takes
it there: on CMU salsa, whose ``lForeArm`` never turns more than 0.9 degrees off one axis in
the whole clip, a wrist dragged 15-20 cm left the elbow 10-27 degrees off it, the target
met. The same points are reached with the upper arm twisted about its own bone instead.

:func:`keep_hinges`: where the frame as sent bends an elbow or knee as a hinge, by at
least :data:`MIN_BEND` about an axis (its local rotation's, in its parent's frame) within
:data:`MAX_LEAN` of square to the lower bone (no roll of the forearm about itself), the
answer's bends about that same axis: the upper arm's (thigh's) turn about the line from
its joint to the elbow's (knee's) and the elbow's angle are chosen so the forearm (shin)
points where the answer put it, keeping the bend's side (a positive angle about the axis)
and, of the two such, the smaller twist. A joint below the elbow (knee) whose turn places a
mapped point (an ankle: the toe) keeps its world rotation (its local rotation takes the
difference), so every mapped point stays where the answer had it (checked: a limb that
would move one by more than rounding is left as it was); the others (a hand and its
fingers: none of them is mapped below the wrist) keep their local rotations, as in the
aim. Bone lengths are the character's own (no offset changes).
"""

from __future__ import annotations

import numpy as np

from core import compiled_hinges
from core.characters import Pose, Skeleton, matrix_to_quat
from core.characters_maps import JointMap
from core.skeleton import JOINT_INDEX

#: (top, hinge, end) canonical joints: the arms and legs
LIMBS = tuple(
    tuple(JOINT_INDEX[f"{side}_{j}"] for j in names)
    for names in (("shoulder", "elbow", "wrist"), ("hip", "knee", "ankle"))
    for side in ("left", "right")
)
#: radians: the least bend whose axis is taken as the hinge's (below it, a straight limb's
#: axis is mostly the capture's noise: salsa's elbows wander up to 0.9 degrees off theirs,
#: 0.1 in 95 % of its frames; a 2-degree bend's axis is within 3 degrees of the clip's
#: there, and the FAIR child's elbow, a hinge to the last digit, bent 4.6 degrees)
MIN_BEND = np.radians(2.0)
#: the most a hinge's axis may lean off square to the lower bone (a rotation with more
#: turns the forearm about itself too: Bandai-Namco's elbows, 12-70 degrees off, carry the
#: forearm's roll, and bending them about their axis took a 29-degree bend to 96 degrees)
MAX_LEAN = np.radians(10.0)
#: a mapped point may move this much (times the limb's length) by rounding, no more
_STILL = 1e-9


def keep_hinges(
    skel: Skeleton, before: Pose, pose: Pose, jmap: JointMap, changed: set[int]
) -> set[int]:
    """Turn ``pose`` (in place; the answer to the frame ``before``) so each limb whose
    hinge ``before`` bends by :data:`MIN_BEND` or more bends about the same axis (module
    docstring); ``changed``: the joints the answer changed (a limb none of whose two
    joints is among them is left). Returns the joints whose local rotation it changed.
    The arithmetic is compiled (:func:`core.compiled_hinges.keep_hinges_into`)."""
    limbs = [(jmap.anchors[top].joint, jmap.anchors[mid].joint, end) for top, mid, end in LIMBS
             if _applies(skel, jmap, jmap.anchors[top].joint, jmap.anchors[mid].joint, top, mid,
                         changed)]  # fmt: skip
    if not limbs:
        return set()
    quats = matrix_to_quat(before.rotations[[hinge for _, hinge, _ in limbs]])
    places = _placing(skel, jmap)
    held = [[c for c in skel.children(hinge) if skel.rotatable[c] and c in places]
            for _, hinge, _ in limbs]  # fmt: skip
    rotations = np.array(pose.rotations, dtype=np.float64, order="C")  # (turned in a copy)
    turned = np.zeros(skel.size, dtype=np.uint8)
    compiled_hinges.keep_hinges_into(
        np.require(skel.parent_array, np.int64, ["C", "W"]), rotations,
        np.require(pose.translations, np.float64, ["C", "W"]),
        np.require(jmap.joints, np.int64, ["C", "W"]),
        np.require(jmap.offsets.reshape(-1, 3), np.float64, ["C", "W"]),
        np.asarray(limbs, dtype=np.int64).reshape(-1, 3), np.require(quats, np.float64, ["C", "W"]),
        np.cumsum([0, *map(len, held)]).astype(np.int64),
        np.asarray([c for h in held for c in h], dtype=np.int64), float(MIN_BEND),
        float(np.sin(MAX_LEAN)), _STILL, turned,
    )  # fmt: skip
    pose.rotations = rotations
    return {int(j) for j in np.flatnonzero(turned)}


def _applies(
    skel: Skeleton, jmap: JointMap, upper: int, hinge: int, top: int, mid: int, changed: set[int]
) -> bool:
    """Whether a limb's twist can be chosen: both joints turn, the hinge hangs below the
    upper joint, both canonical points sit on their joints, and the answer changed one."""
    if upper == hinge or not (skel.rotatable[upper] and skel.rotatable[hinge]):
        return False
    if upper not in changed and hinge not in changed:
        return False
    if jmap.anchors[top].offset.any() or jmap.anchors[mid].offset.any():
        return False
    return skel.is_ancestor(upper, skel.parents[hinge])


def _placing(skel: Skeleton, jmap: JointMap) -> set[int]:
    """The joints whose rotation places a mapped point (one hangs below it, or off its
    origin on it: an ankle's toe), not only themselves (a hand at the wrist's point)."""
    out = set()
    off = np.any(jmap.offsets.reshape(-1, 3) != 0, axis=1).tolist()
    for anchor, placed_off in zip(jmap.anchors, off, strict=True):
        if placed_off:
            out.add(anchor.joint)
        j = skel.parents[anchor.joint]
        while j >= 0 and j not in out:
            out.add(j)
            j = skel.parents[j]
    return out
