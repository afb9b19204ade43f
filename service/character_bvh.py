"""A character given as a BVH file (``/v1/bvh/solve``, ``/v1/bvh/solve/batch``,
``/v1/bvh/inspect``): the file read and checked (a 422 naming the line), the character made
of it (``service.characters``), and the answer: the same file with only the edited frames'
changed values written in (``core.bvh_write``), or what an editor needs to draw it.
Conventions: docs/characters.md, docs/bvh.md.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from itertools import islice
from typing import Any

import numpy as np

from core.bvh import BVH, BVHError, parse_bvh
from core.bvh_rows import odd_row
from core.bvh_write import pose_of, row_of, splice_frames
from core.characters import F64, CharacterError, forward_kinematics
from core.retarget import canonical_points
from core.skeleton import JOINT_INDEX, JOINT_NAMES
from core.text import clip, quoted
from service.bvh_models import (
    BVHBatchRequest,
    BVHBatchResponse,
    BVHFrameAnswer,
    BVHSolveRequest,
    _File,
)
from service.characters import (
    MAX_COORDINATE,
    Character,
    Edit,
    character_problem,
    edit_report,
    invalid_request,
    make_character,
    moves_a_target,
)
from service.errors import EMPTY_BVH, MAX_ERRORS, InvalidRequest, every_item, field_error
from service.problems import SolveProblem
from service.rigs import Rig, bvh_rig


def read_request_bvh(text: str, frames: int | Sequence[int] | None = None) -> BVH:
    """Parse and check a BVH body: every failure is a 422 naming the line and the reason.
    ``frames``: only that frame's (those frames') values are read and checked (the rest is
    kept, unread). A file of blanks alone (a byte order mark, spaces, line ends) is said
    to be empty (it was "not a BVH file (no HIERARCHY keyword)")."""
    body = text[1:] if text.startswith("\ufeff") else text
    if not body or body.isspace():
        raise InvalidRequest("bvh: " + EMPTY_BVH.format(size="blanks alone"))
    try:
        bvh = parse_bvh(text, "bvh", (frames,) if isinstance(frames, int) else frames)
    except BVHError as exc:
        raise invalid_request(exc) from None
    rows = None if bvh.read is None else np.array(sorted(bvh.read), dtype=np.intp)
    bad = ~(np.abs(bvh.motion if rows is None else bvh.motion[rows]) <= MAX_COORDINATE)  # NaN
    if bad.any():  # each frame's first bad value told (a clip's frames), the first few named
        ks = np.flatnonzero(bad.any(axis=1))
        found = [_bad_value(bvh, int(k if rows is None else rows[k]), int(np.argmax(bad[k])))
                 for k in ks[:MAX_ERRORS]]  # fmt: skip
        raise every_item(found, len(ks))
    offsets = np.array([j.offset for j in bvh.joints], dtype=np.float64)
    far = ~(np.abs(offsets) <= MAX_COORDINATE).all(axis=1)  # NaN too
    if far.any():
        j = bvh.joints[int(np.argmax(far))]
        raise InvalidRequest(
            f"bvh: OFFSET of {quoted(j.name)} is {list(j.offset)}: offsets must be finite "
            f"numbers within ±{MAX_COORDINATE:g}"
        )
    return bvh


def _bad_value(bvh: BVH, f: int, c: int) -> InvalidRequest:
    """The 422 of frame ``f``'s channel ``c``, no finite number within the bound: its line."""
    start, end = bvh.frame_span(f) or (0, 0)  # (a BVH read from text has it)
    word = next(islice(re.finditer(r"\S+", bvh.text[start:end]), c, None), None)
    line = bvh.text[: start + (word.start() if word else 0)].count("\n") + 1  # the value's
    joint = next(j for j in reversed(bvh.joints) if j.channel_start <= c and j.channels)
    channel = joint.channels[c - joint.channel_start]
    return InvalidRequest(
        f"bvh: line {line}: frame {f}, channel {clip(joint.name)}.{channel} is "
        f"{float(bvh.motion[f, c])!r}: channel values must be finite numbers within "
        f"±{MAX_COORDINATE:g}"
    )


