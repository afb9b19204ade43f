"""Joint maps: which point of a character's skeleton is each of the 21 canonical joints.

A canonical joint is a *point*: the origin of one of the character's joints (where that
joint's bone starts), or a point fixed in one joint's frame (an End Site, or a point part-way
along a bone where the skeleton has no joint there). :class:`Anchor` holds that.

:func:`auto_map` tries every naming scheme of :data:`SCHEMES` (names compared without case
and without a ``namespace:`` prefix such as ``mixamorig:``, and also without a start that
every joint's name shares, such as HumanIK's ``Character1_``; a closer spelling wins, two
as close a 422: :mod:`core.map_lookup`) and keeps the one that resolves
all 21 joints with the most names; an explicit map (canonical -> joint name) always wins
over it, joint by joint. Then two structural rules apply to every map:

- ``spine2`` (the chest) is, unless named, the lowest common ancestor of the two collars,
  and ``spine1``, unless named, the first joint below the pelvis on the way to it that is
  not on the pelvis;
- a canonical joint that lands on its canonical parent (zero rest length: within a thousandth
  of the mapped joints' extent, whatever joints the map leaves out) is moved part-way
  along its own bone: a collar a quarter of the way to the shoulder (CMU skeletons start
  both clavicles on the midline), the chest 0.35 of the way to the neck (ReActIdle has one chest
  joint); so are two collars on one point (CMU ASF and Rigify start both clavicles where
  the neck does). Any other zero-length canonical bone is an error asking for an explicit
  map, or naming the one bone out of proportion that made it (:mod:`core.rest_checks`,
  which also refuses a rest pose with every joint at one point).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Final

import numpy as np
import numpy.typing as npt

from core.characters import F64, CharacterError, Skeleton
from core.map_lookup import Lookup, lookup_of, missing_message, near, tie_message
from core.map_lookup import name_key as _key
from core.map_points import along_a_bone, fraction, not_made, slid_point
from core.rest_checks import OffsetAt, default_offset_at, refuse_one_point, refuse_out_of_proportion
from core.skeleton import JOINT_INDEX, JOINT_NAMES, MIRROR, PARENT_NAMES
from core.text import clip, quoted
from core.units import UNITS

_LIMBS = ("collar", "shoulder", "elbow", "wrist", "hip", "knee", "ankle", "foot")


@dataclass(frozen=True)
class Scheme:
    description: str
    sides: tuple[tuple[str, str], ...]  # (left token, right token) pairs to try for "{s}"
    joints: Mapping[str, tuple[str, ...]]  # canonical (or "collar"...) -> candidate names
    prefixes: tuple[str, ...] = ("",)  # put before every candidate, one at a time


def _scheme(
    description: str,
    sides: tuple[tuple[str, str], ...],
    prefixes: tuple[str, ...] = ("",),
    /,
    **joints: str,
) -> Scheme:
    return Scheme(description, sides, {k: tuple(v.split("|")) for k, v in joints.items()}, prefixes)


#: MotionBuilder's (HumanIK's) arm names, kept by Mixamo, Rokoko and SOMA: ``{s}Shoulder`` is
#: the clavicle, ``{s}Arm`` the upper arm.
_MB_ARMS: Final[dict[str, str]] = {
    "collar": "{s}Shoulder", "shoulder": "{s}Arm", "elbow": "{s}ForeArm", "wrist": "{s}Hand",
}  # fmt: skip

#: Naming schemes found automatically. "{s}" is the side token; "a|b" tries a, then b;
#: "X_end" is the End Site of joint X. spine1/spine2 are structural unless named.
SCHEMES: Final[dict[str, Scheme]] = {
    "bandai-namco": _scheme(
        "Bandai-Namco Research Motiondataset",
        (("L", "R"),),
        pelvis="Hips",
        spine1="Spine",
        spine2="Chest",
        neck="Neck",
        head="Head",
        collar="Shoulder_{s}",
        shoulder="UpperArm_{s}",
        elbow="LowerArm_{s}",
        wrist="Hand_{s}",
        hip="UpperLeg_{s}",
        knee="LowerLeg_{s}",
        ankle="Foot_{s}",
        foot="Toes_{s}",
    ),
    "cmu-daz": _scheme(
        "CMU BVH, 'daz-friendly' conversion (acRNN cmu-dance), Poser, DAZ Genesis 1-3 and 8",
        (("l", "r"),),
        pelvis="hip|hips",
        spine1="abdomen|abdomenLower",
        spine2="chest|chestUpper",
        neck="neck|neckLower",
        head="head",
        collar="{s}Collar",
        shoulder="{s}Shldr|{s}ShldrBend",
        elbow="{s}ForeArm|{s}ForearmBend",
        wrist="{s}Hand",
        hip="{s}Thigh|{s}ThighBend",
        knee="{s}Shin",
        ankle="{s}Foot",
        foot="{s}Toe|{s}Foot_end",
    ),
    "cmu-asf-bvh": _scheme(
        "CMU ASF/AMC converted to BVH (e.g. AnimatedDrawings cmu1), Xsens MVN BVH, Biovision",
        (("Left", "Right"),),
        pelvis="Hips",
        spine1="Chest",
        spine2="Chest4|Chest3|Chest2",
        neck="Neck",
        head="Head",
        collar="{s}Collar",
        shoulder="{s}Shoulder",
        elbow="{s}Elbow",
        wrist="{s}Wrist",
        hip="{s}Hip",
        knee="{s}Knee",
        ankle="{s}Ankle",
        foot="{s}Toe",
    ),
    "cmu-asf": _scheme(
        "CMU ASF bone names (a joint = the start of its bone)",
        (("l", "r"),),
        pelvis="root",
        spine2="thorax",
        neck="upperneck",
        head="head",
        collar="{s}clavicle",
        shoulder="{s}humerus",
        elbow="{s}radius",
        wrist="{s}hand",
        hip="{s}femur",
        knee="{s}tibia",
        ankle="{s}foot",
        foot="{s}toes",
    ),
    "mixamo": _scheme(
        "Mixamo (mixamorig:), MotionBuilder HumanIK, CMU 'mb-friendly', AnimatedDrawings "
        "fair1, Perception Neuron, OptiTrack Motive (MotionBuilder names)",
        (("Left", "Right"), ("L", "R")),
        ("", "mixamorig"),
        pelvis="Hips",
        neck="Neck",
        head="Head",
        **_MB_ARMS,
        hip="{s}UpLeg",
        knee="{s}Leg",
        ankle="{s}Foot",
        foot="{s}ToeBase|{s}Toe|{s}Foot_end",
    ),
    "unreal": _scheme(
        "Unreal Engine mannequin (UE4 and UE5)",
        (("l", "r"),),
        pelvis="pelvis",
        neck="neck_01",
        head="head",
        collar="clavicle_{s}",
        shoulder="upperarm_{s}",
        elbow="lowerarm_{s}",
        wrist="hand_{s}",
        hip="thigh_{s}",
        knee="calf_{s}",
        ankle="foot_{s}",
        foot="ball_{s}",
    ),
    "vrm": _scheme(
        "VRM humanoid bone names",
        (("left", "right"),),
        pelvis="hips",
        neck="neck",
        head="head",
        collar="{s}Shoulder",
        shoulder="{s}UpperArm",
        elbow="{s}LowerArm",
        wrist="{s}Hand",
        hip="{s}UpperLeg",
        knee="{s}LowerLeg",
        ankle="{s}Foot",
        foot="{s}Toes",
    ),
    "vroid": _scheme(
        "VRoid / VRM node names (J_Bip_*)",
        (("L", "R"),),
        pelvis="J_Bip_C_Hips",
        neck="J_Bip_C_Neck",
        head="J_Bip_C_Head",
        collar="J_Bip_{s}_Shoulder",
        shoulder="J_Bip_{s}_UpperArm",
        elbow="J_Bip_{s}_LowerArm",
        wrist="J_Bip_{s}_Hand",
        hip="J_Bip_{s}_UpperLeg",
        knee="J_Bip_{s}_LowerLeg",
        ankle="J_Bip_{s}_Foot",
        foot="J_Bip_{s}_ToeBase",
    ),
    "rigify": _scheme(
        "Blender Rigify / metarig .L/.R (DEF- bones too), ReActIdle",
        (("L", "R"),),
        pelvis="pelvis|DEF-spine|spine|hips",
        neck="neck|DEF-spine.004|spine.004",
        head="head|DEF-spine.006|spine.006|face",
        collar="DEF-shoulder.{s}|shoulder.{s}",
        shoulder="DEF-upper_arm.{s}|upper_arm.{s}",
        elbow="DEF-forearm.{s}|forearm.{s}",
        wrist="DEF-hand.{s}|hand.{s}|forearm.{s}_end",
        hip="DEF-thigh.{s}|thigh.{s}",
        knee="DEF-shin.{s}|shin.{s}",
        ankle="DEF-foot.{s}|foot.{s}",
        foot="DEF-toe.{s}|toe.{s}|foot.{s}_end",
    ),
    "xsens": _scheme(
        "Xsens MVN segment names (Pelvis, L5, L3, T12, T8; LeftShoulder is the collar)",
        (("Left", "Right"),),
        pelvis="Pelvis",
        spine1="L3",
        spine2="T8",
        neck="Neck",
        head="Head",
        collar="{s}Shoulder",
        shoulder="{s}UpperArm",
        elbow="{s}ForeArm",
        wrist="{s}Hand",
        hip="{s}UpperLeg",
        knee="{s}LowerLeg",
        ankle="{s}Foot",
        foot="{s}Toe",
    ),
    "rokoko": _scheme(
        "Rokoko Studio (Newton skeleton: Spine1-4, LeftThigh, LeftShin)",
        (("Left", "Right"),),
        pelvis="Hips",
        spine1="Spine1",
        spine2="Spine4|Spine3|Spine2",
        neck="Neck",
        head="Head",
        **_MB_ARMS,
        hip="{s}Thigh",
        knee="{s}Shin",
        ankle="{s}Foot",
        foot="{s}Toe|{s}ToeBase|{s}Foot_end",
    ),
    "biped": _scheme(
        "3ds Max Biped (Bip01 / Bip001 / ValveBiped.Bip01_; the clavicles hang from the neck)",
        (("L ", "R "), ("L_", "R_")),
        ("Bip01 ", "Bip001 ", "Bip01_", "Bip001_", "ValveBiped.Bip01_"),
        pelvis="Pelvis",
        spine1="Spine",
        spine2="Spine4|Spine3|Spine2|Spine1|Spine",  # one spine joint: the chest slides up it
        neck="Neck|Neck1",
        head="Head|Head1",
        collar="{s}Clavicle",
        shoulder="{s}UpperArm",
        elbow="{s}Forearm",
        wrist="{s}Hand",
        hip="{s}Thigh",
        knee="{s}Calf",
        ankle="{s}Foot",
        foot="{s}Toe0|{s}Toe0Nub|{s}Foot_end",
    ),
    "smpl": _scheme(
        "SMPL / SMPL-H / SMPL-X (smpl2bvh, m_avg_ / f_avg_; Left_foot is the toe)",
        (("Left_", "Right_"), ("L_", "R_")),
        ("", "m_avg_", "f_avg_"),
        pelvis="Pelvis",
        spine1="Spine1",
        spine2="Spine3",
        neck="Neck",
        head="Head",
        collar="{s}collar",
        shoulder="{s}shoulder",
        elbow="{s}elbow",
        wrist="{s}wrist",
        hip="{s}hip",
        knee="{s}knee",
        ankle="{s}ankle",
        foot="{s}foot",
    ),
    "daz-genesis9": _scheme(
        "DAZ Genesis 9 (l_shoulder is the collar)",
        (("l_", "r_"),),
        pelvis="hip",
        spine1="spine1",
        spine2="spine4",
        neck="neck1",
        head="head",
        collar="{s}shoulder",
        shoulder="{s}upperarm",
        elbow="{s}forearm",
        wrist="{s}hand",
        hip="{s}thigh",
        knee="{s}shin",
        ankle="{s}foot",
        foot="{s}toes",
    ),
    "character-creator": _scheme(
        "Reallusion Character Creator / iClone / AccuRIG (CC_Base_*)",
        (("L_", "R_"),),
        ("CC_Base_",),
        pelvis="Hip",
        spine1="Waist",
        spine2="Spine02",
        neck="NeckTwist01",
        head="Head",
        collar="{s}Clavicle",
        shoulder="{s}Upperarm",
        elbow="{s}Forearm",
        wrist="{s}Hand",
        hip="{s}Thigh",
        knee="{s}Calf",
        ankle="{s}Foot",
        foot="{s}ToeBase",
    ),
    "soma": _scheme(
        "SOMA 30-joint rig (Neck1 / Neck2; LeftLeg is the thigh, LeftShin the shin)",
        (("Left", "Right"),),
        pelvis="Hips",
        spine1="Spine1",
        spine2="Chest",
        neck="Neck1",
        head="Head",
        **_MB_ARMS,
        hip="{s}Leg",
        knee="{s}Shin",
        ankle="{s}Foot",
        foot="{s}ToeBase|{s}Foot_end",
    ),
    "azure-kinect": _scheme(
        "Azure Kinect Body Tracking (k4abt joint ids, K4ABT_JOINT_ optional; SPINE_NAVAL too)",
        (("LEFT", "RIGHT"),),
        ("", "K4ABT_JOINT_"),
        pelvis="PELVIS",
        spine1="SPINE_NAVEL|SPINE_NAVAL",
        spine2="SPINE_CHEST",
        neck="NECK",
        head="HEAD",
        collar="CLAVICLE_{s}",
        shoulder="SHOULDER_{s}",
        elbow="ELBOW_{s}",
        wrist="WRIST_{s}",
        hip="HIP_{s}",
        knee="KNEE_{s}",
        ankle="ANKLE_{s}",
        foot="FOOT_{s}",
    ),
}

_ALL: Final = ", ".join(SCHEMES)

#: Fraction of its own bone by which a canonical joint sitting on its parent is moved: the
#: chest where the training data has it (spine1 -> spine2 is 0.35 of spine1 -> neck in the
#: Bandai-Namco, CMU dance and CMU ASF bodies), the collar a quarter of the clavicle. The
#: training maps (trainer/maps/*.toml) make the same points: tests/trainer/test_maps.py.
_SLIDE: Final[dict[str, float]] = {
    "left_collar": 0.25,
    "right_collar": 0.25,
    "spine2": 0.35,
}


@dataclass(frozen=True)
class Anchor:
    """A point fixed in joint ``joint``'s frame: ``offset`` (character units) from its origin."""

    joint: int
    offset: F64
    label: str  # how the point was found, e.g. "LeftHand" or "0.25 of LeftCollar->LeftShoulder"


