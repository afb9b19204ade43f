"""Characters as users have them: their own skeleton (JSON) or a BVH file, solved through
the canonical 21 joints and answered in their own terms.

The flow of both endpoints: the client's skeleton and pose (``core.characters``) -> its
joint map (``core.characters_maps``: automatic for common naming schemes, or explicit) ->
the 21 mapped points, converted to metres and +Y up -> ``Engine.solve`` -> back to the
client's units and axes -> local rotations by ``core.retarget`` (swing-only, twist kept,
bone lengths the character's own) -> rotations (JSON) or the file with that frame edited
(``core.bvh_write``). Every target and pin is reported as measured on the answer itself
(forward kinematics of the returned rotations), in metres. Conventions: docs/characters.md.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar, Literal, TypeVar

import numpy as np
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    RootModel,
    Tag,
    ValidationError,
    ValidationInfo,
    ValidatorFunctionWrapHandler,
    WrapValidator,
    model_validator,
)
from pydantic_core import InitErrorDetails, PydanticCustomError

from core.bvh import MAX_JOINTS, MAX_NAME
from core.characters import (
    F64,
    CharacterError,
    Pose,
    Skeleton,
    forward_kinematics,
    matrix_to_quat,
    quat_to_matrix,
    units_scale,
    up_rotation,
)
from core.characters_maps import (
    LEG_BANDS,
    NAMED_UNIT_LEG_M,
    JointMap,
    human_units,
    infer_units,
    rest_points,
    up_of,
)
from core.retarget import canonical_points, retarget
from core.sides import read_sides
from core.skeleton import BONES, JOINT_NAMES
from core.text import clip, did_you_mean, quoted, shown
from core.units import UNITS
from service.bounded import Bounded, at_most
from service.engine import Engine
from service.errors import CHARACTER_BOUND, InvalidRequest
from service.floors import floor_warning
from service.grounded import grounded
from service.joint_names import resolve_joint
from service.problems import SolveProblem, SolveResult
from service.rigs import json_map, json_skeleton
from service.schemas import (
    FLOOR_WARNING,
    ITERATIONS,
    MAX_WEIGHT,
    NamedTargetResult,
    SolveOptions,
    SolveRequest,
    SolveResponse,
)
from service.schemas import MAX_COORDINATE as MAX_METRES
from service.validation import MIN_BONE, problem_of, validate_as

MAX_COORDINATE = CHARACTER_BOUND  # client units; beyond this a coordinate is nonsense
#: The shortest quaternion a client may send (normalised here; shorter ones say nothing of
#: a rotation that float noise does not).
MIN_QUAT_LENGTH = 1e-6

Number = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Vec3 = Annotated[
    list[Number], Field(min_length=3, max_length=3, description="x, y, z in the client's units.")
]
Quat = Annotated[
    list[Annotated[float, Field(allow_inf_nan=False)]],
    Field(
        min_length=4,
        max_length=4,
        description=f"[x, y, z, w] (scalar last); any length from {MIN_QUAT_LENGTH:g} (normalised "
        "here).",
    ),
]


def _one_units_error(value: Any, handler: ValidatorFunctionWrapHandler) -> Any:
    """One message for the two forms units take (pydantic names each branch of the union,
    its internals included: ``units.literal['m',…]: …; units.constrained-float: …``)."""
    try:
        return handler(value)
    except ValidationError:
        raise PydanticCustomError(
            "units",
            "must be one of m, cm, mm, in, ft (lower case) or metres per unit, a number > 0; "
            "got {got}",
            {"got": quoted(value)},
        ) from None


Units = Annotated[
    Literal["m", "cm", "mm", "in", "ft"] | Annotated[float, Field(gt=0, allow_inf_nan=False)],
    WrapValidator(_one_units_error),
    Field(description="Unit name, or metres per unit (e.g. 0.0564444 for CMU ASF units)."),
]


V = TypeVar("V")
#: An object keyed by joint names: at most as many entries as a character has joints,
#: counted before any entry is validated (``service.bounded.at_most``).
JointKeyed = Annotated[
    dict[str, V], Field(max_length=MAX_JOINTS), BeforeValidator(at_most(MAX_JOINTS))
]


class _Body(Bounded):
    """A request model (``service.bounded``: strict, no unknown keys, bounded errors)."""


class CharacterTarget(_Body):
    joint: str = Field(description="The client's joint name (mapped) or a canonical name.")
    position: Vec3
    weight: float = Field(default=1.0, gt=0.0, le=MAX_WEIGHT, allow_inf_nan=False)


#: the requests' `joint_map` (the character form's, a BVH file's)
JOINT_MAP = Field(
    default=None, description="canonical joint -> the client's joint name (a BVH file's "
    "joint, or a point along one of its bones: docs/characters.md); wins over the automatic "
    "map joint by joint.",
)  # fmt: skip


class _Edit(_Body):
    """What one frame's edit asks: targets, pins, options."""

    targets: list[CharacterTarget] = Field(min_length=1, max_length=21)
    pins: list[str] = Field(
        default_factory=list,
        max_length=21,
        json_schema_extra={"uniqueItems": True},
        description="Joints held where they are: the client's mapped joint names or "
        "canonical ones, as targets take (each once; not a target too).",
    )
    options: SolveOptions = Field(default_factory=SolveOptions)


