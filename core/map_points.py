"""Points part-way along a bone in a joint map, as :meth:`core.characters_maps.JointMap.describe`
writes them (``"0.35 of spine.001->neck"``: a canonical joint that would sit on its parent,
slid along its own bone) and a client may send back in ``joint_map``: how one is read, and
the refusals of one the map does not make, each naming ``joint_map.<canonical>``."""

from __future__ import annotations

import re

from core.characters import CharacterError, Skeleton
from core.text import quoted

#: A point part-way along a bone as :meth:`JointMap.describe` writes it (a joint sliding
#: along its bone, where it would sit on its parent): accepted back in a ``joint_map``.
SLID = re.compile(r"([0-9.]+) of (.+)->(.+)")


def slid_point(skel: Skeleton, name: str) -> re.Match[str] | None:
    """``name`` read as a point along a bone (its first joint one of the skeleton's), else
    None (a joint's name, or no point)."""
    along = SLID.fullmatch(name) if name not in skel.index else None
    return along if along is not None and along.group(2) in skel.index else None


def fraction(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def along_a_bone(skel: Skeleton, along: re.Match[str], where: str) -> None:
    """Refuse a point ``<fraction> of <joint>-><joint below it>`` whose bone is not one:
    an end the skeleton has not, or the two joints reversed (was: read as the first joint,
    and refused by the map's hierarchy, the point itself not named)."""
    point, top, bottom = along.group(0), along.group(2), along.group(3)
    if bottom not in skel.index:
        raise CharacterError(
            f"{where}: {quoted(point)}: the skeleton has no joint {quoted(bottom)}"
        )
    t, b = skel.index[top], skel.index[bottom]
    if t == b or not skel.is_ancestor(t, b):
        hint = (
            f" (reversed: {quoted(top)} is below it)" if t != b and skel.is_ancestor(b, t) else ""
        )
        raise CharacterError(
            f"{where}: {quoted(point)} is no point along a bone: {quoted(bottom)} is not below "
            f"{quoted(top)} in the skeleton{hint}; a point reads '<fraction> of "
            "<joint>-><a joint below it>', as an answer's joint_map writes it"
        )


def not_made(skel: Skeleton, where: str, point: str, made: str) -> str:
    """The refusal (at the field ``where``) of a ``point`` along a bone that the map does
    not make (it makes ``made``), saying so where its two joints are not parent and child
    (the parent the lower one has)."""
    along = SLID.fullmatch(point)
    why = ""
    if along is not None and along.group(3) in skel.index:
        top, bottom = along.group(2), along.group(3)
        parent = skel.parents[skel.index[bottom]]
        if parent < 0 or skel.names[parent] != top:
            has = (
                f"the parent of {quoted(bottom)} is {quoted(skel.names[parent])}"
                if (parent >= 0)
                else f"{quoted(bottom)} is a root"
            )
            why = f": {quoted(top)} and {quoted(bottom)} are not parent and child ({has})"
    return (
        f"{where}: {quoted(point)} is not a point this map makes (it makes {quoted(made)})"
        f"{why}; name a joint of the skeleton"
    )