@dataclass(frozen=True)
class JointMap:
    anchors: tuple[Anchor, ...]  # one per canonical joint, canonical order
    scheme: str  # the automatic scheme used, "explicit", or "<scheme>+explicit"
    #: the anchors' joints ``[21]`` and offsets ``[21, 3, 1]``, for :meth:`points`
    joints: npt.NDArray[np.intp] = field(init=False, repr=False, compare=False)
    offsets: F64 = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "joints", np.array([a.joint for a in self.anchors], np.intp))
        offsets = np.array([a.offset for a in self.anchors], dtype=np.float64).reshape(-1, 3, 1)
        object.__setattr__(self, "offsets", offsets)

    def points(self, g_rot: F64, g_pos: F64) -> F64:
        """The anchors' world points ``[21, 3]`` of world joint rotations ``[J, 3, 3]`` and
        positions ``[J, 3]`` (of :func:`core.characters.forward_kinematics`)."""
        out: F64 = g_pos[self.joints] + (g_rot[self.joints] @ self.offsets)[..., 0]
        return out

    def describe(self) -> dict[str, str]:
        return {n: a.label for n, a in zip(JOINT_NAMES, self.anchors, strict=True)}

    def swapped(self) -> JointMap:
        """The map with each left canonical joint on its right one's point and back
        (a rig whose sides are named the other way round: :mod:`core.sides`)."""
        return JointMap(tuple(self.anchors[m] for m in MIRROR), self.scheme)