class _Frame(_Edit):
    joint_map: JointKeyed[str] | None = JOINT_MAP


class JointSpec(_Body):
    name: str = Field(min_length=1, max_length=MAX_NAME)
    parent: str | None = Field(
        default=None, description="The parent joint's name; null for the root (one root)."
    )
    offset: Vec3 = Field(description="Rest offset from the parent (root: rest position).")


class CharacterSkeleton(_Body):
    joints: list[JointSpec] = Field(min_length=1, max_length=MAX_JOINTS)
    units: Units | None = Field(
        default="m", description="null: inferred from the rest pose (or else the pose)."
    )
    up: Literal["+Y", "+Z"] | None = Field(
        default="+Y", description="null: inferred from the rest pose (or else the pose)."
    )


class CharacterSolveRequest(_Frame):
    """The character form of `POST /v1/solve`: a skeleton of the client's own, its local
    rotations and root position; targets and pins name its joints or canonical ones."""

    character: CharacterSkeleton = Field(description="The skeleton: joints, units, up axis.")
    rotations: JointKeyed[Quat] = Field(
        default_factory=dict, description="Local rotation per joint; missing joints: identity."
    )
    root_position: Vec3 | None = Field(default=None, description="Default: the root's offset.")


def field_error(title: str, loc: tuple[str, ...], message: str, data: Any) -> ValidationError:
    """A validation error at ``loc`` (relative to the model being validated: nested in a
    batch it becomes ``items[i].<loc>``)."""
    error = InitErrorDetails(type=PydanticCustomError("request_form", message), loc=loc, input=data)
    return ValidationError.from_exception_data(title, [error])


def _alias_schema(schema: dict[str, Any]) -> None:
    """The contract of the alias as it is read: `skeleton` (deprecated) or `character`, one
    of the two (a contract audit: the documented example, which uses `skeleton`, was
    invalid by the schema and answered 200)."""
    props = schema["properties"]
    props["skeleton"] = {
        **props["character"],
        "deprecated": True,
        "description": "The earlier name of `character`: give one of the two (both: a 422).",
    }
    schema["required"] = [r for r in schema.get("required", []) if r != "character"]
    schema["oneOf"] = [{"required": ["character"]}, {"required": ["skeleton"]}]


class CharacterAliasRequest(CharacterSolveRequest):
    """The body of `POST /v1/character/solve`, an alias of the character form of
    `POST /v1/solve`: the same fields; `skeleton` is accepted as the earlier name of
    `character`."""

    model_config = ConfigDict(extra="forbid", strict=True, json_schema_extra=_alias_schema)
    #: earlier name -> field (a slip of an earlier name is offered it: service.field_names)
    EARLIER_NAMES: ClassVar[dict[str, str]] = {"skeleton": "character"}

    @model_validator(mode="before")
    @classmethod
    def _earlier_name(cls, data: Any) -> Any:
        for old, new in cls.EARLIER_NAMES.items():
            if isinstance(data, dict) and old in data:
                if new in data:
                    message = f"give `{new}` or its earlier name `{old}`, not both"
                    raise field_error(cls.__name__, (old,), message, data)
                data = {(new if k == old else k): v for k, v in data.items()}
        return data