def cut_short(bvh: BVH) -> dict[str, Any] | None:
    """The answers' ``cut_short`` (:class:`service.characters.BVHCutShort`): where the file
    ends before its declared frames are whole, else None."""
    cut = bvh.cut
    if cut is None:
        return None
    inside = f"inside frame {cut.frame} ({cut.values} of its {bvh.num_channels} values)"
    where = inside if cut.values else f"before frame {cut.frame}"
    last = cut.frames - 1
    lost = f"frame {last} is" if cut.frame == last else f"frames {cut.frame} to {last} are"
    detail = (
        f"the file is cut short: it ends on line {cut.line}, {where}, of the {cut.frames} "
        f"frames 'Frames:' declares; {lost} lost: the frames before read and edit"
    )
    return {"frame": cut.frame, "values": cut.values, "line": cut.line, "frames": cut.frames,
            "detail": detail}  # fmt: skip


def rows_warning(bvh: BVH) -> str | None:
    """The answers' ``rows_warning``: the first MOTION row the partial read left unread
    that holds other than the file's count of values, a value no number is, or one past
    ±:data:`MAX_COORDINATE` (``1e400``), the frames of a wrapped block too
    (:func:`core.bvh_rows.odd_row`; a file cut short says so in ``cut_short`` instead),
    else None. A file read whole has had every row read."""
    if bvh.read is None:
        return None
    first_line = bvh.text.count("\n", 0, bvh.motion_offset) + 1
    odd = odd_row(
        bvh.text, bvh.motion_offset, first_line, bvh.num_frames, bvh.num_channels, MAX_COORDINATE
    )
    if odd is None or (bvh.cut is not None and odd.frame >= bvh.cut.frame):
        return None
    return (
        f"bvh: line {odd.line}: frame {odd.frame} holds {odd.detail} (the first such "
        "frame): only the frames edited are read, so the answer keeps it as sent, but a "
        "reader of the whole file may refuse the file (an edit of that frame is refused)"
    )


def out_of_range(bvh: BVH, frame: int, where: str = "frame") -> InvalidRequest | None:
    """The 422 of a ``frame`` (the field ``where``) the file does not hold, else None."""
    if frame < bvh.num_frames:
        return None
    n = bvh.num_frames
    held = f"{n} frames: 0 to {n - 1}" if n > 1 else "1 frame: 0" if n else "no frames"
    return InvalidRequest(f"{where}: {clip(frame)} is out of range: the file has {held}")


def rig_of(bvh: BVH, req: _File) -> Rig:
    """The file's skeleton and joint map (:func:`service.rigs.bvh_rig`: made once for the
    files of its hierarchy)."""
    try:
        return bvh_rig(bvh, req.joint_map)
    except (CharacterError, BVHError) as exc:
        raise invalid_request(exc) from None


def character_from_bvh(bvh: BVH, req: _File, frame: int, rig: Rig | None = None) -> Character:
    """The character of the file's frame ``frame`` (``rig``: :func:`rig_of` the file, where
    it is made already: a clip's frames share it)."""
    if (far := out_of_range(bvh, frame)) is not None:
        raise far
    skel, jmap = rig_of(bvh, req) if rig is None else rig
    try:
        pose = pose_of(bvh, frame, root_add=req.root_position == "add")
        points = "joint_map" if req.joint_map else "bvh"
        return make_character(
            skel, pose, jmap, req.units, req.up, points=points, map_keys=list(req.joint_map or ())
        )
    except (CharacterError, BVHError) as exc:
        raise invalid_request(exc) from None


#: A figure whose lowest joint stands further than this from the floor (m) in the frame
#: read, where the other reading of its root channels stands it within
#: :data:`ON_FLOOR_M`, gets a ``root_warning``.
OFF_FLOOR_M, ON_FLOOR_M = 0.3, 0.1