def _shared_prefix(keys: list[str]) -> str:
    """The longest start that every name shares and that ends at a separator (``_``,
    space, ``.`` or ``-``): a character's name that a rig puts before each joint's
    (HumanIK's ``Character1_``); "" where there is none."""
    first, last = min(keys, default=""), max(keys, default="")
    same = (i for i, (a, b) in enumerate(zip(first, last, strict=False)) if a != b)
    common = first[: next(same, len(first))]
    cut = max(common.rfind(c) for c in "_ .-") + 1
    return common[:cut] if cut < len(first) else ""


def _canonical_key(name: str) -> tuple[str, int]:
    """("collar", side) for limb joints, (name, -1) for centre joints."""
    for side, prefix in enumerate(("left_", "right_")):
        if name.startswith(prefix):
            return name[len(prefix) :], side
    return name, -1


def _keys(scheme: Scheme) -> tuple[tuple[tuple[str, tuple[tuple[str, str], ...]], ...], ...]:
    """Per prefix and side-token pair of ``scheme``: each canonical joint's candidate names,
    as looked up (:func:`_key`) and as written, in the order tried."""
    out = []
    for prefix, sides in ((p, s) for p in scheme.prefixes for s in scheme.sides):
        rows = []
        for canon in JOINT_NAMES:
            base, side = _canonical_key(canon)
            names = (
                c.replace("{s}", sides[side]) if side >= 0 else c
                for c in scheme.joints.get(base, ())
            )
            rows.append((canon, tuple((_key(prefix + n), prefix + n) for n in names)))
        out.append(tuple(rows))
    return tuple(out)