#: the answers' `units_warning`
UNITS_WARNING = Field(
    default=None, description="Where the named `units` make the rest-pose leg (hip to ankle) "
    "no person's, 0.3-1.3 m, but not past what a named unit may give (0.1-5 m, else a 422): "
    "what it is and the units that make it a person's (a file in centimetres sent as "
    "inches is a body 2.54 times too big); the answer is solved (`/v1/bvh/inspect`: read) "
    "as asked. Null otherwise.",
)  # fmt: skip


#: the answers' `up_warning`
UP_WARNING = Field(
    default=None, description="Where `up` was inferred (not given) from the rest pose and "
    "the frame edited stands up along the other axis (ankles to head; its root turns the "
    "rest pose so: a rig exported with its root turned a quarter turn, or a body lying down "
    "in a frame): both named, with the `up` that reads the frame upright; the answer used "
    "the rest pose's axis. Or where `up` was given and the frame stands up along the other "
    "axis, the rest pose along neither: solved lying down, as given. Null otherwise.",
)  # fmt: skip


#: the answers' `sides_warning`
SIDES_WARNING = Field(
    default=None, description="Where the body's left and right joints look named for the "
    "other side (read as named, its toes and bent knees point backwards from the way its "
    "hips and shoulders face it, in its rest pose, or in the frame where the rest pose says "
    "nothing): the joint map is swapped, so the body is solved as the body it is (its joints "
    "keep their names; `joint_map` shows the map used), but kept where the request's "
    "`joint_map` names a side joint or the rig's joints carry the canonical names; either "
    "is said here. Null otherwise.",
)  # fmt: skip


class _Mapped(BaseModel):
    """How the character was read: its joint map, units, up axis; the models."""

    joint_map: dict[str, str] = Field(description="canonical joint -> the point it was mapped to")
    scheme: str = Field(description="Naming scheme of the automatic map, or 'explicit'.")
    units: str | float = Field(
        description="As given, else as inferred (named, or metres per unit)."
    )
    up: str = Field(description="As given, else as inferred.")
    units_warning: str | None = UNITS_WARNING
    model: str


class _Solved(BaseModel):
    """What one frame's solve did: targets and pins as measured on the answer."""

    targets: list[NamedTargetResult]
    pins: list[NamedTargetResult]
    solvers: list[str]
    method: Literal["neural", "fabrik"]
    iterations: int = Field(description=ITERATIONS)  # (as the pose form's)
    floor: float = Field(
        description="Height (m, along the character's up axis) of the ground the solve used: "
        "`options.floor` (0 if none), taken as given (`floor_warning` says where it lies far "
        "from the body)."
    )
    up_warning: str | None = UP_WARNING
    floor_warning: str | None = Field(default=None, description=FLOOR_WARNING)
    sides_warning: str | None = SIDES_WARNING


class _Answer(_Solved, _Mapped):
    pass


class CharacterSolveResponse(_Answer):
    rotations: dict[str, list[float]] = Field(
        description="Every joint: [x, y, z, w]; unit length with w >= 0 for the joints the "
        "solve turned, the request's quaternion as sent for the others (not normalised; "
        "identity for a joint the request left out)."
    )
    root_position: list[float] = Field(description="The root's position (the client's units).")
    positions: dict[str, list[float]] = Field(
        description="Every joint, by FK of the answer (the client's units)."
    )


# --------------------------------------------------------------------------------------
# The body of /v1/solve and of each /v1/solve/batch item: either form
# --------------------------------------------------------------------------------------
FORMS = (
    "give either `pose` (the 21 canonical joints, world space, metres) or `character` "
    "(a skeleton of your own: joints with name, parent and rest offset)"
)

#: ``skeleton`` where the alias route is not: on ``/v1/solve`` and in a batch's item.
SKELETON_HERE = (
    "Extra inputs are not permitted: `skeleton` (the earlier name of `character`) is read "
    "only by POST /v1/character/solve; here send the skeleton as `character`, or the 21 "
    "canonical joints as `pose`"
)


def _form_of(data: Any) -> str:
    if isinstance(data, dict):
        return "character" if "character" in data else "pose"
    return "character" if isinstance(data, CharacterSolveRequest) else "pose"


