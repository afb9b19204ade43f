"""Request and response bodies of the REST API (the transport layer's types)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Any, Final, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, create_model
from pydantic_core import PydanticCustomError

from core.bvh import MAX_JOINTS
from core.ends import SOFT_IK_MAX
from core.rest import rest_pose
from core.skeleton import BASE_KEYPOINTS, JOINT_NAMES, PARENT_NAMES
from core.text import shown
from service.bounded import Bounded, at_most

#: Coordinates beyond this (metres) are rejected as nonsense.
MAX_COORDINATE = 1.0e4
#: The most neural passes a request may ask for (``options.passes``).
MAX_PASSES = 4
#: The largest relative weight of a target.
MAX_WEIGHT = 1000.0

if TYPE_CHECKING:  # the names are only known at run time
    JointName = str
    BoneName = str
else:
    JointName = Literal[JOINT_NAMES]
    #: The joint a bone ends at (every joint but the root) names that bone.
    BoneName = Literal[tuple(j for j in JOINT_NAMES if PARENT_NAMES[j] is not None)]

Coordinate = Annotated[
    float,
    Field(allow_inf_nan=False, ge=-MAX_COORDINATE, le=MAX_COORDINATE),
]
Vec3 = Annotated[
    list[Coordinate],
    Field(
        min_length=3,
        max_length=3,
        description=f"x, y, z in metres (world frame, +Y up), each within ±{MAX_COORDINATE:g}.",
    ),
]
Joint = Annotated[JointName, Field(description="A joint name of the canonical skeleton.")]
Finite = Annotated[float, Field(allow_inf_nan=False)]

#: An answered pose: the 21 joints, world space, metres (not bounded like the input: a
#: pose near the coordinate limit may be answered just beyond it).
PoseOut: type[BaseModel] = create_model(
    "PoseOut",
    __doc__="Every one of the 21 joints, world space, metres.",
    **{name: (list[float], ...) for name in JOINT_NAMES},  # type: ignore[call-overload]
)

#: The example pose of the contract: the canonical rest pose (``core.rest``), mm-rounded.
_REST_EXAMPLE: dict[str, Any] = {
    name: [round(float(v), 3) for v in xyz]
    for name, xyz in zip(JOINT_NAMES, rest_pose(), strict=True)
}


class _Body(Bounded):
    """A request model (``service.bounded``: strict, no unknown keys, bounded errors)."""


#: A whole pose: exactly the 21 joints, each [x, y, z] in metres (world frame).
Pose: type[BaseModel] = create_model(
    "Pose",
    __base__=_Body,
    __doc__="Every one of the 21 joints, world space, metres.",
    **{name: (Vec3, ...) for name in JOINT_NAMES},  # type: ignore[call-overload]
)


class Target(_Body):
    joint: Joint
    position: Vec3
    weight: Finite = Field(
        default=1.0,
        gt=0.0,
        le=MAX_WEIGHT,
        description=(
            "Relative importance. The networks read no weight: weights order the neural "
            "solvers, a heavier target's running later in the sequence (its target kept best); "
            "any difference reorders and equal weights keep the default order, so a tiny change "
            "can change the answer as much as a large one. FABRIK (the method, and the polish "
            "of exact reach and pins) pulls by the weight's size."
        ),
    )


#: The largest whole number a JSON number written as a float (``2.0``, ``1e5``) is read
#: as: past it a float holds integers only in steps of 2 or more (every one of them "has no
#: fraction"), and RFC 8259 (section 6) calls integers within ±(2**53 - 1) the
#: interoperable ones.
MAX_WHOLE_FLOAT = 2**53 - 1


def _whole(value: Any) -> Any:
    """A number with no fraction written as a float (``2.0``) is the integer JSON Schema
    says it is (a contract audit: ``"passes": 2.0`` was a 422); any other value as sent,
    but a float that is no whole number, or one past :data:`MAX_WHOLE_FLOAT`, is refused
    here, quoted as JSON writes it (an audit: ``"frame": 1e300`` was read as the integer
    of 301 digits it rounds to, and answered as ``<an integer of 301 digits>``; ``3.5``
    got "Input should be a valid integer", quoting nothing)."""
    if type(value) is not float:
        return value
    if not math.isfinite(value):  # (worded as every field's: service.errors._message)
        raise PydanticCustomError("finite_number", "Input should be a finite number")
    if not value.is_integer():
        raise PydanticCustomError(
            "whole_number", "{value} is not a whole number", {"value": shown(value)}
        )
    if abs(value) > MAX_WHOLE_FLOAT:
        raise PydanticCustomError(
            "whole_number",
            "{value} is not a whole number this API reads: a number written with a fraction "
            "or an exponent stands for one only within ±{limit}",
            {"value": shown(value), "limit": MAX_WHOLE_FLOAT},
        )
    return int(value)


#: An integer field of a request takes a JSON integer, or a float with no fraction within
#: ±:data:`MAX_WHOLE_FLOAT`: ``Annotated[int, Field(<bounds>), WHOLE]`` (the bounds before
#: it, so that the schema states them as bounds).
WHOLE = BeforeValidator(_whole)


class SolveOptions(_Body):
    method: Literal["neural", "fabrik"] = "neural"
    preserve_bone_lengths: bool = Field(
        default=True,
        description="`false`: the networks' raw answer, without the bone pass (bones not "
        "kept). `method: fabrik`, `reach: exact` and pins keep the bone lengths by "
        "construction: `false` beside any of them is a 422 naming both fields.",
    )
    reach: Literal["soft", "exact"] = "soft"
    tolerance: Finite = Field(
        default=0.001, ge=1e-6, le=1.0, description="Metres: `reached` and exact reach."
    )
    floor: Finite = Field(
        default=0.0,
        ge=-MAX_COORDINATE,
        le=MAX_COORDINATE,
        description="Height (m, world y) of the ground the character stands on. The "
        "networks learned poses over a floor at y = 0; a character on a 1 m box needs 1.0.",
    )
    passes: Annotated[int, Field(ge=1, le=MAX_PASSES), WHOLE] | None = Field(
        default=None,
        description="Neural solves per edit, each from the previous answer with the bone "
        "lengths restored (absent: the models' default, `passes` of `GET /v1/models`). "
        "More passes reach closer on bodies unlike the training ones; each costs about one "
        "more solve. 1 is the fastest. `method: fabrik` ignores it.",
    )
    carry: Finite | None = Field(
        default=None,
        ge=0.0,
        le=1.0,
        description="How far the joints below a targeted joint (the wrist under a dragged "
        "elbow, the ankle and foot under a knee) turn with its bone, as a rigid branch "
        "would: 0 leaves them where the network put them, 1 carries the start pose's "
        "branch (as FABRIK does); between, each bone's direction is the mix. Absent: the "
        "models' default, `carry` of `GET /v1/models`. `method: fabrik` ignores it.",
    )
    turn_search: bool | None = Field(
        default=None,
        description="Whether an edit with many targets (`turn_min_targets` of `GET "
        "/v1/models`, 5 for the shipped models) and no pins first searches the body's turn "
        "about the pelvis, and the start moved to fit the targets (`turn_fit`; the solver "
        "path then ends `turn <deg>` or `fit <deg>`); absent: the models' default. About 14 "
        "solves instead of one; `false` is the fast path.",
    )
    mirror: bool | None = Field(
        default=None,
        description="Whether each neural pass also solves the edit's mirror image (left and "
        "right swapped) and answers the mean of the two: a little closer to a real pose on "
        "bodies unlike the training ones, at twice the networks' work. Absent: the models' "
        "default, `solve_mirror` of `GET /v1/models`; `false` is the fast path. `method: "
        "fabrik` ignores it.",
    )
    soft_ik: Finite = Field(
        default=0.0,
        ge=0.0,
        le=SOFT_IK_MAX,
        description="Metres over which a kept limb (a targeted wrist's or ankle's arm or "
        "leg, a lone targeted elbow's collar and shoulder) eases into full stretch (soft "
        "IK; at most a quarter of the limb's reach): its elbow or knee no longer swings "
        "from bent to straight as the target crosses the limb's reach, and a cleaned clip "
        "no longer pops there; the end falls short of full stretch by up to `soft_ik`/e "
        "(exact reach still polishes onto the target; a soft answer is retried and "
        "polished only when short by more than that too). 0 (default): none. 0.01 for "
        "clip clean-up (docs/service.md). `method: fabrik` ignores it.",
    )


class SolveRequest(_Body):
    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        json_schema_extra={
            "examples": [
                {
                    "pose": _REST_EXAMPLE,
                    "targets": [{"joint": "left_wrist", "position": [0.3, 1.4, 0.2]}],
                    "pins": ["left_ankle", "right_ankle"],
                    "options": {"method": "neural", "reach": "soft"},
                }
            ]
        },
    )

    pose: Pose
    targets: list[Target] = Field(min_length=1, max_length=21)
    pins: list[Joint] = Field(
        default_factory=list,
        max_length=21,
        description="Joints held where they are in `pose`; distinct, and none of them "
        "targeted (a request that pins a targeted joint is a 422).",
        json_schema_extra={"uniqueItems": True},
    )
    options: SolveOptions = Field(default_factory=SolveOptions)


class TargetResult(BaseModel):
    joint: str = Field(
        description="The canonical joint (`left_wrist`), in the character and BVH forms too "
        "(whatever name the request gave: its `joint_map` maps one to the other; `name` "
        "says which it gave)."
    )
    error: float = Field(description="Distance (m) from the joint to its target.")
    reached: bool = Field(description="error <= tolerance.")


class NamedTargetResult(TargetResult):
    """A character's target or pin: the canonical joint and the name the request gave."""

    name: str = Field(
        description="The joint as the request named it (the character's own name, or a "
        "canonical one): with a rig's sides swapped (`sides_warning`), `LeftHand` is "
        "reported as the body's `right_wrist`."
    )