#: :func:`_keys` of every scheme, made once.
_KEYS: Final = {name: _keys(scheme) for name, scheme in SCHEMES.items()}


def _resolve_scheme(lookup: Lookup, scheme: str) -> tuple[dict[str, int], int, dict[str, str]]:
    """Best resolution of a scheme over its prefixes and side-token pairs: (canonical ->
    joint, names hit, canonical -> the candidate of a tie: :mod:`core.map_lookup`)."""
    best: tuple[dict[str, int], int, dict[str, str]] = ({}, -1, {})
    for rows in _KEYS[scheme]:
        found: dict[str, int] = {}
        tied: dict[str, str] = {}
        for canon, keys in rows:
            for key, written in keys:
                if key in lookup:
                    found[canon], ties = lookup.find(key, written)
                    if ties:
                        tied[canon] = written
                        lookup.ties[written] = ties
                    break
        if len(found) > best[1]:
            best = (found, len(found), tied)
    return best


def _lca(skel: Skeleton, a: int, b: int) -> int:
    ancestors = set()
    while a >= 0:
        ancestors.add(a)
        a = skel.parents[a]
    while b >= 0 and b not in ancestors:
        b = skel.parents[b]
    return b


def _chest_below_collars(skel: Skeleton, found: dict[str, int]) -> None:
    """Drop a named chest (spine2) that is not above both collars (a chest named by one of
    several spine names, ``Chest4|Chest3|Chest2``, where the collars hang lower), so that
    the structural rule puts it where they meet."""
    chest, collars = found.get("spine2"), [found.get(c) for c in ("left_collar", "right_collar")]
    if chest is None or None in collars:
        return  # (a collar not found: the map is incomplete anyway)
    if not all(skel.is_ancestor(chest, c) for c in collars if c is not None):
        del found["spine2"]


