"""BVH writer: a whole file from a parsed :class:`core.bvh.BVH`, or one frame spliced in.

- :func:`format_bvh` writes the hierarchy (same joints, offsets, channel names and order,
  End Sites) and the motion, numbers in Python's shortest round-trip form, so that
  ``parse_bvh(format_bvh(b))`` has the same hierarchy, offsets, frame time and motion.
- :func:`splice_frame` keeps the file's own text and rewrites only the changed values of one
  frame, where they stand (its line, or its values over several lines where the file wraps
  its frames: every other byte of the file is unchanged); values are written with
  :data:`DECIMALS` decimals, and :func:`row_of` says which changed: a value within
  :data:`KEPT` of its old one keeps its text.
- :func:`skeleton_of`, :func:`pose_of` and :func:`row_of` bridge a BVH frame to a
  :class:`core.characters.Skeleton` / :class:`core.characters.Pose` and back: a joint is
  *rotatable* if it has exactly three rotation channels, *translatable* if it has all three
  position channels, each axis once; Euler angles written back are the solution nearest the
  old angles (same rotation, angles shifted by whole turns or the other branch), so curves
  stay smooth.
"""

from __future__ import annotations

import re

import numpy as np

from core.bvh import BVH, BVHError, BVHJoint
from core.characters import F64, Pose, Skeleton, build_skeleton
from core.euler import euler_angles, euler_matrices, invertible_order

DECIMALS = 6
#: how far a channel's new value may lie from its old one for the old to be kept (text
#: and all): half a unit of the last decimal written, the rounding's own error
KEPT = 0.5 * 10.0**-DECIMALS
_POS = {"xposition": 0, "yposition": 1, "zposition": 2}
_ROT = {"xrotation", "yrotation", "zrotation"}
_WORD_RE = re.compile(r"\S+")


def _num(v: float) -> str:
    return repr(float(v))


def format_bvh(bvh: BVH, motion: F64 | None = None) -> str:
    """The whole file as text (``motion`` replaces the BVH's own rows when given)."""
    if motion is None:
        bvh.whole()  # (a file read for one frame has NaN rows)
    rows = bvh.motion if motion is None else motion
    kids: dict[int, list[int]] = {}
    for i, j in enumerate(bvh.joints):
        kids.setdefault(j.parent, []).append(i)
    out = ["HIERARCHY"]
    for root in kids.get(-1, []):
        _emit(bvh, kids, out, root, 0)
    out += ["MOTION", f"Frames: {len(rows)}", f"Frame Time: {_num(bvh.frame_time)}"]
    out += [" ".join(_num(v) for v in row) for row in rows]
    return "\n".join(out) + "\n"


def _emit(bvh: BVH, kids: dict[int, list[int]], out: list[str], i: int, depth: int) -> None:
    """Joint ``i``'s block, its children's within, onto ``out``. A module function: a nested
    one that calls itself is in its own closure, a reference cycle that kept each file's
    lines until a full collection (as the reader's did: an audit, 2026-12-06)."""
    j = bvh.joints[i]
    pad = "\t" * depth
    offset = " ".join(_num(v) for v in j.offset)
    if j.end_site:
        out.extend([f"{pad}End Site", f"{pad}{{", f"{pad}\tOFFSET {offset}", f"{pad}}}"])
        return
    out.append(f"{pad}{'ROOT' if j.parent < 0 else 'JOINT'} {j.name}")
    out.append(f"{pad}{{")
    out.append(f"{pad}\tOFFSET {offset}")
    out.append(f"{pad}\tCHANNELS {len(j.channels)} {' '.join(j.channels)}".rstrip())
    for k in kids.get(i, []):
        _emit(bvh, kids, out, k, depth + 1)
    out.append(f"{pad}}}")


def splice_frame(bvh: BVH, frame: int, row: F64, columns: list[int]) -> str:
    """The file's text with ``columns`` of frame ``frame`` set from ``row`` (whole motion
    row); every other byte is kept: the frame's values are found where they stand
    (:meth:`core.bvh.BVH.frame_span`: its line, or its values across lines where the file
    wraps its frames), and only those of ``columns`` are written anew; a file of CR line
    ends comes back with them (``BVH.cr_only``). A BVH not read
    from text (none to keep) is written whole by :func:`format_bvh`."""
    if not 0 <= frame < bvh.num_frames:
        raise IndexError(f"frame {frame} out of range: the file has {bvh.num_frames} frames")
    span = bvh.frame_span(frame)
    if span is None:  # (a file read for one frame has its span: it is one read from text)
        bvh.whole()
        motion = bvh.motion.copy()
        motion[frame] = row
        return format_bvh(bvh, motion)
    start, end = span
    line = bvh.text[start:end]
    tokens = list(_WORD_RE.finditer(line))
    if len(tokens) != bvh.num_channels:  # pragma: no cover - the reader found them so
        raise ValueError(
            f"{bvh.name}: frame {frame} holds {len(tokens)} values, not {bvh.num_channels}"
        )
    parts: list[str] = []
    last = 0
    wanted = set(columns)
    for k, m in enumerate(tokens):
        parts.append(line[last : m.start()])
        parts.append(f"{row[k]:.{DECIMALS}f}" if k in wanted else m.group())
        last = m.end()
    parts.append(line[last:])
    out = bvh.text[:start] + "".join(parts) + bvh.text[end:]
    return out.replace("\n", "\r") if bvh.cr_only else out  # (its own line ends)


