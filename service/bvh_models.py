"""The bodies and answers of the BVH routes: ``/v1/bvh/solve`` (one frame of a file
edited), ``/v1/bvh/solve/batch`` (many frames of one file, a clip's edits, in one call) and
``/v1/bvh/inspect`` (read only). Their work: ``service.character_bvh``; conventions:
docs/bvh.md."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field, ValidationInfo, model_validator

from service.characters import (
    JOINT_MAP,
    SIDES_WARNING,
    UNITS_WARNING,
    UP_WARNING,
    JointKeyed,
    Units,
    _Answer,
    _Body,
    _Edit,
    _Frame,
    _Mapped,
    _Solved,
)
from service.errors import too_many_items
from service.schemas import WHOLE

#: How a file's root position channels are read (and an edit written back).
RootPosition = Annotated[
    Literal["replace", "add"],
    Field(
        description="How the root's position channels are read: as its position "
        "(`replace`, the BVH convention) or as a displacement from its OFFSET (`add`: some "
        "exporters write that, ReActIdle's among them); an edit is written back the same way."
    ),
]


class _File(_Body):
    """A BVH file and how to read it."""

    bvh: str = Field(min_length=1, description="The whole BVH file.")
    units: Units | None = Field(default=None, description="Default: inferred from the file.")
    up: Literal["+Y", "+Z"] | None = Field(default=None, description="Default: inferred.")
    root_position: RootPosition = "replace"
    joint_map: JointKeyed[str] | None = JOINT_MAP


class BVHSolveRequest(_Frame, _File):
    frame: Annotated[int, Field(ge=0), WHOLE] = Field(
        description="Index of the frame to edit (0 = first)."
    )


class BVHInspectRequest(_File):
    frame: Annotated[int, Field(ge=0), WHOLE] = Field(
        default=0, description="Frame whose positions are answered."
    )


class BVHJointInfo(BaseModel):
    name: str
    parent: int = Field(description="Index in `joints` (-1 for a root).")
    offset: list[float]
    channels: list[str] = Field(description="As written in the file ([] for an End Site).")
    channel_start: int = Field(description="Column of the first channel in a MOTION row.")
    end_site: bool


class BVHAnchor(BaseModel):
    joint: str = Field(description="The file's joint the point is fixed to.")
    offset: list[float] = Field(description="From that joint's origin, in its frame (units).")
    label: str


class BVHCutShort(BaseModel):
    """Where a file ends before the frames its `Frames:` line declares are whole."""

    frame: int = Field(
        description="The first frame the file does not hold whole: it and "
        "those after it are lost; the frames before it read and edit."
    )
    values: int = Field(
        description="How many of that frame's values the file holds (0: "
        "it ends at the line before)."
    )
    line: int = Field(description="The file's last line.")
    frames: int = Field(description="The frames `Frames:` declares.")
    detail: str = Field(description="The same in words.")


#: the answers' `cut_short`: null for a whole file
CUT_SHORT = Field(
    default=None, description="Where the file ends before its declared frames are whole (a "
    "file cut short, e.g. an interrupted copy): its frames before that read and edit, the "
    "answer keeps the rest as sent (the cut line too); null for a whole file.",
)  # fmt: skip


#: the BVH answers' `rows_warning`
ROWS_WARNING = Field(
    default=None, description="The first MOTION row, of the frames not read (only those "
    "edited or inspected are), that holds another count of values than the file's channels "
    "or a value no number is (`nan`, `1,5`) or one past ±1e7 (`1e400`; a block of frames "
    "wrapped over lines: its first such value): its line, frame and what it holds. The "
    "answer keeps it as sent; a reader of the whole file may refuse the file. Null where none is "
    "found, for a file read whole, and for a file cut short (`cut_short`).",
)  # fmt: skip


#: the BVH answers' `root_warning`
ROOT_WARNING = Field(
    default=None, description="Where the frame's figure, its root channels read as "
    "`root_position` says, stands more than 0.3 m off the floor (y = 0) and the other "
    "reading stands it on the floor (within 0.1 m): that other reading named (some "
    "exporters write the root's position channels as a displacement from its OFFSET: "
    "`\"add\"`); or where no joint at or above the pelvis has three position channels, that "
    "the body cannot move in the file (its targets met by turns alone: `root channels: ...`); "
    "the answer is solved (`/v1/bvh/inspect`: read) as asked. Null otherwise.",
)  # fmt: skip


class BVHInspectResponse(BaseModel):
    joints: list[BVHJointInfo] = Field(description="File order (parents first).")
    anchors: dict[str, BVHAnchor] = Field(description="canonical joint -> its point.")
    joint_map: dict[str, str]
    scheme: str
    units: str | float = Field(
        description="As given, else as inferred (named, or metres per unit)."
    )
    metres_per_unit: float
    up: str = Field(description="As given, else as inferred.")
    frames: int = Field(description="Frames in the file.")
    frame_time: float = Field(description="Seconds per frame, as the file states it.")
    frame: int
    positions: list[list[float]] = Field(description="World position of every joint (units).")
    points: dict[str, list[float]] = Field(description="The 21 canonical points (units).")
    cut_short: BVHCutShort | None = CUT_SHORT
    rows_warning: str | None = ROWS_WARNING
    units_warning: str | None = UNITS_WARNING
    up_warning: str | None = UP_WARNING
    sides_warning: str | None = SIDES_WARNING
    root_warning: str | None = ROOT_WARNING


class _FrameEdited(BaseModel):
    frame: int
    changed_joints: list[str] = Field(description="Joints with a value rewritten (none: as sent).")
    root_warning: str | None = ROOT_WARNING


class BVHSolveResponse(_FrameEdited, _Answer):
    bvh: str = Field(description="The same file, only that frame's changed values rewritten.")
    cut_short: BVHCutShort | None = CUT_SHORT
    rows_warning: str | None = ROWS_WARNING


class BVHFrameEdit(_Edit):
    """One frame's edit of a clip: its targets, pins and options, as ``/v1/bvh/solve``
    takes them for one frame."""

    frame: Annotated[int, Field(ge=0), WHOLE] = Field(
        description="Index of the frame to edit (0 = first); each frame at most once."
    )


class BVHBatchRequest(_File):
    """Many frames of one BVH file edited in one call (a clip cleaned: a foot held over a
    contact, a hand on a prop); each edit solved exactly as ``/v1/bvh/solve`` solves its
    frame, the file read and written once."""

    edits: list[BVHFrameEdit] = Field(
        min_length=1, description="One per frame edited, each frame at most once; answered "
        "in this order. At most POSE_MAX_BATCH_ITEMS, and as many as the batch's work "
        "limit admits (docs/limits.md).",
    )  # fmt: skip

    @model_validator(mode="before")
    @classmethod
    def _counted(cls, data: Any, info: ValidationInfo) -> Any:
        """A clip of more edits than a batch may hold items is refused (413) before any
        edit is validated."""
        settings = (info.context or {}).get("settings")
        edits = data.get("edits") if isinstance(data, dict) else None
        if settings is not None and isinstance(edits, list):
            limit = settings.max_batch_items
            if len(edits) > limit:
                raise too_many_items("edits", len(edits), limit, "edits")
        return data


class BVHFrameAnswer(_FrameEdited, _Solved):
    """One edit's answer in a clip: what ``/v1/bvh/solve`` answers of its frame, less the
    file and how it was read (once, in the batch's answer)."""


class BVHBatchResponse(_Mapped):
    bvh: str = Field(description="The same file, only the edited frames' changed values rewritten.")
    edits: list[BVHFrameAnswer] = Field(description="In request order.")
    cut_short: BVHCutShort | None = CUT_SHORT
    rows_warning: str | None = ROWS_WARNING
