"""BVH writer: a whole file from a parsed :class:`core.bvh.BVH`, or edited frames spliced in.

- :func:`format_bvh` writes the hierarchy (same joints, offsets, channel names and order,
  End Sites) and the motion, numbers in Python's shortest round-trip form, so that
  ``parse_bvh(format_bvh(b))`` has the same hierarchy, offsets, frame time and motion.
- :func:`splice_frames` keeps the file's own text and rewrites
  only the changed values of the frames edited, where they stand (a frame's line, or its
  values over several lines where the file wraps its frames: every other byte of the file
  is unchanged); values are written with
  :data:`DECIMALS` decimals, and :func:`row_of` says which changed: a value within
  :data:`KEPT` of its old one keeps its text.
- :func:`skeleton_of`, :func:`pose_of` and :func:`row_of` bridge a BVH frame to a
  :class:`core.characters.Skeleton` / :class:`core.characters.Pose` and back: a joint is
  *rotatable* if it has exactly three rotation channels, *translatable* if it has all three
  position channels, each axis once; Euler angles written back are the solution nearest the
  old angles (same rotation, angles shifted by whole turns or the other branch), so curves
  stay smooth; a joint at gimbal lock turned by less than :data:`STILL_TURN` keeps its
  old angles (:func:`_locked`).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core.bvh import BVH, BVHError, BVHJoint
from core.characters import F64, Pose, Skeleton, build_skeleton
from core.euler import euler_angles, euler_matrices, invertible_order

DECIMALS = 6
#: how far a channel's new value may lie from its old one for the old to be kept (text
#: and all): half a unit of the last decimal written, the rounding's own error
KEPT = 0.5 * 10.0**-DECIMALS
_POS = {"xposition": 0, "yposition": 1, "zposition": 2}
#: degrees: a joint turned by less than this whose nearest angles change by more than
#: :data:`LOCKED` (a joint at gimbal lock: its middle angle near ±90, where a turn of
#: 0.002 degrees moved the outer two by 84) keeps its angles as they were; the answer is
#: measured on the file as written (``service.character_bvh.frame_answer``), and such a
#: turn moves a point 1 m away by 0.09 mm at most
STILL_TURN = 0.005
LOCKED = 1.0
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


def splice_frames(bvh: BVH, edits: Mapping[int, tuple[F64, list[int]]]) -> str:
    """The file's text with, for each ``frame: (row, columns)`` of ``edits``, ``columns``
    of that frame set from ``row`` (whole motion row); every other byte is kept: each
    frame's values are found where they stand (:meth:`core.bvh.BVH.frame_spans`: its line,
    or its values across lines where the file wraps its frames, all in one pass), and only
    those of its ``columns`` are written anew; a file of CR line ends comes back with them
    (``BVH.cr_only``). A BVH not read from text (none to keep) is written whole by
    :func:`format_bvh`."""
    for frame in edits:
        if not 0 <= frame < bvh.num_frames:
            raise IndexError(f"frame {frame} out of range: the file has {bvh.num_frames} frames")
    frames = sorted(f for f, (_, columns) in edits.items() if columns)
    spans = bvh.frame_spans(frames)
    if spans is None:  # (a file read for some frames has their spans: it is read from text)
        bvh.whole()
        motion = bvh.motion.copy()
        for frame, (row, _) in edits.items():
            motion[frame] = row
        return format_bvh(bvh, motion)
    parts: list[str] = []
    last = 0
    for frame in frames:
        start, end = spans[frame]
        row, columns = edits[frame]
        parts.append(bvh.text[last:start])
        parts.append(_spliced(bvh, frame, bvh.text[start:end], row, set(columns)))
        last = end
    parts.append(bvh.text[last:])
    out = "".join(parts)
    return out.replace("\n", "\r") if bvh.cr_only else out  # (its own line ends)


def _spliced(bvh: BVH, frame: int, text: str, row: F64, wanted: set[int]) -> str:
    """``text``, frame ``frame``'s values, with those numbered ``wanted`` set from ``row``."""
    tokens = list(_WORD_RE.finditer(text))
    if len(tokens) != bvh.num_channels:  # pragma: no cover - the reader found them so
        raise ValueError(
            f"{bvh.name}: frame {frame} holds {len(tokens)} values, not {bvh.num_channels}"
        )
    parts: list[str] = []
    last = 0
    for k, m in enumerate(tokens):
        parts.append(text[last : m.start()])
        parts.append(f"{row[k]:.{DECIMALS}f}" if k in wanted else m.group())
        last = m.end()
    parts.append(text[last:])
    return "".join(parts)


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