#: What an answer's ``iterations`` counts: the pose form's, the character form's and the
#: BVH answers' (``service.characters._Solved``) alike.
ITERATIONS = (
    "FABRIK iterations used: 0 when none ran, or when a polish in `solvers` found its "
    "targets already met."
)


#: ``floor_warning``'s description (``service.floors``)
FLOOR_WARNING = (
    "Null unless `options.floor` lies above the start pose's pelvis, or below it by more "
    "than 4 times its pelvis-to-neck distance (no body the networks learned stood higher: "
    "3.5 mid-jump, 2.2 standing), or above its lowest joint by more than half that "
    "distance (its legs under the ground: a root at the origin): the body was solved over "
    "that floor as asked, a body "
    "under its ground or far above it (`/v1/complete` takes such a floor into that band and "
    "answers the floor it used). Says where the floor lies; the floor is the world height "
    "of the ground the character stands on."
)


class SolveResponse(BaseModel):
    pose: PoseOut
    targets: list[TargetResult]
    pins: list[TargetResult] = Field(
        description="How far each pinned joint moved (m); [] when none was pinned."
    )
    max_bone_length_error: float = Field(description="Max relative bone-length error.")
    solvers: list[str] = Field(
        description="Solver sequence used (target-set keys), then the polishes that ran: "
        "`fabrik-polish` (FABRIK from the networks' answer onto the targets), `fabrik-fallback` "
        "(FABRIK from the pose as sent instead, where the polish left a target beyond the "
        "tolerance), `pin-polish` (pins still off, polished onto them), "
        "`fabrik-critic` (FABRIK's answer instead: the manifest's `serving.critic_fabrik`)."
    )
    model: str = Field(description="Manifest version of the models.")
    method: Literal["neural", "fabrik"]
    iterations: int = Field(description=ITERATIONS)
    floor: float = Field(
        description="Height (m, world y) of the ground the solve used: the request's "
        "`options.floor` (0 if none), taken as given (`floor_warning` says where it lies "
        "far from the body)."
    )
    up_warning: str | None = Field(
        default=None,
        description="Null unless the start pose's pelvis-to-neck line leans more than 60 "
        "degrees from +Y, the up axis a pose is read with: the body was solved lying down, "
        "or upside down along -Y (as asked, if it lies so; a pose captured with +Z up must "
        "be turned to +Y up first, or sent in the character form with its `up`). Says along "
        "which axis the line runs, as `/v1/complete`'s `up_warning` says of key points.",
    )
    floor_warning: str | None = Field(
        default=None,
        description=FLOOR_WARNING,
    )
    handedness_warning: str | None = Field(
        default=None,
        description="Null unless the start pose's left and right look mirrored: its toes "
        "and bent knees point backwards from the way its hips and shoulders face it (a pose "
        "in left-handed coordinates, x mirrored as Unity's, or its sides swapped), which the "
        "networks read as a body seen from behind; solved as asked. Said of upright poses "
        "only, as the character form's `sides_warning` is.",
    )