class SolveBody(
    RootModel[
        Annotated[
            Annotated[SolveRequest, Tag("pose")]
            | Annotated[CharacterSolveRequest, Tag("character")],
            Discriminator(_form_of),
        ]
    ]
):
    """A solve request in one of two forms: the **pose form** (`pose`: the 21 canonical
    joints) answered with `pose`, or the **character form** (`character`: the client's own
    skeleton, `rotations`, `root_position`) answered with `rotations` of every joint,
    `root_position` and `positions` (docs/characters.md). Exactly one of `pose` and
    `character` is given."""

    @model_validator(mode="wrap")
    @classmethod
    def _form(cls, data: Any, handler: ValidatorFunctionWrapHandler, info: ValidationInfo) -> Any:
        if isinstance(data, dict):
            if "character" in data and "pose" in data:
                raise field_error(cls.__name__, ("character",), f"{FORMS}, not both", data)
            if "character" not in data and "pose" not in data:
                if "skeleton" in data:  # the alias route's earlier name of `character`
                    raise field_error(cls.__name__, ("skeleton",), SKELETON_HERE, data)
                raise field_error(cls.__name__, ("pose",), f"Field required: {FORMS}", data)
        return validate_as(
            data,
            handler,
            lambda d: CharacterSolveRequest if _form_of(d) == "character" else SolveRequest,
            info.context,
        )


class BatchRequest(_Body):
    items: list[SolveBody] = Field(min_length=1, description="Each in either form.")


class BatchResponse(BaseModel):
    items: list[SolveResponse | CharacterSolveResponse] = Field(description="In request order.")


@dataclass(frozen=True)
class Character:
    skel: Skeleton
    pose: Pose
    jmap: JointMap
    scale: float  # metres per unit
    up: F64  # rotation taking the client's up axis to +Y
    units: str | float
    up_name: str
    #: where its units and up are (``character.`` in the character form, none for BVH)
    fields: str = ""
    #: what a degenerate pose of its mapped points is put down to: the client's joint map,
    #: else its skeleton (``character.joints``) or its file (``bvh``)
    points: str = "bvh"
    #: what the named units make the body where it is no person's (:func:`_odd_size`),
    #: None where it is a person's; the answers say it with :meth:`units_warning`
    odd_size: str | None = None
    #: the answers' ``up_warning`` (:func:`_up_inferred`), None where the frame agrees
    up_warning: str | None = None
    #: the answers' ``sides_warning`` (:func:`core.sides.read_sides`), None where the
    #: body's sides are as named
    sides_warning: str | None = None

    def units_warning(self, done: str = "solved") -> str | None:
        """The answers' ``units_warning``: the body's odd size and what was done with it,
        as asked: ``done`` is "solved" on the solve routes, "read" on ``/v1/bvh/inspect``
        (which solves nothing)."""
        if self.odd_size is None:
            return None
        return f"{self.odd_size}; {done} as asked ({OWN_SIZE})"

    def to_service(self, p: F64) -> F64:
        return np.asarray(self.scale * (p @ self.up.T))

    def from_service(self, p: F64) -> F64:
        return np.asarray((p / self.scale) @ self.up)


def invalid_request(exc: Exception) -> InvalidRequest:
    detail, where = str(exc), getattr(exc, "location", None)
    if where is None:  # the message's own prefix names the field (service.errors)
        return InvalidRequest(detail)
    message = detail.removeprefix(f"{where}: ")
    return InvalidRequest(detail, errors=[{"location": where, "message": message}])


def _leg_in(leg: float) -> str:
    """The named units that make a leg of ``leg`` file units a person's, each with the leg
    it makes (a message's hint: the file's own tool knows which it is)."""
    return " or ".join(f'"units": "{u}" ({leg * UNITS[u]:.2f} m)' for u in human_units(leg))


