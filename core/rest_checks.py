"""Rest poses a joint map cannot be read from, said as what they are, for
:func:`core.characters_maps.resolve_map`: a skeleton whose offsets put every joint at one
point (a BVH that carries its bones in position channels, every OFFSET 0 0 0), and one
offset out of proportion with the body's other bones (a value in other units: the docs'
character with its Neck 170 m up, ``[0, 170, 0]`` for ``0.17``).

Was: the map's own refusals, which blamed the map: "joint_map: no joint found for
['spine1']" (no joint off the pelvis), and "joint_map: spine1 (Spine) sits on pelvis (Hips)"
(the 12 cm spine counted as zero length against a body 170 m tall), located at a joint_map
the request did not have (an audit, 2026-12-06)."""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np

from core.characters import CharacterError, Skeleton
from core.text import quoted

#: Where a skeleton's offsets are, for a refusal: joint -> its offset's field, None -> the
#: offsets' (e.g. ``character.joints[3].offset`` and ``character.joints``; ``bvh``).
OffsetAt = Callable[[int | None], str]

#: How many times the body's median bone a bone on the map's paths may be before a map
#: that fails for it is refused for that bone (a person's longest bone, the thigh, is ~4
#: times the median of their bones; a value in centimetres in a character in metres, 100).
OUT_OF_PROPORTION = 50.0


def default_offset_at(joint: int | None) -> str:
    return "skeleton"


def refuse_one_point(skel: Skeleton, at: OffsetAt) -> None:
    """Refuse a skeleton of more than one joint whose rest pose has them all at one point:
    no bone, no map, no units and no up can be read from it."""
    rest = skel.rest_positions()
    if skel.size < 2 or float(np.ptp(rest, axis=0).max()) > 0.0:
        return
    where = at(None)
    raise CharacterError(
        f"{where}: the rest pose has every joint at one point (every offset but the root's is "
        "0 0 0), so the skeleton cannot be read from it: the joint map, the units and the up "
        "axis are read from the rest pose's bones; give each joint's offset from its parent "
        "(a file that carries its bones in position channels instead: write them as OFFSETs)",
        where,
    )


def refuse_out_of_proportion(skel: Skeleton, bones: Iterable[int], at: OffsetAt) -> None:
    """Refuse the longest of the offsets of ``bones`` (the joints on the map's paths) where
    it is more than :data:`OUT_OF_PROPORTION` times their median (of those not zero): the
    map, which measures what is zero length against the body's size, fails for it."""
    joints = sorted(set(bones))
    if not joints:
        return
    lengths = np.linalg.norm(skel.offsets[joints], axis=1)
    nonzero = lengths[lengths > 0]
    if nonzero.size < 3:
        return
    median = float(np.median(nonzero))
    k = int(np.argmax(lengths))
    if lengths[k] <= OUT_OF_PROPORTION * median:
        return
    j = joints[k]
    where = at(j)
    parent = skel.parents[j]
    of = f" from {quoted(skel.names[parent])}" if parent >= 0 else ""
    vector = [round(float(v), 6) for v in skel.offsets[j]]
    raise CharacterError(
        f"{where}: the offset of {quoted(skel.names[j])}{of}, {vector}, is "
        f"{lengths[k] / median:.0f} times the median of the body's bones ({median:.4g}): "
        "out of proportion with them (a value in other units?), so that the body's shorter "
        "bones read as zero length; give it in the units of the others",
        where,
    )