def _lowest(ch: Character, pose: Any, g_pos: Any = None) -> float:
    """The height (m, +Y up) of ``pose``'s lowest joint over the floor the service knows
    (``g_pos``: its joints' world positions, where they are known)."""
    if g_pos is None:
        _, g_pos = forward_kinematics(ch.skel, pose)
    return float(ch.to_service(g_pos)[:, 1].min())


def root_warning(
    bvh: BVH,
    ch: Character,
    frame: int,
    root_position: str,
    g_pos: Any = None,
    done: str = "solved",
) -> str | None:
    """The answers' ``root_warning``: where the frame's figure, its root channels read as
    ``root_position`` says, stands off the floor by more than :data:`OFF_FLOOR_M` and the
    other reading stands it on the floor (within :data:`ON_FLOOR_M`): that other reading
    named, the answer ``done`` as asked ("read" on ``/v1/bvh/inspect``); else None.
    (ReActIdle's files, written as displacements from the root's OFFSET and read as
    positions, stand ~0.7 m under the floor, and a wrist dragged 1.2 m up was left 7.5 cm
    short without a word: a user's audit, 2026-12-06.) ``g_pos``: the frame's joints'
    world positions, where known."""
    fixed = _fixed_body(ch)
    if fixed is not None:  # (no position channel: either reading is the same)
        return f"root channels: {fixed}; {done} as asked"
    add = root_position == "add"
    asked = _lowest(ch, ch.pose, g_pos)
    if abs(asked) <= OFF_FLOOR_M:
        return None
    try:
        other = _lowest(ch, pose_of(bvh, frame, root_add=not add))
    except (CharacterError, BVHError, ValueError):
        return None
    if abs(other) > ON_FLOOR_M:
        return None
    side = "under" if asked < 0 else "above"
    name, reading = (
        ("replace", "the root channels as its position") if add
        else ("add", "the root channels as a displacement from its OFFSET")
    )  # fmt: skip
    return (
        f'root_position: read as "{root_position}", the frame\'s lowest joint stands '
        f'{abs(asked):.2f} m {side} the floor; read as "{name}" ({reading}) it stands '
        f"on it ({other:+.2f} m): the file may be written so; {done} as asked"
    )


def _fixed_body(ch: Character) -> str | None:
    """Why the body cannot move in its file, where no joint at or above the pelvis's has
    three position channels (``core.retarget`` moves the body through the nearest that
    has), else None: its targets are met by turns alone (a pelvis dragged 10 cm came back
    unmoved without a word, where the JSON form moves its ``root_position``: an API audit,
    2026-12-07)."""
    pelvis = ch.jmap.anchors[JOINT_INDEX["pelvis"]].joint
    j = pelvis
    while j >= 0 and not ch.skel.translatable[j]:
        j = ch.skel.parents[j]
    if j >= 0:
        return None
    return (
        f"no joint at or above the pelvis ({quoted(ch.skel.names[pelvis])}) has three "
        "position channels: the body cannot move in this file, so its targets are met by "
        "turning its joints alone"
    )


@dataclass(frozen=True)
class FrameAnswer:
    """One frame's edit as the file will hold it: its motion row, the columns rewritten
    (none: the frame as sent) and what the answer says of it."""

    frame: int
    row: F64
    columns: list[int]
    report: dict[str, Any]


def frame_answer(bvh: BVH, ch: Character, frame: int, root: str, edit: Edit) -> FrameAnswer:
    """The frame's changed values as they will be written (rounded, read back) and the
    edit measured on them (``root``: the request's ``root_position``); one bringing no
    target nearer (:func:`service.characters.moves_a_target`) is the frame as it was."""
    add = root == "add"
    row, columns = row_of(bvh, frame, edit.pose, edit.changed, root_add=add)
    points = canonical_points(ch.skel, pose_of(bvh, frame, row, root_add=add), ch.jmap)
    if not moves_a_target(ch, edit, points):  # (noise: the file's curves churn)
        row, columns = bvh.row(frame), []
        points = canonical_points(ch.skel, ch.pose, ch.jmap)  # (the frame as it is)
    report = {
        "frame": frame,
        "changed_joints": [ch.skel.names[j] for j in sorted(_written(bvh, columns))],
        **edit_report(ch, edit, points),
        "root_warning": root_warning(bvh, ch, frame, root),
    }
    return FrameAnswer(frame, row, columns, report)