def make_character(
    skel: Skeleton,
    pose: Pose,
    jmap: JointMap,
    units: Any,
    up: str | None,
    prefix: str = "",
    stated: bool = True,
    up_stated: bool = True,
    points: str = "bvh",
    fields: str = "",
    map_keys: Collection[str] = (),
) -> Character:
    """The character of a pose; ``units`` and ``up`` as the client gave them (None: read
    from the rest pose; ``stated`` / ``up_stated`` False: the character form's default),
    errors naming the fields ``<prefix>units`` and ``<prefix>up``; ``fields``: where its
    units and up are, an item's prefix left out (``character.``; none for BVH),
    ``points``: what a degenerate pose of its mapped points is put down to, and ``map_keys``:
    the canonical joints the client's ``joint_map`` names (``core.sides.read_sides``)."""
    where = f"{prefix}units"
    warning = None
    rest, frame = rest_points(skel, jmap), canonical_points(skel, pose, jmap)  # (once each)
    rest_up, frame_up = up_of(rest), up_of(frame)
    if isinstance(units, str) and units in UNITS:  # a named unit: a slip is refused
        _, leg = infer_units(skel, jmap)
        metres = leg * UNITS[units]
        given = "" if stated else " (the default: no units were given)"
        said = (
            f"{where}: {quoted(units)}{given} makes the rest-pose leg (hip to ankle, {leg:.4g} "
            f"file units) {metres:.4g} m long"
        )
        low, high = NAMED_UNIT_LEG_M
        fits = _leg_in(leg)
        if not low <= metres <= high:
            reads = f"; a person's leg (0.3-1.3 m) with {fits}" if fits else ""
            raise InvalidRequest(
                f"{said}, outside the {low:g}-{high:g} m a named unit may give{reads}; a "
                "character of that size: units as metres per unit (a number), taken as given"
            )
        warning = _odd_size(said, metres, fits)
    if units is None:
        name, leg = infer_units(skel, jmap)
        if name is None:
            fits = _leg_in(leg) or '"units": "in"'
            raise InvalidRequest(
                f"{where}: not plain from the rest pose (its leg, hip to ankle, is {leg:.4g} "
                "units: not 0.3-1.3 m, 45-130 cm or 450-1300 mm); state them, e.g. "
                f'{fits}, or a number of metres per unit ("units": 0.0564444 for CMU ASF)'
            )
        units = name
    # up given (or the default) against the body: refused where the rest pose stands up
    # along the other axis and the frame does not stand along this one (a rig whose rest is
    # Z-up but whose root turns it to stand up along +Y is right in +Y; the Z-up child,
    # upright or bent, is not)
    if up is not None and rest_up is not None and rest_up != up and frame_up != up:
        given = "" if up_stated else " (the default: no up was given)"
        raise InvalidRequest(
            f"{prefix}up: {quoted(up)}{given}, but the rest pose stands up along "
            f"{rest_up} (ankles to head) and this frame not along {up}; give "
            f'"up": "{rest_up}", or null to infer it'
        )
    up_warning = None
    if up is not None and rest_up is None and frame_up not in (None, up):
        up_warning = _up_against_frame(f"{prefix}up", up, frame_up, up_stated)
    if up is None:
        found = rest_up
        if found is not None and frame_up not in (None, found):
            up_warning = _up_inferred(f"{prefix}up", found, frame_up)
        found = found or frame_up
        if found is None:
            raise InvalidRequest(
                f"{prefix}up: neither the rest pose nor this frame stands up along +Y or +Z; "
                'state the axis the file\'s world has up: "up": "+Y" or "+Z"'
            )
        up = found
    turn = up_rotation(up)
    upright = (rest_up == up, frame_up == up)  # (each says nothing lying down)
    jmap, sides_warning = read_sides(rest @ turn.T, frame @ turn.T, jmap, map_keys, upright)
    return Character(
        skel, pose, jmap, units_scale(units), turn, units, up, fields, points, warning,
        up_warning, sides_warning,
    )  # fmt: skip


def _up_inferred(where: str, rest: str, frame: str) -> str:
    """The answers' ``up_warning``: ``up`` inferred as ``rest`` from the rest pose, where
    the frame edited stands up along ``frame`` (an audit, 2026-12-06: a rig whose Z-up
    offsets its root turns upright along +Y was solved lying down without a word, its
    answer up to 7.6 cm from the upright one's)."""
    return (
        f"{where}: inferred {quoted(rest)} from the rest pose (ankles to head), but this "
        f"frame stands up along {frame} (its root turns the rest pose so): give "
        f'"up": "{frame}" if the file\'s world is {frame} up; {quoted(rest)} is right for a '
        "body lying down in this frame"
    )


def _up_against_frame(where: str, up: str, frame: str, stated: bool) -> str:
    """The answers' ``up_warning``: ``up`` given (or the default), the rest pose standing
    along neither axis and the frame edited along ``frame``: solved lying down. An API audit
    (2026-12-07) sent a Bandai-Namco walk (a +Y file whose rest pose stands along neither)
    with ``"up": "+Z"``: it was solved lying down without a word."""
    given = "" if stated else " (the default: no up was given)"
    return (
        f"{where}: {quoted(up)}{given}, but this frame stands up along {frame} (ankles to "
        f"head; the rest pose along neither axis), so it was solved lying down: give "
        f'"up": "{frame}" if the file\'s world is {frame} up'
    )


