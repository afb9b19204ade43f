"""Request and response bodies of the REST API (the transport layer's types)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, create_model

from core.skeleton import BASE_KEYPOINTS, JOINT_NAMES

Vec3 = Annotated[
    list[float],
    Field(min_length=3, max_length=3, description="x, y, z in metres (world frame, +Y up)."),
]
Joint = Annotated[
    str,
    Field(
        description="A joint name of the canonical skeleton.",
        json_schema_extra={"enum": list(JOINT_NAMES)},
    ),
]

#: A whole pose: exactly the 21 joints, each [x, y, z] in metres (world frame).
Pose: type[BaseModel] = create_model(
    "Pose",
    __config__=ConfigDict(extra="forbid", strict=True),
    __doc__="Every one of the 21 joints, world space, metres.",
    **{name: (Vec3, ...) for name in JOINT_NAMES},  # type: ignore[call-overload]
)

_REST_EXAMPLE: dict[str, Any] = {
    "pelvis": [0.0, 0.95, 0.0],
    "spine1": [0.0, 1.1, -0.01],
    "spine2": [0.0, 1.21, -0.01],
    "neck": [0.0, 1.43, -0.03],
    "head": [0.0, 1.52, -0.01],
    "left_collar": [0.03, 1.39, -0.05],
    "left_shoulder": [0.17, 1.39, -0.05],
    "left_elbow": [0.2, 1.12, -0.07],
    "left_wrist": [0.22, 0.89, -0.04],
    "right_collar": [-0.03, 1.39, -0.05],
    "right_shoulder": [-0.17, 1.39, -0.05],
    "right_elbow": [-0.2, 1.12, -0.07],
    "right_wrist": [-0.22, 0.89, -0.04],
    "left_hip": [0.09, 0.9, 0.0],
    "left_knee": [0.1, 0.49, 0.01],
    "left_ankle": [0.1, 0.08, -0.02],
    "left_foot": [0.11, 0.02, 0.1],
    "right_hip": [-0.09, 0.9, 0.0],
    "right_knee": [-0.1, 0.49, 0.01],
    "right_ankle": [-0.1, 0.08, -0.02],
    "right_foot": [-0.11, 0.02, 0.1],
}


class _Body(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class Target(_Body):
    joint: Joint
    position: Vec3
    weight: float = Field(
        default=1.0,
        gt=0.0,
        le=1000.0,
        description="Relative importance: later in the solver sequence, more pull in FABRIK.",
    )


class SolveOptions(_Body):
    method: Literal["neural", "fabrik"] = "neural"
    preserve_bone_lengths: bool = True
    reach: Literal["soft", "exact"] = "soft"
    tolerance: float = Field(
        default=0.001, ge=1e-6, le=1.0, description="Metres: `reached` and exact reach."
    )
    floor: float = Field(
        default=0.0,
        ge=-1e4,
        le=1e4,
        description="Height (m, world y) of the ground the character stands on. The "
        "networks learned poses over a floor at y = 0; a character on a 1 m box needs 1.0.",
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
    pins: list[Joint] = Field(default_factory=list, max_length=21)
    options: SolveOptions = Field(default_factory=SolveOptions)


class TargetResult(BaseModel):
    joint: str
    error: float = Field(description="Distance (m) from the joint to its target.")
    reached: bool = Field(description="error <= tolerance.")


class SolveResponse(BaseModel):
    pose: Pose
    targets: list[TargetResult]
    pins: list[TargetResult] = Field(
        default_factory=list, description="How far each pinned joint moved (m)."
    )
    max_bone_length_error: float = Field(description="Max relative bone-length error.")
    solvers: list[str] = Field(description="Solver sequence used (target-set keys).")
    model: str = Field(description="Manifest version of the models.")
    method: Literal["neural", "fabrik"]
    iterations: int = Field(description="FABRIK iterations used (0 when none ran).")


class BatchRequest(_Body):
    items: list[SolveRequest] = Field(min_length=1)


class BatchResponse(BaseModel):
    items: list[SolveResponse]


class Keypoint(_Body):
    joint: Joint
    position: Vec3


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
    floor: float = Field(
        default=0.0, ge=-1e4, le=1e4, description="Height (m, world y) of the ground."
    )
    bone_lengths: dict[str, Annotated[float, Field(ge=1e-3, le=2.0)]] | None = Field(
        default=None,
        description="Length (m) of the bone ending at each named joint; missing bones "
        "take the reference length scaled like the given ones.",
    )


class CompleteResponse(BaseModel):
    pose: Pose
    keypoints: list[TargetResult]
    levels: list[int] = Field(description="Completion levels run (1 = six base points).")
    model: str


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
    models: list[ModelInfo]


class Problem(BaseModel):
    """RFC 9457 problem details: every 4xx/5xx answer (``application/problem+json``)."""

    model_config = ConfigDict(extra="allow")

    type: str
    title: str
    status: int
    detail: str
    errors: list[dict[str, str]] | None = Field(
        default=None, description="Per-field errors of an invalid body."
    )
    missing: list[str] | None = Field(default=None, description="Missing base key points.")


class Health(BaseModel):
    status: Literal["live", "ready", "not ready"]
    detail: str | None = None