@dataclass(frozen=True)
class _Layout:
    """Where a file's channels go (worked out once per file, :func:`_layout`): the rotation
    columns ``[m, 3]`` of the joints of each Euler order, and each position channel's
    joint, axis and column (the last of a joint's channels on one axis: it is the one read)."""

    orders: dict[str, tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]]
    offsets: F64
    pos: npt.NDArray[np.intp]  # [P, 3]: joint, axis, column
    root: npt.NDArray[np.bool_]  # [P]: a root's channel (``root_add`` shifts it)


def _layout(bvh: BVH) -> _Layout:
    found = bvh.memo.get("layout")
    if isinstance(found, _Layout):
        return found
    orders: dict[str, tuple[list[int], list[list[int]]]] = {}
    pos: dict[tuple[int, int], int] = {}
    for i, j in enumerate(bvh.joints):
        if seq := j.rotation_order:
            cols = [j.channel_start + k for k, c in enumerate(j.channels) if c.lower() in _ROT]
            joints, columns = orders.setdefault(seq, ([], []))
            joints.append(i)
            columns.append(cols)
        for k, c in enumerate(j.channels):
            if c.lower() in _POS:
                pos[(i, _POS[c.lower()])] = j.channel_start + k
    table = np.array([(i, a, c) for (i, a), c in pos.items()], dtype=np.intp).reshape(-1, 3)
    out = _Layout(
        {seq: (np.array(js, dtype=np.intp), np.array(cs, dtype=np.intp))
         for seq, (js, cs) in orders.items()},
        np.array([j.offset for j in bvh.joints], dtype=np.float64),
        table,
        np.array([bvh.joints[i].parent < 0 for i in table[:, 0]], dtype=bool),
    )  # fmt: skip
    for a in (out.offsets, out.pos, out.root, *(x for pair in out.orders.values() for x in pair)):
        a.setflags(write=False)  # (shared by the files of one hierarchy: ``BVH.memo``)
    bvh.memo["layout"] = out
    return out


def pose_of(bvh: BVH, frame: int, row: F64 | None = None, *, root_add: bool = False) -> Pose:
    """Local rotations and translations of one frame (of ``row`` instead, when given).
    ``root_add``: a root's position channels are a displacement from its OFFSET (some
    exporters, ReActIdle's), not its position (the BVH convention)."""
    row = bvh.row(frame) if row is None else row
    lay = _layout(bvh)
    rot = np.broadcast_to(np.eye(3), (len(bvh.joints), 3, 3)).copy()
    trans = lay.offsets.copy()
    joint, axis, col = lay.pos.T
    shift = np.where(lay.root, lay.offsets[joint, axis], 0.0) if root_add else 0.0
    trans[joint, axis] = row[col] + shift
    for seq, (joints, columns) in lay.orders.items():
        rot[joints] = euler_matrices(seq, np.deg2rad(row[columns]))
    return Pose(rot, trans)


def _nearest_euler(seq: str, matrix: F64, old: F64) -> F64:
    """Euler angles (degrees, intrinsic ``seq``) of ``matrix [..., 3, 3]`` nearest to
    ``old [..., 3]``, joint by joint (one product for all): each of the two
    solutions turned by whole turns towards the old angles and checked to give the matrix
    back (to 1e-5 of each entry, plus 1e-9), the one whose largest change is least kept (the
    first on a tie; the first where neither checks)."""
    first = np.rad2deg(euler_angles(seq, matrix))
    a, b, c = first[..., 0], first[..., 1], first[..., 2]
    proper = seq[0] == seq[2]
    other = np.stack([a + 180.0, -b if proper else 180.0 - b, c + 180.0], axis=-1)
    both = np.stack([first, other], axis=-2)  # [..., 2, 3]
    cands = old[..., None, :] + (both - old[..., None, :] + 180.0) % 360.0 - 180.0  # turns
    backs = euler_matrices(seq, np.deg2rad(cands))  # [..., 2, 3, 3], all in one product
    want = matrix[..., None, :, :]
    ok: npt.NDArray[np.bool_] = np.asarray(
        (np.abs(backs - want) <= 1e-9 + 1e-5 * np.abs(want)).all(axis=(-2, -1))
    )  # (np.allclose's test, its absolute tolerance 1e-9)
    cost = np.where(ok, np.abs(cands - old[..., None, :]).max(axis=-1), np.inf)
    second = np.asarray(ok[..., 1] & (cost[..., 1] < cost[..., 0]))
    best = np.where(second[..., None], cands[..., 1, :], cands[..., 0, :])
    some: npt.NDArray[np.bool_] = np.asarray(ok.any(axis=-1))  # (neither checks: the first)
    return np.asarray(np.where(some[..., None], best, first), dtype=np.float64)