def _odd_size(said: str, metres: float, fits: str) -> str | None:
    """The answers' ``units_warning``: ``said`` (what a named unit makes the rest-pose leg,
    ``metres`` long) where that is no person's (the metre band of
    :data:`core.characters_maps.LEG_BANDS`) but within what a named unit may give (else
    refused), with the units that ``fits``: a file in centimetres sent as inches is a body
    2.54 times too big (an 80 cm leg read as 2.03 m), solved (or read) as asked: the
    answers add it (:meth:`Character.units_warning`; the editor's own test opens one so)."""
    low, high, _ = LEG_BANDS[0]
    if low <= metres <= high:
        return None
    return f"{said}, not a person's {low:g}-{high:g} m" + (
        f": {fits} would make it one" if fits else ""
    )


#: how a character really of an odd size is given (the end of a ``units_warning``)
OWN_SIZE = "a character of that size: units as metres per unit, a number"


def _refused(where: str, message: str) -> InvalidRequest:
    """A 422 whose one error is at the field ``where``."""
    return InvalidRequest(f"{where}: {message}", errors=[{"location": where, "message": message}])


def _within_reach_of_metres(points: F64, where: str, what: str, ch: Character) -> None:
    """The service works within ±``MAX_METRES`` m, as the pose form does: a character
    whose values times its units land beyond (or overflow) is refused by name (``what``,
    at the field ``where``), before any geometry runs on numbers it cannot hold (an SVD
    that does not converge, a NaN error)."""
    far = float(np.max(np.abs(points), initial=0.0))
    if not far <= MAX_METRES:
        raise _refused(
            where,
            f"{what} {far:.4g} m from the origin in metres (values x units "
            f"{quoted(ch.units)} = {ch.scale:.4g} m per unit); the service works within "
            f"±{MAX_METRES:g} m: check the units or move the character nearer the origin",
        )


def character_problem(ch: Character, req: _Edit, where: str = "") -> SolveProblem:
    """The canonical solve problem of one frame, in metres and +Y up; errors name their
    field under ``where`` (e.g. ``items[3]``)."""
    prefix = f"{where}." if where else ""
    with np.errstate(over="ignore", invalid="ignore"):  # refused by name just below
        pts = ch.to_service(canonical_points(ch.skel, ch.pose, ch.jmap))
        goals = [ch.to_service(np.asarray(t.position, dtype=np.float64)) for t in req.targets]
    # the pose's points come from the skeleton's offsets, the pose and the units: the
    # character form's pose (its root_position, rotations), or the BVH file's frame
    pose_at = f"{prefix}{ch.fields or 'bvh'}".removesuffix(".")
    _within_reach_of_metres(pts, pose_at, "the pose's mapped joints lie", ch)
    for i, g in enumerate(goals):
        _within_reach_of_metres(g, f"{prefix}targets[{i}].position", "the target lies", ch)
    lengths = np.linalg.norm(pts[[c for c, _ in BONES]] - pts[[p for _, p in BONES]], axis=1)
    if lengths.min() < MIN_BONE:
        short = [JOINT_NAMES[c] for (c, _), n in zip(BONES, lengths, strict=True) if n < MIN_BONE]
        if len(short) == len(BONES):  # every bone: the units, not the map
            raise _refused(
                f"{prefix}{ch.fields}units",
                f"the whole body spans {float(lengths.sum()):.3g} m of bones at "
                f"{quoted(ch.units)} = {ch.scale:.4g} m per unit; check the units",
            )
        raise _refused(
            f"{prefix}{ch.points}",
            f"the mapped points make zero-length bones ending at {', '.join(short)} (each "
            f"canonical joint must be at least {MIN_BONE * 1000:g} mm from its parent)",
        )
    return problem_of(
        pts,
        [
            resolve_joint(ch.skel, ch.jmap, t.joint, f"{prefix}targets[{i}].joint")
            for i, t in enumerate(req.targets)
        ],
        np.asarray(goals, dtype=np.float64),
        [t.weight for t in req.targets],
        [
            resolve_joint(ch.skel, ch.jmap, name, f"{prefix}pins[{i}]")
            for i, name in enumerate(req.pins)
        ],
        req.options,
        where,
        ([t.joint for t in req.targets], list(req.pins)),
    )