def skeleton_of(bvh: BVH) -> Skeleton:
    """The BVH hierarchy as a :class:`Skeleton` (same joint order: the file's). A joint
    the solve may turn has three rotation channels whose angles can be written back
    (:func:`core.euler.invertible_order`); the others keep theirs."""
    skel, order = build_skeleton(
        [j.name for j in bvh.joints],
        [None if j.parent < 0 else bvh.joints[j.parent].name for j in bvh.joints],
        [j.offset for j in bvh.joints],
        rotatable=[invertible_order(j.rotation_order) for j in bvh.joints],
        translatable=[_position_axes(j) == [0, 1, 2] for j in bvh.joints],
        where=bvh.name,
    )
    if order != list(range(len(bvh.joints))):  # pragma: no cover - the reader keeps file order
        raise BVHError(bvh.name, "joints are not in parents-first order")
    return skel


def _position_axes(joint: BVHJoint) -> list[int]:
    """The axes of ``joint``'s position channels, sorted: a joint moves (is *translatable*)
    and its position channels are written only where they are the three, each once
    (``Xposition Yposition Yposition`` cannot write a move along Z: such a joint was taken
    to move the pelvis, the move lost, and its first ``Yposition`` written the second's
    value)."""
    return sorted(_POS[c.lower()] for c in joint.channels if c.lower() in _POS)


def _root_shift(joint: BVHJoint, axis: int, root_add: bool) -> float:
    """What a position channel of ``joint`` on ``axis`` is read with and written without:
    a root's OFFSET there where its channels are a displacement (``root_add``), else 0."""
    return joint.offset[axis] if root_add and joint.parent < 0 else 0.0


def pose_of(bvh: BVH, frame: int, row: F64 | None = None, *, root_add: bool = False) -> Pose:
    """Local rotations and translations of one frame (of ``row`` instead, when given).
    ``root_add``: a root's position channels are a displacement from its OFFSET (some
    exporters, ReActIdle's), not its position (the BVH convention)."""
    row = bvh.row(frame) if row is None else row
    n = len(bvh.joints)
    rot = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    trans = np.array([j.offset for j in bvh.joints], dtype=np.float64)
    orders: dict[str, tuple[list[int], list[list[int]]]] = {}  # one product per order
    for i, j in enumerate(bvh.joints):
        seq = j.rotation_order
        if seq:
            cols = [j.channel_start + k for k, c in enumerate(j.channels) if c.lower() in _ROT]
            joints, columns = orders.setdefault(seq, ([], []))
            joints.append(i)
            columns.append(cols)
        for k, c in enumerate(j.channels):
            if c.lower() in _POS:
                axis = _POS[c.lower()]
                trans[i, axis] = row[j.channel_start + k] + _root_shift(j, axis, root_add)
    for seq, (joints, columns) in orders.items():
        rot[joints] = euler_matrices(seq, np.deg2rad(row[np.array(columns)]))
    return Pose(rot, trans)


def _nearest_euler(seq: str, matrix: F64, old: F64) -> F64:
    """Euler angles (degrees, intrinsic ``seq``) of ``matrix`` nearest to ``old``."""
    first = np.rad2deg(euler_angles(seq, matrix))
    a, b, c = first
    proper = seq[0] == seq[2]
    other = np.array([a + 180.0, -b if proper else 180.0 - b, c + 180.0])
    best, best_cost = first, np.inf
    cands = old + (np.stack([first, other]) - old + 180.0) % 360.0 - 180.0  # turns to old
    backs = euler_matrices(seq, np.deg2rad(cands))  # both checked in one product
    for cand, back in zip(cands, backs, strict=True):
        if not (np.abs(back - matrix) <= 1e-9 + 1e-5 * np.abs(matrix)).all():  # np.allclose
            continue
        cost = float(np.abs(cand - old).max())
        if cost < best_cost:
            best, best_cost = cand, cost
    return np.asarray(best, dtype=np.float64)


def row_of(
    bvh: BVH, frame: int, pose: Pose, joints: set[int] | frozenset[int], *, root_add: bool = False
) -> tuple[F64, list[int]]:
    """The motion row of ``pose`` for the changed ``joints`` (others keep their values), and
    the columns that changed, as they will be written (rounded to :data:`DECIMALS`);
    ``root_add`` as :func:`pose_of` reads it. A channel whose old value lies within half
    a unit of the written precision (:data:`KEPT`) of its new one keeps its value and its
    text: it already says the new value as well as the rewritten one would (so a value
    that moved by nothing, ``-9.35e-15`` against ``0``, is not written ``-0.000000``:
    compared after rounding the new one alone, it always changed)."""
    row = bvh.row(frame).copy()
    new: dict[int, float] = {}
    for i in sorted(joints):
        j = bvh.joints[i]
        rot_cols = [j.channel_start + k for k, c in enumerate(j.channels) if c.lower() in _ROT]
        if len(rot_cols) == 3 and invertible_order(j.rotation_order):  # else never turned
            angles = _nearest_euler(j.rotation_order, pose.rotations[i], row[rot_cols])
            new.update(zip(rot_cols, angles.tolist(), strict=True))
        moves = _position_axes(j) == [0, 1, 2]  # (else its position channels are kept:
        for k, c in enumerate(j.channels):  # an axis twice was written the last one's value)
            if c.lower() in _POS and moves:
                axis = _POS[c.lower()]
                value = float(pose.translations[i, axis]) - _root_shift(j, axis, root_add)
                new[j.channel_start + k] = value
    columns = sorted(col for col, value in new.items() if not abs(value - row[col]) <= KEPT)
    for col in columns:  # the values as they will be read back
        row[col] = float(f"{new[col]:.{DECIMALS}f}")
    return row, columns