def _structural(skel: Skeleton, found: dict[str, int]) -> None:
    """Fill spine2 (lowest common ancestor of the collars) and spine1 (first joint below the
    pelvis towards it, off the pelvis) where no name gave them."""
    rest = skel.rest_positions()
    if "spine2" not in found and "left_collar" in found and "right_collar" in found:
        chest = _lca(skel, found["left_collar"], found["right_collar"])
        if chest >= 0:
            found["spine2"] = chest
    if "spine1" not in found and "pelvis" in found and "spine2" in found:
        path = []
        j = found["spine2"]
        while j >= 0 and j != found["pelvis"]:
            path.append(j)
            j = skel.parents[j]
        if j == found["pelvis"]:
            scale = float(np.linalg.norm(rest[found["spine2"]] - rest[found["pelvis"]])) or 1.0
            for k in reversed(path):
                if np.linalg.norm(rest[k] - rest[found["pelvis"]]) > 0.05 * scale:
                    found["spine1"] = k
                    break


def _bones(skel: Skeleton, anchors: Mapping[str, Anchor]) -> list[int]:
    """The joints whose offsets are the bones between the anchors' joints."""
    out = []
    for canon, parent in PARENT_NAMES.items():
        if parent is not None:
            top, j = anchors[parent].joint, anchors[canon].joint
            while j != top and j >= 0:
                out.append(j)
                j = skel.parents[j]
    return out