@dataclass(frozen=True)
class Edit:
    pose: Pose
    changed: frozenset[int]  # joints whose local rotation or translation changed
    problem: SolveProblem
    result: SolveResult
    version: str


def solve_character(engine: Engine, ch: Character, req: _Edit) -> Edit:
    """Solve one frame of a character: the new pose and what it took."""
    return solve_prepared(engine, ch, character_problem(ch, req))


def solve_prepared(engine: Engine, ch: Character, p: SolveProblem) -> Edit:
    """Solve ``p`` (from :func:`character_problem`) alone and retarget the answer onto the
    character: every character solve, single or a batch item, runs exactly this."""
    (result,) = engine.solve([p])
    solved = ch.from_service(np.asarray(result.pose, dtype=np.float64))
    # in joint order: the answer must not depend on the order the request listed them in
    given = sorted(range(p.n_targets), key=lambda q: int(p.target_idx[q]))
    pairs = [(int(j), ch.from_service(g)) for j, g in zip(p.target_idx, p.target_pos, strict=True)]
    targets = [pairs[q] for q in given]
    # a pin the canonical answer broke (a target it met instead) lies where it put it
    pins = sorted(
        ((j, g if err <= p.tolerance else solved[j])
         for (j, g), err in zip(pairs[p.n_targets :], result.pin_errors, strict=True)),
        key=lambda pin: pin[0],
    )  # fmt: skip
    if p.reach == "exact":  # the targets the answer met are held as pins are
        met = (result.errors <= p.tolerance)[given]
        goals = {"held": [t for t, ok in zip(targets, met, strict=True) if ok],
                 "exact": [t for t, ok in zip(targets, met, strict=True) if not ok]}  # fmt: skip
    else:  # the targeted joints come near where the canonical answer put them
        goals = {"soft": [(j, solved[j]) for j, _ in targets]}
    out = grounded(ch.to_service, p, solved, targets, pins, lambda held: retarget(
        ch.skel, ch.pose, ch.jmap, solved, pins=held, tolerance=p.tolerance / ch.scale, **goals
    ))  # fmt: skip
    return Edit(out.pose, out.changed, p, result, engine.version)


#: Metres: how much nearer an answer must bring a target to be answered. One that brings
#: none nearer than the character as sent is answered with it as sent: what the solve moved
#: is noise (the networks' float32 turns a target placed where its joint stands: up to
#: 2.5e-5 degrees on 16 joints of CMU salsa), which would churn a user's animation curves.
NEARER = 1e-6


def moves_a_target(ch: Character, edit: Edit, after: F64) -> bool:
    """Whether the answer's mapped points ``after`` (the 21 points, client units) bring a
    target more than :data:`NEARER` nearer than the sent pose has it (``edit.problem.pose``:
    the same points of the pose as sent, in metres)."""
    p = edit.problem
    goals, at = p.target_pos[: p.n_targets], p.target_idx[: p.n_targets]
    old = np.linalg.norm(p.pose[at] - goals, axis=1)
    new = np.linalg.norm(ch.to_service(after)[at] - goals, axis=1)
    return bool((old - new > NEARER).any())


def edit_report(ch: Character, edit: Edit, points: F64) -> dict[str, Any]:
    """The fields of :class:`_Answer`, targets and pins measured on ``points`` (the 21
    mapped points of the answer, client units)."""
    p, r = edit.problem, edit.result
    got = ch.to_service(points)[p.target_idx]
    errors = np.linalg.norm(got - p.target_pos, axis=1).tolist()
    names = p.names or [JOINT_NAMES[int(j)] for j in p.target_idx]
    rows = [
        {"joint": JOINT_NAMES[int(j)], "name": n, "error": e, "reached": e <= p.tolerance}
        for j, n, e in zip(p.target_idx, names, errors, strict=True)
    ]
    return {
        "targets": rows[: p.n_targets],
        "pins": rows[p.n_targets :],
        "joint_map": ch.jmap.describe(),
        "scheme": ch.jmap.scheme,
        "units": ch.units,
        "up": ch.up_name,
        "units_warning": ch.units_warning(),
        "solvers": r.solvers,
        "model": edit.version,
        "method": "fabrik" if p.method == "fabrik" else "neural",
        "iterations": r.iterations,
        "floor": p.floor,
        "up_warning": ch.up_warning,
        "floor_warning": floor_warning(p.pose, p.floor, ch.up_name[-1].lower()),
        "sides_warning": ch.sides_warning,
    }


