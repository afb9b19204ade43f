"""BVH reader and batched forward kinematics (numpy only: the service reads BVH too).

Conventions implemented here:

- Any rotation channel order, on any joint (at most :data:`MAX_JOINT_CHANNELS` channels
  on one, :data:`MAX_JOINTS` joints in all). BVH Euler channels are *intrinsic* rotations
  applied in the listed order, ``R = R_c1 @ R_c2 @ R_c3`` (degrees); e.g. ``Zrotation
  Xrotation Yrotation`` gives ``Rz @ Rx @ Ry``. Any number of rotation channels works
  (within that bound).
- Position channels, on any joint (6-channel joints: Bandai-Namco, ReActIdle), *replace*
  the matching component of the joint's OFFSET. Offsets are never added to them.
- ``End Site`` blocks become pseudo-joints named ``<parent>_end`` (``_end2``... if a joint
  has several), addressable by joint maps like any other joint. A name a real joint of the
  file has stays the joint's: its End Site takes the next free ``_endK``.
- Nothing of the file is lost, so a writer can round-trip it: every joint keeps its
  channel names in file order (:attr:`BVHJoint.channels`) and first MOTION column
  (:attr:`BVHJoint.channel_start`); :attr:`BVH.motion` holds the raw channel values, one
  row per frame; :attr:`BVH.text` is the file's text and :meth:`BVH.frame_lines` its
  frame lines, unchanged.
- Numbers are ASCII decimals as writers write them (``-1.5``, ``2e-3``): not ``1_000``,
  other scripts' digits or ``nan``/``inf``, which Python's ``float()`` reads.
- The MOTION block is parsed in one go by numpy (``np.fromstring``, no Python object per
  value); where numpy does not read every word, or reads one not finite, one regex checks
  them all numbers (then ``str.split`` + ``float``), and errors are found line by line.
- ``parse_bvh(text, frames=[k])`` reads the values of those frames only (the service
  edits one frame of a file: a 3.6 MB file's block takes ~90 ms to read whole on this
  host, its frame line ~5 ms to find by counting newlines); the other rows are NaN and
  :meth:`BVH.row` refuses them (:attr:`BVH.read` says which were read). A block whose
  frames are wrapped over lines, or has blank lines among them, has its words counted
  instead (numpy, a chunk at a time: ~15 ms for 7.5 MB), and a frame's values are its
  words from the ``k * C``-th; :meth:`BVH.frame_span` is where a writer finds them.

Malformed input raises :class:`BVHError`, which names the file and the reason (with the line
number where there is one).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache
from itertools import islice
from pathlib import Path

import numpy as np
import numpy.typing as npt

from core.bvh_words import MAX_NAME as MAX_NAME
from core.bvh_words import (
    WHOLE_RE,
    Tokens,
    after_newlines,
    as_number,
    count_words,
    explain_count,
    fromstring,
    motion_values,
)
from core.bvh_words import BVHError as BVHError
from core.bvh_words import error as _error
from core.euler import euler_matrices
from core.text import quoted

FloatArray = npt.NDArray[np.float64]
Memo = dict[str, object]

_POSITION_CHANNELS = {"xposition": 0, "yposition": 1, "zposition": 2}
_ROTATION_CHANNELS = {"xrotation": "X", "yrotation": "Y", "zrotation": "Z"}
_MOTION_RE = re.compile(r"^[ \t]*MOTION[ \t]*\r?$", re.MULTILINE)
_BLANK_RE = re.compile(r"\n[^\S\n]*(?=\n|\Z)")  # a blank line after the first
_BLANK_FIRST_RE = re.compile(r"[^\S\n]*(?:\n|\Z)")  # a blank first line
_BLANK_MID_RE = re.compile(r"\n[^\S\n]*\n")  # a blank line between two others
_FRAME_LINE_RE = re.compile(r"^[^\n]*\S[^\n]*", re.MULTILINE)  # a non-blank line
_FRAMES_RE = re.compile(r"^[ \t]*Frames:[ \t]*(\S+)[ \t]*\r?$")
_LINE_RE = re.compile(r"^line \d+: ")  # an error's line, where it opens the reason
_FRAME_TIME_RE = re.compile(r"^[ \t]*Frame Time:[ \t]*(\S+)[ \t]*\r?$")


@dataclass(frozen=True)
class BVHJoint:
    """One joint (or End Site pseudo-joint) of a BVH hierarchy."""

    name: str
    parent: int  # index into BVH.joints, -1 for a root
    offset: tuple[float, float, float]
    channels: tuple[str, ...] = ()  # as written in the file, e.g. ("Zrotation", ...)
    channel_start: int = 0  # column of the first channel in the MOTION rows
    end_site: bool = False

    @property
    def rotation_order(self) -> str:
        """Intrinsic Euler sequence of the rotation channels, e.g. ``"ZXY"`` ('' if none)."""
        return "".join(
            _ROTATION_CHANNELS[c.lower()] for c in self.channels if c.lower() in _ROTATION_CHANNELS
        )


@dataclass(frozen=True)
class Cut:
    """Where a MOTION block read for some frames ends before its declared frames are whole
    (a file cut short): on line ``line``, inside frame ``frame`` after ``values`` of its
    values (0: before it), of the ``frames`` its ``Frames:`` line declares. The frames
    before ``frame`` read (and a writer keeps the rest as written); it and those after are
    lost, and one asked for is refused as the whole read refuses the block."""

    frame: int
    values: int
    line: int
    frames: int


@dataclass(frozen=True)
class BVH:
    """A parsed BVH file: the hierarchy (parents precede children) and the motion."""

    name: str
    joints: tuple[BVHJoint, ...]
    frame_time: float
    motion: FloatArray  # [F, C] channel values, one row per frame
    #: The file's text, unchanged ('' when built in code), and the offset in it of the first
    #: frame line (just after the ``Frame Time`` line): a writer keeps untouched parts as-is.
    text: str = field(default="", repr=False, compare=False)
    motion_offset: int = field(default=0, repr=False, compare=False)
    #: the frames whose values were read (None: all; the others' rows are NaN)
    read: frozenset[int] | None = field(default=None, repr=False, compare=False)
    #: (start, end) offsets in ``text`` of the lines of the frames read alone (a writer's)
    spans: dict[int, tuple[int, int]] = field(default_factory=dict, repr=False, compare=False)
    #: where the block ends before its frames are whole, where it was read for some frames
    cut: Cut | None = field(default=None, repr=False, compare=False)
    #: the file's line end where it is CR alone (classic Mac OS): ``text`` holds LF there
    #: (as read), and a writer gives the file back with its own
    cr_only: bool = field(default=False, repr=False, compare=False)
    _index: dict[str, int] = field(default_factory=dict, repr=False, compare=False)
    #: what readers work out once per hierarchy, of its joints alone (``core.bvh_write``'s
    #: channel layout, the service's rig), shared by the files read with it: read-only
    memo: Memo = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._index.update({j.name: i for i, j in enumerate(self.joints)})

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def num_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def num_channels(self) -> int:
        return int(self.motion.shape[1])

    def frame_span(self, frame: int) -> tuple[int, int] | None:
        """(start, end) offsets in :attr:`text` of the text that holds frame ``frame``'s
        values and nothing else: its line (its line ending left out but a ``\r``) where the
        block holds one frame a line and no blank line, else from its first value to the
        end of its last (over several lines where the file wraps its frames). None for a
        BVH not read from text."""
        if not 0 <= frame < self.num_frames:
            return None
        return (self.frame_spans([frame]) or {}).get(frame)

    def frame_spans(self, frames: Iterable[int]) -> dict[int, tuple[int, int]] | None:
        """:meth:`frame_span` of each of ``frames`` (in range), those the reader did not
        find found in one pass over the block (a clip's); None for a BVH not from text."""
        if not self.text:
            return None
        picks = sorted(set(frames))
        found = {f: self.spans[f] for f in picks if f in self.spans}
        if not (missing := [f for f in picks if f not in found]):
            return found
        if one_frame_a_line(self.text, self.motion_offset, self.num_frames):
            lines = _FRAME_LINE_RE.finditer(self.text, self.motion_offset)
            at = 0
            for f in missing:  # (ascending: the lines are stepped over once)
                line = next(islice(lines, f - at, None))
                found[f], at = (line.start(), line.end()), f + 1
            return found
        words = frame_words(self.text, self.motion_offset, self.num_frames, self.num_channels,
                            missing)  # fmt: skip
        return None if words is None else {**found, **words}

    def row(self, frame: int) -> FloatArray:
        """Frame ``frame``'s channel values ``[C]``; ``ValueError`` for a frame the reader
        was not asked to read."""
        if self.read is not None and frame not in self.read:
            raise ValueError(f"{self.name}: frame {frame} was not read (read: {sorted(self.read)})")
        out: FloatArray = self.motion[frame]
        return out

    @property
    def fps(self) -> float:
        """Frame rate from the header's Frame Time (the file may lie; see joint maps)."""
        return 1.0 / self.frame_time

    @property
    def rotation_joints(self) -> tuple[int, ...]:
        """Indices of the joints that carry at least one rotation channel."""
        return tuple(i for i, j in enumerate(self.joints) if j.rotation_order)

    def frame_lines(self) -> list[str]:
        """The raw text of each frame line of the MOTION block (``num_frames`` strings, line
        endings stripped), exactly as in the file; empty if the BVH was not parsed from text."""
        if not self.text:
            return []
        lines = [ln.rstrip("\r") for ln in self.text[self.motion_offset :].split("\n")]
        return [ln for ln in lines if ln.strip()]

    def frame_line_count(self) -> int:
        """``len(self.frame_lines())``, without making the lines: every line of the MOTION
        block less the blank ones (found by their newline, so the search skips along)."""
        return count_frame_lines(self.text, self.motion_offset) if self.text else 0

    def whole(self) -> None:
        """``ValueError`` unless every frame was read (a writer of the whole motion asks)."""
        if self.read is not None:
            raise ValueError(f"{self.name}: only frames {sorted(self.read)} were read")

    def index(self, name: str) -> int:
        """Index of a joint by name; ``KeyError`` listing the known names if absent."""
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(
                f"{self.name}: no joint {quoted(name)}; joints are {', '.join(self.joint_names)}"
            ) from None

    def forward_kinematics(
        self,
        names: Sequence[str] | None = None,
        frames: slice | npt.NDArray[np.integer] | None = None,
    ) -> FloatArray:
        """World positions ``[F, K, 3]`` (file units) of ``names`` (default: all joints).

        ``frames`` selects motion rows before FK (e.g. ``slice(None, None, 4)``), so that
        sub-sampling costs nothing. Only the requested joints' ancestors are evaluated.
        """
        return forward_kinematics(self, names, frames)


def count_frame_lines(text: str, at: int) -> int:
    """The non-blank lines of ``text`` from offset ``at``, without making the lines (found
    by their newline, so the search skips along; each blank line is one match)."""
    blank = sum(1 for _ in _BLANK_RE.finditer(text, at))
    return text.count("\n", at) + 1 - blank - (_BLANK_FIRST_RE.match(text, at) is not None)


def one_frame_a_line(text: str, at: int, n_frames: int) -> bool:
    """Whether the MOTION block from ``at`` holds ``n_frames`` lines and no blank line (so
    a frame's line holds its values and nothing else)."""
    if _BLANK_FIRST_RE.match(text, at) or _BLANK_MID_RE.search(text, at):
        return False
    last = text[text.rfind("\n") + 1 :]  # (the block's last line: "" after a final newline)
    return text.count("\n", at) + (not last.isspace() and last != "") == n_frames


#: what ``str.split()`` splits at (``str.isspace``; none past U+3000), by code point; the
#: last entry (not a space) stands for every code point past it
_SPACES = np.zeros(0x3002, dtype=bool)
_SPACES[[c for c in range(0x3001) if chr(c).isspace()]] = True
_CHUNK = 1 << 20  # characters looked at a time by :func:`_word_starts`
_WORD_RE = re.compile(r"\S+")


def _word_starts(text: str, at: int, wanted: Sequence[int]) -> tuple[int, list[int]]:
    """The count of the words of ``text[at:]`` (as ``str.split()`` splits it) and the
    offsets of those numbered ``wanted`` (0-based, ascending, each less than the count),
    found by numpy a chunk of :data:`_CHUNK` characters at a time: no Python object per
    word (a 7.5 MB block of 1.2 M words: ~10 ms; a regex stepping over them took 45)."""
    count, found, k, space_before = 0, [], 0, True
    for lo in range(at, len(text), _CHUNK):
        chunk = text[lo : lo + _CHUNK]
        if chunk.isascii():
            codes = np.frombuffer(chunk.encode("ascii"), dtype=np.uint8)
        else:  # (code points; a lone surrogate, which JSON may carry, is no space)
            wide = np.frombuffer(chunk.encode("utf-32-le", "surrogatepass"), dtype=np.uint32)
            codes = np.minimum(wide, len(_SPACES) - 1)
        space = _SPACES[codes]
        start = ~space  # a word starts where a space (or the block's start) is before it
        start[1:] &= space[:-1]
        start[0] &= space_before
        n = int(np.count_nonzero(start))
        if k < len(wanted) and wanted[k] < count + n:
            where = np.flatnonzero(start)
            while k < len(wanted) and wanted[k] < count + n:
                found.append(lo + int(where[wanted[k] - count]))
                k += 1
        count, space_before = count + n, bool(space[-1])
    return count, found


def frame_words(
    text: str, at: int, n_frames: int, n_channels: int, frames: Iterable[int]
) -> dict[int, tuple[int, int]] | None:
    """(start, end) offsets in ``text`` of each of ``frames``' values (from its first
    value's start to its last's end, across lines where the file wraps a frame), where
    the MOTION block from ``at`` holds ``n_frames * n_channels`` words; None where it
    holds another count (the whole read says why). ``frames`` are in range."""
    picks = sorted(set(frames))
    count, starts = _word_starts(text, at, [f * n_channels for f in picks])
    if count != n_frames * n_channels:
        return None
    spans: dict[int, tuple[int, int]] = {}
    for f, start in zip(picks, starts, strict=True):
        last = next(islice(_WORD_RE.finditer(text, start), n_channels - 1, None))
        spans[f] = (start, last.end())
    return spans


#: the deepest nesting of joints read (a real rig's fingers or hair are tens deep; the
#: reader recurses once per level, and Python's stack holds about a thousand)
MAX_DEPTH = 256
#: the most joints a hierarchy may hold, End Sites included (a real rig has tens to a few
#: hundred: fingers, toes, a face); what the service reads of a character in any form
#: (``service.characters``). A file past it is refused as soon as the reader gets there:
#: an 8 MiB body of End Sites alone held ~295,000, and reading, mapping and answering
#: them took a worker 3.6-11.7 s against its 2 s deadline (an API audit, 2026-12-05).
MAX_JOINTS = 2000
#: the most channels one joint may list (real files list 3 or 6; any order and any number
#: of rotation channels up to this are read): one joint of 400,000 rotation channels took
#: a worker past its deadline too (the same audit).
MAX_JOINT_CHANNELS = 12


class _Hierarchy:
    """The joints of a HIERARCHY as its words are read: a joint's children by recursion
    (:meth:`joint`, at most :data:`MAX_DEPTH` deep), at most :data:`MAX_JOINTS` joints. A
    class: a nested function that calls itself is in its own closure, a reference cycle
    that kept the words of every hierarchy read until a full collection (a hardening audit,
    2026-12-06: five refused 8 MiB hierarchies held a worker at 2.4 GiB)."""

    def __init__(self, toks: Tokens) -> None:
        self.toks = toks
        self.file = toks.file
        self.joints: list[BVHJoint] = []
        self.names: set[str] = set()
        self.n_channels = 0
        self.open = 0  # the '{' read and not yet closed (a file cut short: one or more)

    def read(self) -> None:
        """The HIERARCHY keyword and every ROOT's block (not what follows them)."""
        toks = self.toks
        toks.expect("HIERARCHY")
        while toks.peek() == "ROOT":
            toks.next("ROOT")
            self.joint(-1, 1)
        if not self.joints:
            raise _error(self.file, f"line {toks.line()}: no ROOT joint in HIERARCHY")

    def too_many(self, line: int) -> None:
        if len(self.joints) >= MAX_JOINTS:
            raise _error(
                self.file, f"line {line}: more than {MAX_JOINTS} joints (End Sites included): "
                "more than a character the service reads may have",
            )  # fmt: skip

    def joint(self, parent: int, depth: int) -> None:
        """A ROOT's or JOINT's block (its keyword read), its children's too."""
        toks, file, joints = self.toks, self.file, self.joints
        line = toks.line()
        if depth > MAX_DEPTH:
            raise _error(file, f"line {line}: joints nested more than {MAX_DEPTH} deep")
        name = toks.rest_of_line("a joint name")
        if not name:
            raise _error(file, f"line {line}: missing joint name")
        self.too_many(line)
        if name in self.names:
            raise _error(file, f"line {line}: duplicate joint name {quoted(name)}")
        self.names.add(name)
        toks.expect("{")
        self.open += 1
        toks.expect("OFFSET")
        ox, oy, oz = toks.floats(3, f"OFFSET of {name}")
        channels = self.channels(name)
        index = len(joints)
        joints.append(BVHJoint(name, parent, (ox, oy, oz), channels, self.n_channels))
        self.n_channels += len(channels)
        end_count = 0
        while True:
            line = toks.line()
            tok = toks.next("JOINT, End Site or '}'")
            if tok == "}":
                self.open -= 1
                return
            if tok == "JOINT":
                self.joint(index, depth + 1)
            elif tok == "End":
                toks.expect("Site")
                toks.expect("{")
                self.open += 1
                toks.expect("OFFSET")
                ex, ey, ez = toks.floats(3, f"End Site OFFSET of {name}")
                toks.expect("}")
                self.open -= 1
                self.too_many(line)
                end_count += 1
                end_name = f"{name}_end" if end_count == 1 else f"{name}_end{end_count}"
                joints.append(  # (named anew below where a real joint has that name)
                    BVHJoint(end_name, index, (ex, ey, ez), (), self.n_channels, end_site=True)
                )
            else:
                raise _error(
                    file, f"line {line}: expected JOINT, End Site or '}}', got {quoted(tok)}"
                )

    def channels(self, name: str) -> tuple[str, ...]:
        """A joint's CHANNELS line: the count, then as many channel names."""
        toks, file = self.toks, self.file
        line = toks.line()
        toks.expect("CHANNELS")
        count_tok = toks.next("a channel count")
        count = int(count_tok) if WHOLE_RE.fullmatch(count_tok) else -1
        if count < 0:
            raise _error(
                file, f"line {line}: bad channel count {quoted(count_tok)}: not a whole number >= 0"
            )
        if count > MAX_JOINT_CHANNELS:
            raise _error(
                file, f"line {line}: {quoted(count)} channels on joint {quoted(name)}: at most "
                f"{MAX_JOINT_CHANNELS} are read (files list 3 or 6)",
            )  # fmt: skip
        channels: list[str] = []
        for _ in range(count):
            line = toks.line()
            ch = toks.next("a channel name")
            if ch.lower() not in _POSITION_CHANNELS and ch.lower() not in _ROTATION_CHANNELS:
                short = (
                    f" (CHANNELS {count} lists {len(channels)}?)"
                    if ch.upper() in ("JOINT", "END", "}", "{", "OFFSET")
                    else ""
                )
                raise _error(
                    file,
                    f"line {line}: unknown channel {quoted(ch)} of joint {quoted(name)}{short}",
                )
            channels.append(ch)
        return tuple(channels)


#: hierarchies shared: the last :data:`SHARED` read (their text before MOTION, at most
#: :data:`SHARED_TEXT` characters) are parsed once, and each file that has one shares its
#: joints and :attr:`BVH.memo` (an editor sends one file's hierarchy with every edit)
SHARED, SHARED_TEXT = 8, 1 << 17


def _parse_hierarchy(file: str, text: str, end: int) -> tuple[tuple[BVHJoint, ...], Memo]:
    """The joints of the HIERARCHY ``text[:end]`` and their memo (shared: above)."""
    return _shared(file, text[:end]) if end <= SHARED_TEXT else (_joints(file, text, end), {})


@lru_cache(maxsize=SHARED)
def _shared(file: str, text: str) -> tuple[tuple[BVHJoint, ...], Memo]:
    return _joints(file, text, len(text)), {}


def _joints(file: str, text: str, end: int) -> tuple[BVHJoint, ...]:
    """The joints of the HIERARCHY ``text[:end]`` (read in place: no copy of it is made)."""
    toks = Tokens(file, text, end)
    reader = _Hierarchy(toks)
    reader.read()
    if toks.peek() is not None:
        raise _error(
            file, f"line {toks.line()}: unexpected {quoted(toks.peek())} after the hierarchy"
        )
    return tuple(_end_sites_named(reader.joints, reader.names))


def _no_motion(file: str, text: str) -> BVHError:
    """Why ``text``, which has a HIERARCHY keyword and no MOTION line, is refused, naming
    where it ends (the line of its last word): cut short inside its hierarchy (the words
    run out, or the last one is wrong, before every joint is closed), a fault of its
    hierarchy before that (as a whole file's), or a whole hierarchy with no MOTION
    section after it. It was "missing MOTION section" alone, no line (an audit,
    2026-12-06: the first 1,500 bytes of a real file)."""
    toks = Tokens(file, text, len(text))
    reader = _Hierarchy(toks)
    try:
        reader.read()
    except BVHError as exc:
        if toks.peek() is not None:  # (a fault before the file's last word)
            return exc
        unclosed = f"{reader.open} '{{' not closed, " if reader.open else ""
        reason = _LINE_RE.sub("", exc.reason)  # (the line is named once)
        why = "" if reason.startswith("unexpected end") else f": {reason}"
        return _error(
            file, f"line {toks.line()}: the file ends inside its HIERARCHY ({unclosed}no "
            f"MOTION section): it looks cut short{why}",
        )  # fmt: skip
    last, after = toks.line(), toks.peek()
    if after is not None:
        return _error(
            file, f"line {last}: missing MOTION section: the HIERARCHY is whole, and "
            f"{quoted(after)} follows it where a 'MOTION' line should",
        )  # fmt: skip
    return _error(
        file, f"line {last}: missing MOTION section: the file ends after its HIERARCHY, "
        "which is whole (a file of a skeleton alone has no frames to edit)",
    )  # fmt: skip


def _end_sites_named(joints: list[BVHJoint], taken: set[str]) -> list[BVHJoint]:
    """``joints`` with each End Site whose name is ``taken`` (the real joints' names, and
    the End Sites' before it) renamed to its parent's next free ``_endK``, in file order:
    a file whose joint is called ``Hand_end`` beside ``Hand``'s End Site is valid BVH."""
    out = []
    for joint in joints:
        if joint.end_site:
            name, k = joint.name, 1
            while name in taken:
                k += 1
                name = f"{joints[joint.parent].name}_end{k}"
            taken.add(name)
            joint = replace(joint, name=name)
        out.append(joint)
    return out


def parse_bvh(text: str, name: str = "<string>", frames: Iterable[int] | None = None) -> BVH:
    """Parse BVH text; ``name`` is used in error messages. ``frames``: read only these
    frames' values (those in range), each frame read checked as a whole block is; all are
    read where the block holds fewer or more values than its frames need (the whole read
    says where), or is too short for them."""
    cr_only = "\r" in text and "\n" not in text  # lines ended by CR alone (classic Mac OS):
    if cr_only:  # read as LF; a writer gives an edited file back with CR (``BVH.cr_only``)
        text = text.replace("\r", "\n")
    match = _MOTION_RE.search(text)
    if match is None:
        if "HIERARCHY" not in text:
            raise _error(name, "not a BVH file (no HIERARCHY keyword)")
        raise _no_motion(name, text)
    joints, memo = _parse_hierarchy(name, text, match.start())
    columns = [(j.name, c) for j in joints for c in j.channels]  # (errors name them)
    n_channels = len(columns)
    if n_channels == 0:
        raise _error(name, "the hierarchy has no channels")

    motion_line = text.count("\n", 0, match.start()) + 1  # 1-based line number of MOTION
    # the rest of the MOTION line (empty), then Frames, Frame Time and the body, found
    # without copying the body (one frame of a large file is read without it)
    ends = [text.find("\n", match.end())]
    for _ in range(2):
        ends.append(-1 if ends[-1] < 0 else text.find("\n", ends[-1] + 1))
    if ends[1] < 0:
        raise _error(name, f"line {motion_line}: truncated MOTION header")
    frames_text = text[ends[0] + 1 : ends[1]]
    time_text = text[ends[1] + 1 : len(text) if ends[2] < 0 else ends[2]]
    frames_match = _FRAMES_RE.match(frames_text)
    if frames_match is None:
        got = quoted(frames_text)
        raise _error(name, f"line {motion_line + 1}: expected 'Frames: <n>', got {got}")
    time_match = _FRAME_TIME_RE.match(time_text)
    if time_match is None:
        got = quoted(time_text)
        raise _error(name, f"line {motion_line + 2}: expected 'Frame Time: <seconds>', got {got}")
    count = frames_match.group(1)
    try:
        n_frames = int(count) if WHOLE_RE.fullmatch(count) else None
    except ValueError:  # (past 4,300 digits)
        n_frames = None
    if n_frames is None:
        raise _error(name, f"line {motion_line + 1}: bad frame count {quoted(count)}")
    frame_time = as_number(time_match.group(1))
    if frame_time is None:
        got = quoted(time_match.group(1))
        raise _error(name, f"line {motion_line + 2}: bad Frame Time {got}: not a number")
    if n_frames < 0:
        raise _error(name, f"line {motion_line + 1}: negative frame count {quoted(n_frames)}")
    if not np.isfinite(frame_time) or frame_time <= 0:
        said = quoted(time_match.group(1))  # (as the file has it: 1e-400 read as 0.0)
        raise _error(name, f"line {motion_line + 2}: bad Frame Time {said}: not above 0 and finite")

    body_offset = len(text) if ends[2] < 0 else ends[2] + 1
    first_line = motion_line + 3
    some = None
    if frames is not None:
        some = _read_frames(name, text, body_offset, first_line, n_frames, columns, frames)
    read: frozenset[int] | None = None
    spans: dict[int, tuple[int, int]] = {}
    cut = None
    if some is None:
        motion = _read_all(name, text[body_offset:], first_line, n_frames, columns)
    else:
        motion, read, spans, cut = some
    return BVH(
        name=name,
        joints=joints,
        frame_time=frame_time,
        motion=motion,
        text=text,
        motion_offset=body_offset,
        read=read,
        spans=spans,
        cut=cut,
        cr_only=cr_only,
        memo=memo,
    )


def _read_all(
    name: str, body: str, first_line: int, n_frames: int, columns: list[tuple[str, str]]
) -> FloatArray:
    """Every frame's values ``[F, C]`` of the MOTION block ``body`` (``columns``: the C
    (joint name, channel) pairs)."""
    values = fromstring(body)
    count = count_words(body) if values is None else values.size
    if count != n_frames * len(columns):
        explain_count(name, body, first_line, n_frames, len(columns))
    return motion_values(name, body, first_line, values, columns, 0).reshape(n_frames, len(columns))


def _read_frames(
    name: str,
    text: str,
    at: int,
    first_line: int,
    n_frames: int,
    columns: list[tuple[str, str]],
    frames: Iterable[int],
) -> tuple[FloatArray, frozenset[int], dict[int, tuple[int, int]], Cut | None] | None:
    """The motion ``[F, C]`` with only ``frames``' rows read (the others NaN), the set read,
    their lines' (start, end) in ``text`` and where the block is cut short
    (:func:`_cut_short`: the frames before the cut are read, one at or past it is not),
    where the block from ``at`` holds ``n_frames`` non-blank lines; None where it does not,
    or cannot hold the values (frames across lines, a count that does not match, fewer
    characters than the values need: the whole read explains it, and no table larger than
    the text allows is made)."""
    n_channels = len(columns)
    if n_frames * n_channels * 2 > len(text) - at + 1:  # a value and a separator each
        return None
    read = frozenset(f for f in frames if 0 <= f < n_frames)
    # a block cut short: the frames before the cut are read line by line; one at or past
    # it as before (line by line where the cut is inside the last line, else whole: refused)
    plain = one_frame_a_line(text, at, n_frames)
    cut = _cut_short(text, at, first_line, n_frames, n_channels, plain)
    if not plain and (cut is None or any(f >= cut.frame for f in read)):
        return _read_frame_words(name, text, at, first_line, n_frames, columns, read)
    motion = np.full((n_frames, n_channels), np.nan)
    spans: dict[int, tuple[int, int]] = {}
    line_at, line_frame = at, 0  # the start of a frame line found, and its frame
    for f in sorted(read):
        start = after_newlines(text, line_at, f - line_frame)
        end = text.find("\n", start)
        end = len(text) if end < 0 else end
        spans[f] = (start, end)
        line_at, line_frame = start, f
        line, number = text[start:end], first_line + f  # (no blank line among them)
        count = count_words(line)
        if count != n_channels:
            got = f"expected {n_channels} values per frame, got {count}"
            raise _error(name, f"line {number}: {got}")
        motion[f] = motion_values(name, line, number, fromstring(line), columns, f)
    return motion, read, spans, cut


def _cut_short(
    text: str, at: int, first_line: int, n_frames: int, n_channels: int, plain: bool
) -> Cut | None:
    """Where the MOTION block from ``at`` ends before its ``n_frames`` frames are whole
    (an interrupted copy), if it holds one frame a line and no blank line among them: its
    last line holds fewer than ``n_channels`` values, or it has fewer lines than frames
    (cut at a line's end; its first line holding one frame's values). None where the block
    is whole, or is not so laid out (read as before: whole, which refuses it). ``plain``:
    it holds ``n_frames`` lines and no blank line (:func:`one_frame_a_line`): only its last
    line is looked at (no second pass over a large block)."""
    if plain:
        end = text.rfind("\n", at)  # (the last line, or the blank after it)
        if end < 0 or text[end + 1 :].strip():
            end = len(text)
        values = count_words(text[max(at, text.rfind("\n", at, end) + 1) : end])
        if values >= n_channels or n_frames == 0:
            return None
        return Cut(n_frames - 1, values, first_line + n_frames - 1, n_frames)
    # else (blank lines after it, or fewer lines than frames) only where each line is one
    # frame (its first says so: a wrapped block is told apart here, before a pass over it)
    first = text.find("\n", at)
    if count_words(text[at : len(text) if first < 0 else first]) != n_channels:
        return None
    end = max(at, len(text.rstrip()))  # (trailing blank lines are no frame; in C)
    if _BLANK_MID_RE.search(text, at, end):
        return None
    n_lines = text.count("\n", at, end) + 1
    values = count_words(text[max(at, text.rfind("\n", at, end) + 1) : end])
    if n_lines > n_frames or values > n_channels or (n_lines == n_frames and values == n_channels):
        return None
    whole = n_lines - (values < n_channels)
    return Cut(whole, values % n_channels, first_line + n_lines - 1, n_frames)


def _read_frame_words(
    name: str,
    text: str,
    at: int,
    first_line: int,
    n_frames: int,
    columns: list[tuple[str, str]],
    read: frozenset[int],
) -> tuple[FloatArray, frozenset[int], dict[int, tuple[int, int]], Cut | None] | None:
    """:func:`_read_frames` of a block whose frames are not one a line (wrapped over
    several lines, or blank lines among them): each frame read is its values' words
    (:func:`frame_words`), checked as the whole read checks them; None where the block
    does not hold as many words as its frames' values (the whole read says why)."""
    n_channels = len(columns)
    spans = frame_words(text, at, n_frames, n_channels, read)
    if spans is None:
        return None
    motion = np.full((n_frames, n_channels), np.nan)
    line, line_at = first_line, at  # the line of offset line_at
    for f in sorted(read):
        start, end = spans[f]
        line, line_at = line + text.count("\n", line_at, start), start
        words = text[start:end]
        motion[f] = motion_values(name, words, line, fromstring(words), columns, f)
    return motion, read, spans, None


def read_bvh(path: str | Path, name: str | None = None) -> BVH:
    """Read and parse a BVH file (``BVHError`` on malformed content or unreadable file)."""
    path = Path(path)
    label = name if name is not None else str(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise _error(label, f"cannot read: {exc.strerror or exc}") from None
    return parse_bvh(text, label)


def forward_kinematics(
    bvh: BVH,
    names: Sequence[str] | None = None,
    frames: slice | npt.NDArray[np.integer] | None = None,
) -> FloatArray:
    """World positions ``[F, K, 3]`` of the named joints (default: all), in file units.

    Batched over frames; Euler rotations are converted per distinct channel order in one
    vectorised call each. ``ValueError`` for a file read for some frames only.
    """
    bvh.whole()
    motion = bvh.motion if frames is None else bvh.motion[frames]
    n_frames = motion.shape[0]
    wanted = list(range(len(bvh.joints))) if names is None else [bvh.index(n) for n in names]

    needed: set[int] = set()
    for j in wanted:
        while j >= 0 and j not in needed:
            needed.add(j)
            j = bvh.joints[j].parent
    order = sorted(needed)  # file order: parents precede children

    # Local rotations, batched per Euler sequence.
    local_rot: dict[int, FloatArray] = {}
    by_seq: dict[str, list[int]] = {}
    for j in order:
        seq = bvh.joints[j].rotation_order
        if seq:
            by_seq.setdefault(seq, []).append(j)
    for seq, joint_ids in by_seq.items():
        cols = [
            [
                bvh.joints[j].channel_start + k
                for k, c in enumerate(bvh.joints[j].channels)
                if c.lower() in _ROTATION_CHANNELS
            ]
            for j in joint_ids
        ]
        # angles: [F, n_joints, len(seq)] -> rotation matrices [F, n_joints, 3, 3]
        angles = np.deg2rad(motion[:, np.asarray(cols, dtype=np.intp)])
        mats = euler_matrices(seq, angles)
        for k, j in enumerate(joint_ids):
            local_rot[j] = mats[:, k]

    glob_rot: dict[int, FloatArray] = {}
    glob_pos: dict[int, FloatArray] = {}
    for j in order:
        joint = bvh.joints[j]
        trans = np.broadcast_to(np.asarray(joint.offset, dtype=np.float64), (n_frames, 3))
        pos_cols = [
            (joint.channel_start + k, _POSITION_CHANNELS[c.lower()])
            for k, c in enumerate(joint.channels)
            if c.lower() in _POSITION_CHANNELS
        ]
        if pos_cols:
            trans = trans.copy()
            for col, axis in pos_cols:
                trans[:, axis] = motion[:, col]
        rot = local_rot.get(j)
        if joint.parent < 0:
            glob_pos[j] = np.array(trans)
            glob_rot[j] = rot if rot is not None else np.broadcast_to(np.eye(3), (n_frames, 3, 3))
        else:
            prot = glob_rot[joint.parent]
            glob_pos[j] = glob_pos[joint.parent] + np.einsum("fij,fj->fi", prot, trans)
            glob_rot[j] = prot if rot is None else np.matmul(prot, rot)

    out = np.empty((n_frames, len(wanted), 3), dtype=np.float64)
    for k, j in enumerate(wanted):
        out[:, k] = glob_pos[j]
    return out