def _local_path(skel: Skeleton, top: int, bottom: int) -> F64:
    """Rest-pose vector from ``top``'s origin to ``bottom``'s, in ``top``'s frame."""
    v = np.zeros(3)
    j = bottom
    while j != top:
        v += skel.offsets[j]
        j = skel.parents[j]
    return v


def resolve_map(
    skel: Skeleton,
    explicit: Mapping[str, str] | None = None,
    *,
    where: str = "joint_map",
    offset_at: OffsetAt = default_offset_at,
) -> JointMap:
    """The joint map of ``skel``: automatic, overridden joint by joint by ``explicit``;
    ``offset_at`` names the fields of its offsets, for a rest pose that cannot be read
    (:mod:`core.rest_checks`). A map refused as a whole (at ``where``) that is made
    without the points along a bone ``explicit`` gives is refused at the first of them it
    does not make (:func:`_point_to_blame`)."""
    try:
        return _resolve_map(skel, explicit, where, offset_at)
    except CharacterError as exc:
        if not str(exc).startswith(f"{where}: "):
            raise
        blamed = _point_to_blame(skel, explicit or {}, where, offset_at)
        if blamed is None:
            raise
        raise blamed from None


def _point_to_blame(
    skel: Skeleton, explicit: Mapping[str, str], where: str, offset_at: OffsetAt
) -> CharacterError | None:
    """The refusal of the first point along a bone of ``explicit`` that the map made
    without them does not make, where that map is made (the point broke it); else None.
    (``{"spine2": "0.35 of spine->neck"}`` on ReActIdle, whose neck hangs from spine.001,
    was a 422 at `joint_map` naming a joint the client did not touch: "no joint found for
    ['spine1']"; an audit, 2026-12-06.)"""
    points = {c: n for c, n in explicit.items() if slid_point(skel, n) is not None}
    if not points:
        return None
    try:
        rest = {c: n for c, n in explicit.items() if c not in points}
        jmap = _resolve_map(skel, rest, where, offset_at)
    except CharacterError:
        return None
    for canon, point in points.items():
        made = jmap.anchors[JOINT_INDEX[canon]].label
        if made != point:
            return CharacterError(not_made(skel, f"{where}.{canon}", point, made))
    return None