def bvh_answer(bvh: BVH, ch: Character, req: BVHSolveRequest, edit: Edit) -> dict[str, Any]:
    """The file with the frame's changed values written in (:func:`frame_answer`)."""
    done = frame_answer(bvh, ch, req.frame, req.root_position, edit)
    return {
        "bvh": splice_frames(bvh, {req.frame: (done.row, done.columns)}),
        **done.report,
        "cut_short": cut_short(bvh),
        "rows_warning": rows_warning(bvh),
    }


def clip_edits(
    bvh: BVH, req: BVHBatchRequest, framed: dict[int, InvalidRequest] | None = None
) -> list[tuple[Character, SolveProblem]]:
    """Each edit's character and canonical problem, made as ``/v1/bvh/solve`` makes its
    frame's (so each is solved to the same bits). Every edit's own errors are told, as a
    batch's items' are (a frame edited twice, one the file does not hold, targets and
    pins, a frame that cannot be read as asked); an error every edit's frame gives alike
    (the file's units, say) once, in the words of ``/v1/bvh/solve``. ``up`` is the
    file's: where it is left to the service and the rest pose stands along neither axis,
    frames that stand up along different ones are refused (state it). ``framed``:
    :func:`clip_frames` of the clip, where found already."""
    rig = rig_of(bvh, req)
    framed = clip_frames(bvh, req) if framed is None else framed
    found: list[tuple[str, InvalidRequest]] = []  # (a frame not read as asked: its edit)
    out: list[tuple[Character, SolveProblem]] = []
    for i, e in enumerate(req.edits):
        where = f"edits[{i}]"
        if i in framed:
            found.append(("", framed[i]))
            continue
        try:
            ch = character_from_bvh(bvh, req, e.frame, rig)
        except InvalidRequest as exc:
            found.append((f"{where} (frame {e.frame})", exc))
            continue
        try:
            out.append((ch, character_problem(ch, e, where)))
        except InvalidRequest as exc:
            found.append(("", exc))
    unread = [exc for at, exc in found if at]
    if unread and not out and len({exc.detail for exc in unread}) == 1:
        raise unread[0]  # (every frame alike: the file's own error, told once)
    if found:  # (a frame not read as asked named: its edit and frame, at its field)
        raise every_item([_named(at, exc) if at else exc for at, exc in found])
    ups = _first_read(out, lambda ch: ch.up_name)
    if len(ups) > 1:  # (given, up is one; inferred from the rest pose, one too)
        said = ", ".join(f"{up} (edits[{i}], frame {req.edits[i].frame})" for up, i in ups.items())
        raise InvalidRequest(
            f"up: not given, and the rest pose stands up along neither +Y nor +Z: the frames "
            f"edited stand up along different axes, {said}; state it, e.g. "
            f'"up": "{next(iter(ups))}"'
        )
    sides = _first_read(out, lambda ch: ch.jmap.anchors[JOINT_INDEX["left_hip"]].label)
    if len(sides) > 1:  # (a rest pose that says which side is which decides every frame)
        said = ", ".join(f"edits[{i}] (frame {req.edits[i].frame}) with {quoted(hip)} as the "
                         "left hip" for hip, i in sides.items())  # fmt: skip
        raise InvalidRequest(
            f"joint_map: the rest pose says nothing of which side is which, and the frames "
            f"edited read it differently, {said}; give joint_map its left_ and right_ entries"
        )
    return out


def _first_read(
    out: list[tuple[Character, SolveProblem]], read: Callable[[Character], str]
) -> dict[str, int]:
    """Each way the clip's frames are read (``read``: their up axis, their left hip), with
    the first edit read so: one clip is read one way (its answer names it once)."""
    first: dict[str, int] = {}
    for i, (ch, _) in enumerate(out):
        first.setdefault(read(ch), i)
    return first


