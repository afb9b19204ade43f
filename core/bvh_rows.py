"""A look over the MOTION rows a partial read leaves unread (:func:`odd_row`).

The service parses only the frames it edits (``core.bvh.parse_bvh(frames=...)``): a
malformed row elsewhere (83 of 84 values, 85, a ``nan``) was answered 200 without a word,
and written back as sent. :func:`odd_row` finds the first such row without parsing a
number: each line's count of values and the first character no number or space holds
(numpy, a chunk of lines at a time: ~1.5 ms a MB).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from core.bvh import one_frame_a_line

#: a character no decimal number (nor a separator) holds: ``nan``, ``inf``, ``1,5``, ``x``
_NOT_NUMBER_RE = re.compile(r"[^0-9eE+\-.\s]")
_CHUNK = 1 << 20  # characters looked at a time (whole lines)
#: ASCII spaces as ``str.split()`` has them (a chunk with others is split by Python)
_SPACE = np.zeros(256, dtype=bool)
_SPACE[[9, 10, 11, 12, 13, 28, 29, 30, 31, 32]] = True
#: ASCII characters a decimal number or a space holds
_NUMBER = _SPACE.copy()
_NUMBER[list(b"0123456789eE+-.")] = True
_ALLOWED = bytes(np.flatnonzero(_NUMBER).tolist())


@dataclass(frozen=True)
class OddRow:
    frame: int  # the first frame whose row is not its channels' values
    line: int  # its line in the file (1-based)
    detail: str  # what is wrong with it, in words


def odd_row(text: str, at: int, first_line: int, n_frames: int, n_channels: int) -> OddRow | None:
    """The first of the ``n_frames`` rows of the MOTION block from ``at`` (one frame a
    line, the first on line ``first_line``) that holds a value no decimal number is, or
    other than ``n_channels`` values; None where every row looks whole, or where the block
    is not one frame a line (wrapped frames, blank lines, fewer lines than frames: the
    partial read tells those apart itself)."""
    if n_frames == 0 or n_channels == 0 or not one_frame_a_line(text, at, n_frames):
        return None
    lo, line = at, 0
    while lo <= len(text):
        hi = len(text) if lo + _CHUNK >= len(text) else text.rfind("\n", lo, lo + _CHUNK)
        if hi < lo:  # a line longer than a chunk
            hi = text.find("\n", lo + _CHUNK)
            hi = len(text) if hi < 0 else hi
        index, detail = _odd_in(text[lo:hi], n_channels)
        if detail:
            frame = line + index
            return None if frame >= n_frames else OddRow(frame, first_line + frame, detail)
        line += index
        lo = hi + 1
    return None


def _odd_in(chunk: str, n: int) -> tuple[int, str]:
    """The first line of ``chunk`` (its index) with a word no number is or other than
    ``n`` words, and what is wrong with it; else the count of its lines and ``""``."""
    if not chunk.isascii():  # (rare: a space or a letter past ASCII) line by line
        for i, ln in enumerate(chunk.split("\n")):
            words = ln.split()
            bad = next((w for w in words if _NOT_NUMBER_RE.search(w)), None)
            if bad is not None:
                return i, f"{bad[:20]!r}, not a number"
            if len(words) != n:
                return i, f"{len(words)} values, not {n}"
        return chunk.count("\n") + 1, ""
    raw = chunk.encode("ascii")
    codes = np.frombuffer(raw, dtype=np.uint8)
    # (with no other character, every one up to a space's code is a space)
    wrong = np.flatnonzero(~_NUMBER[codes]) if raw.translate(None, _ALLOWED) else None
    space = codes <= 32
    starts = np.empty(codes.size, dtype=bool)
    starts[:1] = ~space[:1]
    np.greater(space[:-1], space[1:], out=starts[1:])
    newlines = np.flatnonzero(codes == 10)
    counts = np.add.reduceat(starts, np.r_[0, newlines], dtype=np.int32) if codes.size else [0]
    odd = np.flatnonzero(np.asarray(counts) != n)
    if wrong is not None:
        at = int(wrong[0])
        bad_line = int(np.searchsorted(newlines, at))
        if not odd.size or bad_line <= odd[0]:
            start = max(chunk.rfind(c, 0, at) for c in " \t\n\r") + 1
            return bad_line, f"{chunk[start : start + 20].split()[0]!r}, not a number"
    if odd.size:
        return int(odd[0]), f"{int(counts[odd[0]])} values, not {n}"
    return newlines.size + 1, ""