def _resolve_map(
    skel: Skeleton, explicit: Mapping[str, str] | None, where: str, offset_at: OffsetAt
) -> JointMap:
    lookup = lookup_of(skel.names, _shared_prefix([_key(n) for n in skel.names]))
    given: dict[str, int] = {}
    slid: dict[str, str] = {}  # a point part-way along a bone, as a map describes it
    for canon, name in (explicit or {}).items():
        if canon not in JOINT_INDEX:
            at = f"{where}.{clip(canon, 40)}"  # the key, as a schema error names one
            raise CharacterError(
                f"{at}: unknown canonical joint {quoted(canon)}{near(JOINT_NAMES, canon)}; "
                f"joints are {', '.join(JOINT_NAMES)}",
                at,
            )
        along = slid_point(skel, name)
        if along is not None:  # "0.5 of Spine1->Neck"
            if _SLIDE.get(canon) != fraction(along.group(1)):
                raise CharacterError(
                    f"{where}.{canon}: {quoted(name)} is not a point a map makes (only "
                    + ", ".join(f"{k} slides {v:g} of its bone" for k, v in _SLIDE.items())
                    + "); name a joint of the skeleton"
                )
            along_a_bone(skel, along, f"{where}.{canon}")
            slid[canon], name = name, along.group(2)
        if name not in skel.index:
            raise CharacterError(
                f"{where}.{canon}: the skeleton has no joint {quoted(name)}{near(skel.names, name)}"
            )
        given[canon] = skel.index[name]

    refuse_one_point(skel, offset_at)
    best_name, best_found, best_hits, best_tied = "", dict(given), -1, {}
    structural = {"spine1", "spine2"}  # the joints the structural rules may fill
    matched = False  # whether any scheme's name is a joint's
    as_close: list[str] = []  # the schemes after the best one that score as well (its tie)
    for scheme_name in SCHEMES:
        found, hits, tied = _resolve_scheme(lookup, scheme_name)
        _chest_below_collars(skel, found)
        # the names it finds, but spine1 and spine2's: the structural rules find them for
        # every scheme, so a scheme that names them is no closer for it (Rokoko's Spine1 and
        # Spine2 are a Mixamo rig's too: one with its legs renamed was read as Rokoko's)
        hits = len(found.keys() - structural)
        matched = matched or hits > 0
        found.update(given)
        if set(JOINT_NAMES) - found.keys() <= structural:  # else it cannot be complete
            _structural(skel, found)
        complete = len(found) == len(JOINT_NAMES)
        score = hits + (1000 if complete else 0)
        if score > best_hits:
            best_name, best_found, best_hits, best_tied = scheme_name, found, score, tied
            as_close = []
        elif score == best_hits:  # (the first of SCHEMES wins: the more common)
            as_close.append(scheme_name)
    if given:
        best_name = "explicit" if len(given) == len(JOINT_NAMES) else f"{best_name}+explicit"
    missing = [c for c in JOINT_NAMES if c not in best_found]
    if missing:  # (the structural rules ran already where they could complete a map)
        _structural(skel, best_found)
        missing = [c for c in JOINT_NAMES if c not in best_found]
    if missing:
        more = f" and {len(as_close) - 3} more" if len(as_close) > 3 else ""
        tie = f" ({', '.join(as_close[:3])}{more} as close)" if as_close else ""
        closest = f"{best_name}{tie}" if matched else None
        raise CharacterError(missing_message(where, missing, closest, skel.names, _ALL))
    for canon, written in best_tied.items():  # two joints as good a match: neither taken
        if canon not in given:
            names = [skel.names[j] for j in lookup.ties[written]]
            raise CharacterError(tie_message(where, canon, written, names))
    jmap = _anchors(skel, best_found, best_name, where, offset_at)
    for canon, label in slid.items():  # as the map itself slides it, or refused
        got = jmap.anchors[JOINT_INDEX[canon]].label
        if got != label:
            raise CharacterError(not_made(skel, f"{where}.{canon}", label, got))
    return jmap


def _anchors(
    skel: Skeleton, found: dict[str, int], scheme: str, where: str, offset_at: OffsetAt
) -> JointMap:
    rest = skel.rest_positions()
    # the body's size: the mapped joints' extent, not the whole skeleton's (a prop, a camera
    # or a second root far from the body must not make a real bone count as zero length)
    body = rest[sorted(set(found.values()))]
    span = max(float(np.ptp(body, axis=0).max()), 1e-9)
    anchors: dict[str, Anchor] = {}
    for canon in JOINT_NAMES:  # parents first
        j = found[canon]
        anchors[canon] = Anchor(j, np.zeros(3), skel.names[j])
        parent = PARENT_NAMES[canon]
        if parent is None:
            continue
        pj = anchors[parent].joint
        if not skel.is_ancestor(pj, j):
            raise CharacterError(
                f"{where}: {canon} -> {quoted(skel.names[j])} is not below {parent} -> "
                f"{quoted(skel.names[pj])} in the skeleton"
            )

    # zero-length canonical bones: slide the child part-way along its own bone; so too two
    # collars on one point (CMU ASF's clavicles both start where the neck does, not on the
    # chest: the networks never saw a body without shoulders' width there)
    def point(canon: str) -> F64:
        out: F64 = rest[anchors[canon].joint] + anchors[canon].offset
        return out

    twins = float(np.linalg.norm(point("left_collar") - point("right_collar"))) <= 1e-3 * span
    for canon in JOINT_NAMES:
        parent = PARENT_NAMES[canon]
        if parent is None:
            continue
        a, pa = anchors[canon], anchors[parent]
        here, there = point(canon), point(parent)
        on_twin = twins and canon in ("left_collar", "right_collar")
        if np.linalg.norm(here - there) > 1e-3 * span and not on_twin:
            continue
        child = next((c for c in JOINT_NAMES if PARENT_NAMES[c] == canon), None)
        if canon not in _SLIDE or child is None:  # (one bone out of proportion: said so)
            refuse_out_of_proportion(skel, _bones(skel, anchors), offset_at)
            raise CharacterError(
                f"{where}: {canon} ({a.label}) sits on {parent} ({pa.label}) in the rest pose; "
                "map them to distinct points"
            )
        cj = anchors[child].joint if child in anchors else found[child]
        if not skel.is_ancestor(a.joint, cj) or cj == a.joint:
            raise CharacterError(f"{where}: {canon} ({a.label}) has no bone to slide along")
        frac = _SLIDE[canon]
        anchors[canon] = Anchor(
            a.joint,
            frac * _local_path(skel, a.joint, cj),
            f"{frac:g} of {skel.names[a.joint]}->{skel.names[cj]}",
        )
    return JointMap(tuple(anchors[c] for c in JOINT_NAMES), scheme)