class Keypoint(_Body):
    joint: Joint
    position: Vec3


#: The length a bone of a completion's ``bone_lengths`` may have, metres (a bone two key
#: points fix takes their distance, at least the shortest: ``service.completion``).
BONE_M: Final[tuple[float, float]] = (1e-3, 2.0)


class CompleteRequest(_Body):
    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        json_schema_extra={
            "examples": [
                {"keypoints": [{"joint": j, "position": _REST_EXAMPLE[j]} for j in BASE_KEYPOINTS]}
            ]
        },
    )

    keypoints: list[Keypoint] = Field(min_length=1, max_length=21)
    floor: Finite = Field(
        default=0.0,
        ge=-MAX_COORDINATE,
        le=MAX_COORDINATE,
        description="Height (m, world y) of the ground.",
    )
    bone_lengths: (
        Annotated[
            dict[BoneName, Annotated[Finite, Field(ge=BONE_M[0], le=BONE_M[1])]],
            Field(max_length=MAX_JOINTS),
            BeforeValidator(at_most(MAX_JOINTS)),
        ]
        | None
    ) = Field(
        default=None,
        description="Length (m) of the bone ending at each named joint; missing bones "
        "take the reference length scaled like the given ones.",
    )


class CompleteResponse(BaseModel):
    pose: PoseOut
    keypoints: list[TargetResult]
    levels: list[int] = Field(description="Completion levels run (1 = six base points).")
    floor: float = Field(
        description="Height (m, world y) of the ground the completion used: the request's "
        "`floor`, or the lowest key point's height where it lies above that (no body stands "
        "under its ground), or 4 pelvis-to-neck lengths below the pelvis where it lies "
        "farther below (no body of the training data stood higher)."
    )
    model: str
    scale_warning: str | None = Field(
        default=None,
        description="Null unless the body answered is not the size the request gave: "
        "`bone_lengths` naming some bones but not all (the others take the reference "
        "skeleton's lengths times the named ones' median ratio: `{\"left_wrist\": 2.0}` "
        "made a body whose bones total 34 m), or key points of a body outside the sizes "
        "the networks know (completed scaled into them and answered back: centimetres "
        "sent as metres), or `bone_lengths` of a body the key points do not have: bones "
        "totalling under half or over twice the body the key points imply (every bone at "
        "1 mm, or at 2 m), or too short to reach a key point from the next one up the "
        "skeleton (the answer misses it); or, without `bone_lengths`, a wrist or an ankle "
        "farther from the neck or the pelvis than 1.5 times any person's reaches (3.2 and 4.5 "
        "pelvis-to-neck distances), which the answer reaches with a limb stretched to it. "
        "Says by how much.",
    )
    up_warning: str | None = Field(
        default=None,
        description="Null unless the pelvis-to-neck line of the key points leans more than "
        "60 degrees from +Y, the up axis key points are read with: the body was completed "
        "lying down, or upside down along -Y (as asked, if it lies so; key points captured "
        "with +Z up must be turned to +Y up first). Says along which axis the line runs.",
    )