def _locked(seq: str, matrix: F64, old: F64, angles: F64) -> npt.NDArray[np.bool_]:
    """``[J]``: the joints whose rotation ``matrix`` turns less than :data:`STILL_TURN`
    from their ``old`` angles while its nearest ``angles`` move more than :data:`LOCKED`
    (gimbal lock: the outer angles are ill-determined)."""
    # (the turn's angle from the chord: |R - R0| = 2 sqrt(2) sin(angle / 2))
    chord = np.linalg.norm(matrix - euler_matrices(seq, np.deg2rad(old)), axis=(-2, -1))
    turn = np.rad2deg(2.0 * np.arcsin(np.minimum(chord / (2.0 * np.sqrt(2.0)), 1.0)))
    return np.asarray((turn < STILL_TURN) & (np.abs(angles - old).max(axis=-1) > LOCKED))


def _writable(
    bvh: BVH,
) -> tuple[tuple[tuple[str, tuple[int, ...]] | None, ...], tuple[tuple[tuple[int, int], ...], ...]]:
    """Per joint, what :func:`row_of` may write (worked out once per hierarchy,
    ``BVH.memo``): its Euler order and rotation columns where it has three rotation
    channels whose angles can be written back (else None: never turned), and its position
    channels' (column, axis) where they are the three axes, each once (else none: an axis
    twice was written the last one's value)."""
    found = bvh.memo.get("writable")
    if isinstance(found, tuple):
        return found
    rot_of: list[tuple[str, tuple[int, ...]] | None] = []
    pos_of: list[tuple[tuple[int, int], ...]] = []
    for j in bvh.joints:
        cols = tuple(j.channel_start + k for k, c in enumerate(j.channels) if c.lower() in _ROT)
        seq = j.rotation_order
        rot_of.append((seq, cols) if len(cols) == 3 and invertible_order(seq) else None)
        moves = _position_axes(j) == [0, 1, 2]
        pos_of.append(
            tuple(
                (j.channel_start + k, _POS[c.lower()])
                for k, c in enumerate(j.channels)
                if c.lower() in _POS and moves
            )
        )
    out = (tuple(rot_of), tuple(pos_of))
    bvh.memo["writable"] = out
    return out


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
    turned: dict[str, tuple[list[int], list[tuple[int, ...]]]] = {}  # order -> joints, columns
    rot_of, pos_of = _writable(bvh)
    for i in sorted(joints):
        if (found := rot_of[i]) is not None:  # else never turned
            ids, cols = turned.setdefault(found[0], ([], []))
            ids.append(i)
            cols.append(found[1])
        for col, axis in pos_of[i]:
            shift = _root_shift(bvh.joints[i], axis, root_add)
            new[col] = float(pose.translations[i, axis]) - shift
    for seq, (ids, cols) in turned.items():  # (one product per order, as pose_of reads)
        old = row[np.array(cols)]
        angles = _nearest_euler(seq, pose.rotations[ids], old)
        angles = np.where(_locked(seq, pose.rotations[ids], old, angles)[:, None], old, angles)
        new.update(zip(np.ravel(cols).tolist(), angles.ravel().tolist(), strict=True))
    columns = sorted(col for col, value in new.items() if not abs(value - row[col]) <= KEPT)
    for col in columns:  # the values as they will be read back
        row[col] = float(f"{new[col]:.{DECIMALS}f}")
    return row, columns
