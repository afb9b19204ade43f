"""Which joint of a skeleton a naming scheme's candidate name finds, for
:func:`core.characters_maps.resolve_map`: names are compared without case, without a
``namespace:`` prefix (``mixamorig:``) and without a start every name shares (HumanIK's
``Character1_``), but a closer spelling wins over a looser one: the name as written over a
case-folded one, over a namespace-stripped one, over a shared-prefix-stripped one. Two joints
that match a candidate equally well are a tie, which the map refuses, naming both.

Was: the first joint in file order that matched in any way (a socket ``LEFTHAND`` under
``LeftForeArm``, listed before the real ``LeftHand``, became the wrist: every wrist target
and pin moved the socket, and the answer said it was reached; an audit, 2026-12-06)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from core.text import near_name, quoted

#: the most of a skeleton's joint names a refusal of a map lists, and the characters they
#: may take (quoted, each at most core.text.QUOTE): then how many more
LISTED_NAMES = 40
LISTED_CHARS = 1500


def name_key(name: str) -> str:
    """A name as it is looked up: no case, no ``namespace:`` prefix."""
    return name.rsplit(":", 1)[-1].lower()


#: A joint a key finds: (joint, spelling, looseness); ``spelling`` is the part of its name
#: that is compared (its name less a namespace or a shared start), ``looseness`` 0 for the
#: name itself, 1 with a namespace dropped, 2 with the shared start dropped too. (A tuple:
#: a lookup of a 2,000-joint skeleton is made for each request.)
Match = tuple[int, str, int]


@dataclass
class Lookup:
    """Every key's matches (:func:`lookup_of`), and what a scheme's resolution found tied:
    canonical joint -> the joints that match its candidate equally well."""

    keys: dict[str, list[Match]]
    ties: dict[str, tuple[int, ...]] = field(default_factory=dict)

    def __contains__(self, key: str) -> bool:
        return key in self.keys

    def find(self, key: str, written: str) -> tuple[int, tuple[int, ...]]:
        """The joint that ``key`` (of the candidate ``written``) finds, the closest match
        (first in file order among equals), and the joints that match it as well (one:
        no tie)."""
        matches = self.keys[key]
        if len(matches) == 1:
            return matches[0][0], ()
        grades = [(loose, spelling != written) for _, spelling, loose in matches]
        best = min(grades)
        tied = tuple(m[0] for m, g in zip(matches, grades, strict=True) if g == best)
        return tied[0], tied if len(tied) > 1 else ()


def lookup_of(names: tuple[str, ...], shared_prefix: str) -> Lookup:
    """The lookup of a skeleton's joint ``names``, in file order; ``shared_prefix``: the
    start every key shares (lower case; "" for none), also dropped."""
    keys: dict[str, list[Match]] = {}
    for i, name in enumerate(names):
        bare = name.rsplit(":", 1)[-1]
        keys.setdefault(bare.lower(), []).append((i, bare, int(bare != name)))
    if shared_prefix:  # "Character1_LeftArm" is also "LeftArm"
        cut = len(shared_prefix)
        for i, name in enumerate(names):
            bare = name.rsplit(":", 1)[-1][cut:]
            found = keys.setdefault(bare.lower(), [])
            if all(m[0] != i for m in found):
                found.append((i, bare, 2))
    return Lookup(keys)


def tie_message(where: str, canon: str, written: str, names: list[str]) -> str:
    """A refusal of a tie: ``names`` (two or more) all match ``canon``'s candidate
    ``written`` equally well."""
    both = " and ".join(quoted(n) for n in names[:4])
    more = f" (and {len(names) - 4} more)" if len(names) > 4 else ""
    return (
        f"{where}: {canon} is ambiguous: the joints {both}{more} "
        f"{'both' if len(names) == 2 else 'all'} read as {quoted(written)} "
        "(names are compared without case, a namespace: prefix or a start every name shares); "
        f'give "joint_map": {{"{canon}": "<the joint>"}} to choose one, or rename the other'
    )


def missing_message(
    where: str, missing: list[str], closest: str | None, names: Sequence[str], schemes: str
) -> str:
    """A refusal of a map that finds no joint for the canonical joints ``missing``: the
    scheme that came closest (None: no joint name matched any scheme's), and the
    skeleton's joints ``names`` in file order (the first :data:`LISTED_NAMES`, within
    :data:`LISTED_CHARS`, then how many more), for a client to write ``joint_map`` with.
    Was the scheme alone, "closest" too where no name matched any (a new-user audit,
    2026-12-06: a rig renamed `root_jnt`, `hand_lf`, ... got "closest naming scheme:
    bandai-namco", and no joint name to write the map with). The form of a point along a
    bone is offered too: an API audit (2026-12-07) built a rig without clavicles, and the
    refusal named only joints, though ``"0.25 of Spine3->LeftArm"`` answered it."""
    listed: list[str] = []
    size = 0
    for name in names[:LISTED_NAMES]:
        size += len(shown := quoted(name)) + 2
        if size > LISTED_CHARS:
            break
        listed.append(shown)
    more = f" and {len(names) - len(listed)} more" if len(names) > len(listed) else ""
    why = f"closest naming scheme: {closest}" if closest else "no joint name matched a scheme's"
    return (
        f"{where}: no joint found for {missing} ({why}); give them in joint_map as "
        f"{{canonical: joint name}}, naming one of the skeleton's {len(names)} joints: "
        f"{', '.join(listed)}{more}, or a point part-way along a bone where the rig has no "
        f'such joint (a rig without clavicles: {{"{missing[0]}": "0.25 of <joint>-><its '
        f'child>"}}); schemes found automatically: {schemes}'
    )


def near(names: Sequence[str], name: str) -> str:
    """`` (did you mean 'Left  Hand'?)`` for a joint named as ``name`` is but for case and
    blanks among a skeleton's ``names`` (offered as written: a file's two spaces are two),
    or a slip of one (``LeftHnad``: :func:`core.text.near_name`), else nothing."""
    found = near_name(name, names)
    return "" if found is None else f" (did you mean {quoted(found)}?)"