class SkeletonResponse(BaseModel):
    joints: list[str]
    parents: dict[str, str | None]
    reference_bone_lengths: dict[str, float]
    frame: dict[str, str]


class ModelInfo(BaseModel):
    name: str
    kind: str
    key: str | None
    joints: list[str]
    parameters: int
    bytes: int
    metrics: dict[str, float]


class ModelsResponse(BaseModel):
    version: str
    licence: str
    model_card: str
    solver_sets: list[str]
    completion_levels: list[list[str]]
    passes: int = Field(
        description="Neural solves per edit when a request's `options.passes` is absent "
        "(the manifest's `serving.passes`)."
    )
    carry: float = Field(
        description="How far joints below a targeted joint turn with its bone, as a rigid "
        "branch would, after the bone pass: 0 (the network's answer) to 1 (the start pose's "
        "branch carried, as FABRIK does); the manifest's `serving.carry`."
    )
    turn_yaws: int = Field(
        description="Turns of the start a searching edit tries (1: no search; the manifest's "
        "`serving.turn_yaws`)."
    )
    turn_min_targets: int = Field(
        description="The fewest targets of an edit that searches its turn "
        "(`serving.turn_min_targets`)."
    )
    turn_fit: float = Field(
        description="Metres by which the turn search's start moved to fit the targets must "
        "score below every other candidate to be kept (0: not tried; `serving.turn_fit`)."
    )
    turn_quick: bool = Field(
        description="Whether the turn search scores its candidates on their quick form (one "
        "pass, no mirror image) before solving the edit as asked (`serving.turn_quick`)."
    )
    turn_gate: float = Field(
        description="Metres: an edit that may search its turn searches only if its targets "
        "lie at least this far across from their joints on average, at the networks' body "
        "size (0: always; `serving.turn_gate`)."
    )
    turn_critic: str = Field(
        description="What judges how natural a searched turn's answer is: `completion` (the "
        "body completion builds from its base key points) or `autoencoder` (its round trip); "
        "the manifest's `serving.turn_critic`."
    )
    turn_plausibility: float = Field(
        description="The weight of that judgement beside the reach in a candidate's score "
        "(`serving.turn_plausibility`)."
    )
    retry_reach: float = Field(
        description="Metres beyond which a soft answer's farthest target gets one more pass "
        "from that answer, at the networks' body size and scaled with each character's "
        "(0: never; the manifest's `serving.retry_reach`)."
    )
    retry_polish: bool = Field(
        description="Whether a soft answer still farther than `retry_reach` from a target "
        "after that pass is polished onto its targets, as exact reach is (`solvers` then "
        "ends with `fabrik-polish`; the manifest's `serving.retry_polish`)."
    )
    keep_ends: bool = Field(
        description="Whether the bone pass keeps each targeted wrist and ankle where the "
        "networks put it, its elbow or knee placed anew with the character's lengths (the "
        "manifest's `serving.keep_ends`)."
    )
    keep_elbows: bool = Field(
        description="Whether the bone pass keeps each targeted elbow where the networks put "
        "it, its shoulder placed anew with the character's lengths (the manifest's "
        "`serving.keep_elbows`)."
    )
    keep_ease: float = Field(
        description="Metres below which a kept end that the bone pass left that near the "
        "networks' goes back only in proportion (0: all the way; the manifest's "
        "`serving.keep_ease`)."
    )
    bend_side: float = Field(
        description="Below this fraction of the bend the character's lengths need, a kept "
        "limb the networks drew too straight bends towards the side elbows and knees bend "
        "to (0: the networks' plane alone; the manifest's `serving.bend_side`)."
    )
    keep_feet: bool = Field(
        description="Whether a leg no target or pin names that the answer sinks below the "
        "floor (or below where the start had it) is raised back, its knee bent to fit (the "
        "manifest's `serving.keep_feet`)."
    )
    keep_collar: bool = Field(
        description="Whether a soft answer's kept wrist beyond the arm's reach turns its "
        "shoulder about the collar first (the manifest's `serving.keep_collar`)."
    )
    critic_fabrik: float = Field(
        description="Metres (mean per joint) by which the critic must find a neural answer "
        "less like a real body than FABRIK's, FABRIK's reaching every target, for the edit "
        "to be answered by FABRIK (0: never; the manifest's `serving.critic_fabrik`)."
    )
    keep_pairs: bool = Field(
        description="Whether the hips and the collars keep the start's width between them, "
        "each pair turned as one rigid part after the bone pass (the manifest's "
        "`serving.keep_pairs`)."
    )
    keep_pelvis: float = Field(
        description="Metres of the networks' pelvis move a few-target edit drops (0: none; "
        "the manifest's `serving.keep_pelvis`)."
    )
    pelvis_travel: bool = Field(
        description="Whether a targeted pelvis first takes the start with it horizontally "
        "(the manifest's `serving.pelvis_travel`)."
    )
    reach_travel: bool = Field(
        description="Whether a few-target edit's target farther across than its chain "
        "reaches first moves the start across (the manifest's `serving.reach_travel`)."
    )
    solve_mirror: bool = Field(
        description="Whether each neural pass also solves the edit's mirror image and answers "
        "the mean of the two, unless a request says (`options.mirror`; the manifest's "
        "`serving.solve_mirror`)."
    )
    max_body_bytes: int = Field(
        description="The largest request body this server takes, in bytes "
        "(`POSE_MAX_BODY_BYTES`); a larger one is a 413. The editor sends a BVH file over it "
        "a frame at a time (docs/editor.md), and whole under it."
    )
    models: list[ModelInfo]