def clip_frames(bvh: BVH, req: BVHBatchRequest) -> dict[int, InvalidRequest]:
    """The edits whose ``frame`` is refused (edited by an edit before, or not in the file),
    each with its 422: found before the clip is priced (they cost nothing to tell)."""
    seen: dict[int, int] = {}
    out: dict[int, InvalidRequest] = {}
    for i, e in enumerate(req.edits):
        where = f"edits[{i}].frame"
        if e.frame in seen:
            out[i] = InvalidRequest(
                f"{where}: frame {e.frame} is edited by edits[{seen[e.frame]}] too: each "
                "frame at most once"
            )
        elif (far := out_of_range(bvh, e.frame, where)) is not None:
            out[i] = far
        else:
            seen[e.frame] = i
    return out


def _named(at: str, exc: InvalidRequest) -> InvalidRequest:
    """``exc`` (a frame not read as asked) told as ``at``'s: its edit and frame before its
    message, at the field its message names (``up``, ``units``)."""
    own = field_error(exc)
    return InvalidRequest(
        f"{at}: {exc.detail}",
        errors=[{"location": own["location"], "message": f"{at}: {own['message']}"}],
    )


def clip_answer(bvh: BVH, done: list[FrameAnswer]) -> dict[str, Any]:
    """``/v1/bvh/solve/batch``'s answer: the file with every edited frame's changed values
    written in, one pass; each edit's report, and how the file was read, once."""
    solved = set(BVHFrameAnswer.model_fields)
    first = done[0].report
    return {
        "bvh": splice_frames(bvh, {d.frame: (d.row, d.columns) for d in done}),
        "edits": [{k: v for k, v in d.report.items() if k in solved} for d in done],
        **{k: first[k] for k in BVHBatchResponse.model_fields if k in first},
        "cut_short": cut_short(bvh),
        "rows_warning": rows_warning(bvh),
    }


def _written(bvh: BVH, columns: list[int]) -> set[int]:
    """The joints of ``bvh`` one of whose channel ``columns`` the answer rewrites."""
    cols = set(columns)
    return {
        i for i, j in enumerate(bvh.joints)
        if cols.intersection(range(j.channel_start, j.channel_start + len(j.channels)))
    }  # fmt: skip


def bvh_inspect(
    bvh: BVH, ch: Character, frame: int, root_position: str = "replace"
) -> dict[str, Any]:
    """What an editor needs to draw and pose the file: its joints and channels, where the 21
    canonical joints sit on them, units and axes, and one frame's world positions."""
    g_rot, g_pos = forward_kinematics(ch.skel, ch.pose)
    points = ch.jmap.points(g_rot, g_pos)
    names = ch.skel.names
    return {
        "joints": [
            {
                "name": j.name,
                "parent": j.parent,
                "offset": list(j.offset),
                "channels": list(j.channels),
                "channel_start": j.channel_start,
                "end_site": j.end_site,
            }
            for j in bvh.joints
        ],
        "anchors": {
            c: {"joint": names[a.joint], "offset": a.offset.tolist(), "label": a.label}
            for c, a in zip(JOINT_NAMES, ch.jmap.anchors, strict=True)
        },
        "joint_map": ch.jmap.describe(),
        "scheme": ch.jmap.scheme,
        "units": ch.units,
        "metres_per_unit": ch.scale,
        "up": ch.up_name,
        "frames": bvh.num_frames,
        "frame_time": bvh.frame_time,
        "frame": frame,
        "positions": g_pos.tolist(),
        "points": dict(zip(JOINT_NAMES, points.tolist(), strict=True)),
        "cut_short": cut_short(bvh),
        "rows_warning": rows_warning(bvh),
        "units_warning": ch.units_warning("read"),
        "up_warning": ch.up_warning,
        "sides_warning": ch.sides_warning,
        "root_warning": root_warning(bvh, ch, frame, root_position, g_pos, "read"),
    }