#: Leg length (hip to ankle, rest pose) bands that make a unit plain: (low, high, unit).
LEG_BANDS: Final[tuple[tuple[float, float, str], ...]] = (
    (0.3, 1.3, "m"),
    (45.0, 130.0, "cm"),
    (450.0, 1300.0, "mm"),
)


#: Rest-pose leg length in metres (hip to ankle) a NAMED unit may give (a figure 30 cm
#: to 15 m tall): beyond it the unit is taken for a slip (a file in centimetres sent as
#: "m", in millimetres as "cm") and refused; a number of metres per unit is taken as given.
NAMED_UNIT_LEG_M: Final[tuple[float, float]] = (0.1, 5.0)


def human_units(leg: float) -> list[str]:
    """The unit names that make a rest-pose leg of ``leg`` file units a person's (the
    metre band of :data:`LEG_BANDS`), for a message to suggest."""
    low, high, _ = LEG_BANDS[0]
    return [name for name, scale in UNITS.items() if low <= leg * scale <= high]


def rest_points(skel: Skeleton, jmap: JointMap) -> F64:
    """The 21 canonical points of the rest pose (identity rotations)."""
    rest = skel.rest_positions()
    return np.stack([rest[a.joint] + a.offset for a in jmap.anchors])


def infer_units(skel: Skeleton, jmap: JointMap) -> tuple[str | None, float]:
    """The unit the rest-pose leg length (hip -> knee -> ankle, mean of both sides) makes
    plain by :data:`LEG_BANDS`, else None; and that leg length in file units."""
    pts = rest_points(skel, jmap)
    legs = []
    for side in ("left", "right"):
        hip, knee, ankle = (JOINT_INDEX[f"{side}_{n}"] for n in ("hip", "knee", "ankle"))
        legs.append(
            float(np.linalg.norm(pts[knee] - pts[hip]) + np.linalg.norm(pts[ankle] - pts[knee]))
        )
    leg = float(np.mean(legs))
    for low, high, unit in LEG_BANDS:
        if low <= leg <= high:
            return unit, leg
    return None, leg


def infer_up(skel: Skeleton, jmap: JointMap) -> str | None:
    """ "+Y" or "+Z" where the rest pose's ankles-to-head vector lies within ~37 degrees of
    that axis (:func:`up_of`), else None (the service then looks at the frame edited)."""
    return up_of(rest_points(skel, jmap))


def up_of(pts: F64) -> str | None:
    """ "+Y" or "+Z" when the 21 points' ankles-to-head vector lies within ~37 degrees of
    that axis, else None."""
    v = pts[JOINT_INDEX["head"]] - 0.5 * (
        pts[JOINT_INDEX["left_ankle"]] + pts[JOINT_INDEX["right_ankle"]]
    )
    n = float(np.linalg.norm(v))
    if n == 0:
        return None
    for axis, name in ((1, "+Y"), (2, "+Z")):
        if v[axis] >= 0.8 * n:
            return name
    return None