class FieldError(BaseModel):
    location: str = Field(description="The field: `items[2].targets[0].joint`, `body`.")
    message: str


def _no_default(schema: dict[str, Any]) -> None:
    """An answer's field that is absent, not empty, when it does not apply: no default."""
    schema.pop("default", None)


class Problem(BaseModel):
    """RFC 9457 problem details: every 4xx/5xx answer (``application/problem+json``)."""

    model_config = ConfigDict(extra="allow")

    type: str
    title: str
    status: int
    detail: str
    errors: list[FieldError] = Field(
        default_factory=list,
        description="Per-field errors of an invalid body (422 only; absent otherwise).",
        json_schema_extra=_no_default,
    )
    missing: list[str] = Field(
        default_factory=list,
        description="Missing base key points (a completion's 422 only; absent otherwise): "
        "those the nearest of `key_point_sets` lacks.",
        json_schema_extra=_no_default,
    )
    key_point_sets: list[list[str]] = Field(
        default_factory=list,
        description="The key point sets a completion takes, one per completion level (6, "
        "11, 16 points; any other joints may be given besides): with `missing` only.",
        json_schema_extra=_no_default,
    )


class Health(BaseModel):
    status: Literal["live", "ready", "not ready"]
    detail: str | None = None


# -- the columnar batch (service.columnar validates it vectorised; these models are its
# -- contract, and validate it when it reaches the route itself) --------------------------
PoseRow = Annotated[
    list[Coordinate],
    Field(
        min_length=3 * len(JOINT_NAMES),
        max_length=3 * len(JOINT_NAMES),
        description="The 21 joints' x, y, z in the order of `/v1/skeleton` `joints` "
        "(pelvis x, y, z, spine1 x, y, z, …), metres, world frame.",
    ),
]
Weight = Annotated[float, Field(allow_inf_nan=False, gt=0.0, le=MAX_WEIGHT)]
#: A packed column (``service.columnar.PACKED``): the same numbers, row after row, as one
#: base64 string of little-endian float64
Packed = Annotated[
    str,
    Field(
        min_length=1,
        pattern=r"^[A-Za-z0-9+/]*={0,2}$",
        description="The same numbers packed: row after row, little-endian float64 (8 bytes "
        "each), as one base64 string (RFC 4648, padded, no line breaks); a pose row is 504 "
        "bytes. Numpy: `base64.b64encode(rows.astype('<f8').tobytes())`; JavaScript: a "
        "Float64Array's bytes. Exact, and parsed ~5 times faster than JSON numbers.",
    ),
]
JointRow = Annotated[list[Joint], Field(min_length=1, max_length=21)]


