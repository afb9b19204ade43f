"""Which canonical joint a character's target or pin names (docs/characters.md: "Targets
and pins name the client's joints (those mapped to a canonical joint) or the canonical
names").

A name that is both, a joint of the skeleton and a canonical name that joint is not mapped
to (a finger renamed ``left_wrist`` while canonical ``left_wrist`` is the hand; DAZ Genesis
9's ``spine2``, whose canonical ``spine2`` is its ``spine4``), is ambiguous: it is refused,
naming the joint and both readings (was: read as the canonical joint, and the answer said it
reached its target while the client's own joint of that name ended elsewhere).

A joint of the skeleton that the map puts no canonical joint on (Mixamo's ``Spine1`` where
canonical spine1 is its ``Spine``) is refused saying so, with the ``joint_map`` entry that
makes it one (was: "did you mean 'spine1'?", and following it moved ``Spine``)."""

from __future__ import annotations

import json
from typing import NoReturn

from core.characters import Skeleton
from core.characters_maps import JointMap
from core.skeleton import JOINT_INDEX, JOINT_NAMES
from core.text import QUOTE, name_key, near_name, printable, quoted
from service.errors import InvalidRequest


def resolve_joint(skel: Skeleton, jmap: JointMap, name: str, where: str) -> int:
    """The canonical joint (index) that ``name`` names: a mapped joint of ``skel`` (the
    origin of the joint a canonical joint is mapped to), else a canonical name; refused
    (422 at ``where``) when neither, or when ambiguous (above)."""
    own = skel.index.get(name)
    canon = JOINT_INDEX.get(name)
    if canon is not None:  # the canonical joint, unless the skeleton's joint so named is not it
        if own is None or jmap.anchors[canon].joint == own:
            return canon
        _ambiguous(jmap, name, own, canon, where)
    for k, a in enumerate(jmap.anchors):
        if a.joint == own and not a.offset.any():
            return k
    mapped = ", ".join(f"{n} ({lbl})" for n, lbl in jmap.describe().items())
    if own is not None:
        _unmapped(jmap, name, where, mapped)
    known = [*(skel.names[a.joint] for a in jmap.anchors if not a.offset.any()), *JOINT_INDEX]
    meant = near_name(name, known)  # (maps ignore case; not here)
    near = f" (did you mean {quoted(meant)}?)" if meant is not None else ""
    raise InvalidRequest(
        f"{where}: {quoted(name)} is neither a mapped joint of this skeleton nor a canonical "
        f"joint{near}; mapped: {mapped}"
    )


def _ambiguous(jmap: JointMap, name: str, own: int, canon: int, where: str) -> NoReturn:
    """Refuse ``name``: the skeleton's joint ``own`` and the canonical joint ``canon``,
    which the map puts elsewhere."""
    as_own = [c for c, a in zip(JOINT_NAMES, jmap.anchors, strict=True) if a.joint == own]
    theirs = f"mapped to {', '.join(as_own)}" if as_own else "not in the map"
    point = jmap.anchors[canon]
    other = (
        f"name {quoted(point.label)} for the canonical joint, " if not point.offset.any() else ""
    )
    fix = f'{other}give "joint_map": {{"{name}": "{name}"}} to map it onto this joint'
    raise InvalidRequest(
        f"{where}: {quoted(name)} is ambiguous: it is this skeleton's joint {quoted(name)} "
        f"({theirs}) and the canonical joint {name}, which the map puts on "
        f"{quoted(point.label)}; {fix}, or rename the joint"
    )


def _unmapped(jmap: JointMap, name: str, where: str, mapped: str) -> NoReturn:
    """Refuse ``name``, a joint of the skeleton that no canonical joint is mapped to, with
    the ``joint_map`` entry that maps one onto it: never a "did you mean" the canonical
    joint named like it (``spine1`` for ``Spine1``), which stands for another joint."""
    like = [c for c in JOINT_NAMES if name_key(c) == name_key(name)]
    canon = like[0] if like else "<canonical joint>"
    elsewhere = jmap.anchors[JOINT_INDEX[canon]].label if like else ""
    there = f"; the map puts the canonical joint {canon} on {quoted(elsewhere)}" if like else ""
    value = json.dumps(name, ensure_ascii=False) if len(name) <= QUOTE else "<its name>"
    fix = printable(f'give "joint_map": {{"{canon}": {value}}}')
    raise InvalidRequest(
        f"{where}: {quoted(name)} is a joint of this skeleton that no canonical joint is "
        f"mapped to{there}; {fix} to map {canon if like else 'one'} onto this joint and "
        f"target it; mapped: {mapped}"
    )
