"""A character given as a BVH file (``/v1/bvh/solve``, ``/v1/bvh/inspect``): the file read
and checked (a 422 naming the line), the character made of it (``service.characters``),
and the answer: the same file with only that frame's changed values written in
(``core.bvh_write``), or what an editor needs to draw it. Conventions: docs/characters.md.
"""

from __future__ import annotations

import re
from itertools import islice
from typing import Any

import numpy as np

from core.bvh import BVH, BVHError, parse_bvh
from core.bvh_write import pose_of, row_of, skeleton_of, splice_frame
from core.characters import CharacterError, forward_kinematics
from core.characters_maps import resolve_map
from core.retarget import canonical_points
from core.skeleton import JOINT_NAMES
from core.text import clip, quoted
from service.characters import (
    MAX_COORDINATE,
    BVHInspectRequest,
    BVHSolveRequest,
    Character,
    Edit,
    edit_report,
    invalid_request,
    make_character,
    moves_a_target,
)
from service.errors import InvalidRequest


def read_request_bvh(text: str, frame: int | None = None) -> BVH:
    """Parse and check a BVH body: every failure is a 422 naming the line and the reason.
    ``frame``: only that frame's values are read and checked (the rest is kept, unread)."""
    try:
        bvh = parse_bvh(text, "bvh", None if frame is None else (frame,))
    except BVHError as exc:
        raise invalid_request(exc) from None
    rows = None if bvh.read is None else np.array(sorted(bvh.read), dtype=np.intp)
    bad = ~(np.abs(bvh.motion if rows is None else bvh.motion[rows]) <= MAX_COORDINATE)  # NaN
    if bad.any():
        k, c = (int(v) for v in np.argwhere(bad)[0])
        f = k if rows is None else int(rows[k])
        start, end = bvh.frame_span(f) or (0, 0)  # (a BVH read from text has it)
        word = next(islice(re.finditer(r"\S+", bvh.text[start:end]), c, None), None)
        line = bvh.text[: start + (word.start() if word else 0)].count("\n") + 1  # the value's
        joint = next(j for j in reversed(bvh.joints) if j.channel_start <= c and j.channels)
        channel = joint.channels[c - joint.channel_start]
        raise InvalidRequest(
            f"bvh: line {line}: frame {f}, channel {clip(joint.name)}.{channel} is "
            f"{float(bvh.motion[f, c])!r}: channel values must be finite numbers within "
            f"±{MAX_COORDINATE:g}"
        )
    offsets = np.array([j.offset for j in bvh.joints], dtype=np.float64)
    far = ~(np.abs(offsets) <= MAX_COORDINATE).all(axis=1)  # NaN too
    if far.any():
        j = bvh.joints[int(np.argmax(far))]
        raise InvalidRequest(
            f"bvh: OFFSET of {quoted(j.name)} is {list(j.offset)}: offsets must be finite "
            f"numbers within ±{MAX_COORDINATE:g}"
        )
    return bvh


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


def character_from_bvh(bvh: BVH, req: BVHSolveRequest | BVHInspectRequest) -> Character:
    if req.frame >= bvh.num_frames:
        n = bvh.num_frames
        held = f"{n} frames: 0 to {n - 1}" if n > 1 else "1 frame: 0" if n else "no frames"
        raise InvalidRequest(f"frame: {clip(req.frame)} is out of range: the file has {held}")
    try:
        skel = skeleton_of(bvh)
        pose = pose_of(bvh, req.frame, root_add=req.root_position == "add")
        jmap = resolve_map(skel, req.joint_map, offset_at=lambda _: "bvh")
        points = "joint_map" if req.joint_map else "bvh"
        return make_character(skel, pose, jmap, req.units, req.up, points=points)
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
    bvh: BVH, ch: Character, frame: int, root_position: str, g_pos: Any = None
) -> str | None:
    """The answers' ``root_warning``: where the frame's figure, its root channels read as
    ``root_position`` says, stands off the floor by more than :data:`OFF_FLOOR_M` and the
    other reading stands it on the floor (within :data:`ON_FLOOR_M`): that other reading
    named, the answer solved as asked; else None. (ReActIdle's files, written as
    displacements from the root's OFFSET and read as positions, stand ~0.7 m under the
    floor, and a wrist dragged 1.2 m up was left 7.5 cm short without a word: a user's
    audit, 2026-12-06.) ``g_pos``: the frame's joints' world positions, where known."""
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
        f"on it ({other:+.2f} m): the file may be written so; solved as asked"
    )


def bvh_answer(bvh: BVH, ch: Character, req: BVHSolveRequest, edit: Edit) -> dict[str, Any]:
    """The file with the frame's changed values written in, measured as written (rounded, read
    back); one bringing no target nearer (:func:`service.characters.moves_a_target`) is the
    frame as it was."""
    add = req.root_position == "add"
    row, columns = row_of(bvh, req.frame, edit.pose, edit.changed, root_add=add)
    points = canonical_points(ch.skel, pose_of(bvh, req.frame, row, root_add=add), ch.jmap)
    if not moves_a_target(ch, edit, points):  # (noise: the file's curves churn)
        row, columns = bvh.row(req.frame), []
        points = canonical_points(ch.skel, ch.pose, ch.jmap)  # (the frame as it is)
    return {
        "bvh": splice_frame(bvh, req.frame, row, columns),
        "frame": req.frame,
        "changed_joints": [ch.skel.names[j] for j in sorted(_written(bvh, columns))],
        **edit_report(ch, edit, points),
        "cut_short": cut_short(bvh),
        "root_warning": root_warning(bvh, ch, req.frame, req.root_position),
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
        "units_warning": ch.units_warning,
        "root_warning": root_warning(bvh, ch, frame, root_position, g_pos),
    }