class ColumnarTargets(_Body):
    joints: JointRow | Annotated[list[JointRow], Field(min_length=1)] = Field(
        description="K joint names shared by every item, or one row of K names per item "
        "(every row the same length K).",
    )
    positions: list[list[Coordinate]] | Packed = Field(
        description="One row per item: the K targets' x, y, z in the order of `joints`; or "
        "packed (3K float64 numbers a row)."
    )
    weights: list[Weight] | list[list[Weight]] | None = Field(
        default=None, description="K weights shared by every item, or one row per item."
    )


class ColumnarBatch(_Body):
    """The **columnar form** of a batch: arrays instead of items, for throughput (parsed
    straight into arrays, answered from arrays). Every item has K targets and P pins;
    joint names are shared or given per item; the options hold for every item."""

    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        json_schema_extra={
            "examples": [
                {
                    "poses": [[v for name in JOINT_NAMES for v in _REST_EXAMPLE[name]]],
                    "targets": {"joints": ["left_wrist"], "positions": [[0.3, 1.4, 0.2]]},
                    "pins": ["left_ankle", "right_ankle"],
                    "options": {"method": "neural", "reach": "soft"},
                }
            ]
        },
    )

    poses: Annotated[list[PoseRow], Field(min_length=1)] | Packed = Field(
        description="One row of 63 numbers per item; or packed (the answer's `poses` then "
        "come back packed alike)."
    )
    targets: ColumnarTargets
    pins: list[Joint] | list[list[Joint]] = Field(
        default_factory=list,
        description="P joints held where they are, shared or one row per item; distinct "
        "and none of them targeted.",
    )
    options: SolveOptions = Field(default_factory=SolveOptions)