# --------------------------------------------------------------------------------------
# JSON characters
# --------------------------------------------------------------------------------------
def character_from_request(req: CharacterSolveRequest, where: str = "") -> Character:
    """The client's skeleton, pose and joint map; errors name their field under ``where``
    (e.g. ``items[3].character.joints[5].parent``)."""
    prefix = f"{where}." if where else ""
    joints = req.character.joints
    try:
        skel, order, digest = json_skeleton(
            ([j.name for j in joints], [j.parent for j in joints], [j.offset for j in joints]),
            f"{prefix}character.joints",
        )
        unknown = sorted(set(req.rotations) - set(skel.names))
        if unknown:
            names = ", ".join(quoted(n) + did_you_mean(n, skel.names) for n in unknown[:8])
            more = f"; and {len(unknown) - 8} more" if len(unknown) > 8 else ""  # (as others)
            raise CharacterError(f"{prefix}rotations: unknown joints {names}{more}")
        rot = np.broadcast_to(np.eye(3), (skel.size, 3, 3)).copy()
        for name, q in req.rotations.items():
            with np.errstate(over="ignore"):  # a huge one is fine: normalised overflow-safe
                length = float(np.linalg.norm(q))
            if length < MIN_QUAT_LENGTH:
                where = f"{prefix}rotations.{clip(name, 40)}"  # as a schema error names it
                raise CharacterError(
                    f"{where}: quaternion {q} shorter than {MIN_QUAT_LENGTH:g}", where
                )
            rot[skel.index[name]] = quat_to_matrix(q)
        trans = skel.offsets.copy()
        roots = [j for j, p in enumerate(skel.parents) if p < 0]
        if len(roots) != 1:
            raise CharacterError(
                f"{prefix}character.joints: {len(roots)} roots "
                f"{shown([skel.names[r] for r in roots])}; one is needed"
            )
        if req.root_position is not None:
            trans[roots[0]] = req.root_position
        pose = Pose(rot, trans)
        at = f"{prefix}character.joints"  # (a rest pose not read: its offsets named)
        jmap = json_map(
            skel, digest, req.joint_map, f"{prefix}joint_map",
            lambda j: at if j is None else f"{at}[{order[j]}].offset",
        )  # fmt: skip
        units, up = req.character.units, req.character.up
        given = req.character.model_fields_set
        where = f"{prefix}character."
        points = "joint_map" if req.joint_map else "character.joints"
        return make_character(
            skel, pose, jmap, units, up, where, "units" in given, "up" in given, points,
            "character.", list(req.joint_map or ()),
        )  # fmt: skip
    except CharacterError as exc:
        raise invalid_request(exc) from None


def character_answer(ch: Character, edit: Edit, given: dict[str, list[float]]) -> dict[str, Any]:
    """The answer: untouched joints give back the request's own quaternion (identity if it
    gave none), changed ones their new rotation with w >= 0; one that brings no target
    nearer (:func:`moves_a_target`) is the character as sent."""
    pose, changed = edit.pose, edit.changed
    g_rot, g_pos = forward_kinematics(ch.skel, pose)
    points = ch.jmap.points(g_rot, g_pos)
    if not moves_a_target(ch, edit, points):  # (the pose as sent: its own positions)
        pose, changed = ch.pose, frozenset()
        g_rot, g_pos = forward_kinematics(ch.skel, pose)
        points = ch.jmap.points(g_rot, g_pos)
    quats = matrix_to_quat(pose.rotations).tolist()
    rotations = {
        n: quats[j] if j in changed else given.get(n, [0.0, 0.0, 0.0, 1.0])
        for j, n in enumerate(ch.skel.names)
    }
    root = ch.skel.parents.index(-1)
    return {
        "rotations": rotations,
        "root_position": pose.translations[root].tolist(),
        "positions": dict(zip(ch.skel.names, g_pos.tolist(), strict=True)),
        **edit_report(ch, edit, points),
    }