class ColumnarResponse(BaseModel):
    """The answer to a columnar batch: arrays, row b for item b."""

    poses: list[list[float]] | str = Field(
        description="One row of 63 numbers per item; packed (one base64 string of "
        "little-endian float64, 504 bytes a row) where the request's `poses` were."
    )
    errors: list[list[float]] = Field(description="Distance (m) of each target, [B][K].")
    reached: list[list[bool]] = Field(description="errors <= tolerance, [B][K].")
    pin_errors: list[list[float]] = Field(description="How far each pin moved (m), [B][P].")
    max_bone_length_error: list[float] = Field(description="Per item, relative.")
    iterations: list[int] = Field(description="FABRIK iterations per item.")
    solvers: list[list[str]] = Field(description="The distinct solver sequences used.")
    solver_of: list[int] = Field(description="Per item: its index into `solvers`.")
    model: str
    method: Literal["neural", "fabrik"]
    floor: float = Field(
        description="Height (m, world y) of the ground every item was solved over: "
        "`options.floor` (0 if none), as given."
    )
    up_warning: list[str | None] = Field(
        description="Per item: its start pose's `up_warning`, as the item list's answers "
        "say it (null where its pelvis-to-neck line leans 60 degrees or less from +Y)."
    )
    floor_warning: list[str | None] = Field(
        description="Per item: its start pose's `floor_warning`, as the item list's answers "
        "say it (null where the floor lies below its pelvis by at most 4 pelvis-to-neck "
        "distances)."
    )
    handedness_warning: list[str | None] = Field(
        description="Per item: its start pose's `handedness_warning`, as the item list's "
        "answers say it."
    )
