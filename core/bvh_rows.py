"""A look over the MOTION rows a partial read leaves unread (:func:`odd_row`).

The service parses only the frames it edits (``core.bvh.parse_bvh(frames=...)``): a
malformed row elsewhere (83 of 84 values, 85, a ``nan``) was answered 200 without a word,
and written back as sent. :func:`odd_row` finds the first such row without parsing every
number: each line's count of values and the first character no number or space holds
(numpy, a chunk of lines at a time: ~1.5 ms a MB); only a chunk that may hold a number
beyond the bound (an exponent not negative, ``1e400``, or eight digits before a point)
has its numbers read, by numpy. A block of frames wrapped over several lines (or with
blank lines among them) has its words looked at alike, each word's frame its index over
the channels.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from core.bvh import _SPACES, one_frame_a_line
from core.bvh_words import fromstring

_WORD_RE = re.compile(r"\S+")
#: a word that is no decimal number as ``float`` (and numpy) reads one: ``1.2.3``, ``1-2``
#: (possessive: ``\d+\.?\d*`` backtracked over a long run of digits, quadratic: a word of
#: 16,000 digits and an ``x`` took 5 s)
_NOT_A_NUMBER_RE = re.compile(
    r"(?<!\S)(?![-+]?+(?:\d++(?:\.\d*+)?+|\.\d++)(?:[eE][-+]?+\d++)?+(?!\S))\S+"
)
_CHUNK = 1 << 20  # characters looked at a time (whole lines)
#: ASCII spaces as ``str.split()`` has them (a chunk with others is split by Python)
_SPACE = np.zeros(256, dtype=bool)
_SPACE[[9, 10, 11, 12, 13, 28, 29, 30, 31, 32]] = True
#: ASCII characters a decimal number or a space holds
_NUMBER = _SPACE.copy()
_NUMBER[list(b"0123456789eE+-.")] = True
_ALLOWED = bytes(np.flatnonzero(_NUMBER).tolist())
_LONG = 8  # digits before a point from which a number may be past a bound of 1e7
#: digits and ``+`` to ``0``, ``E`` to ``e``, ``-`` and spaces to `` ``: an exponent not
#: negative is ``b"e0"``, a run of :data:`_LONG` digits not after a point ``b" 00000000"``
#: (found by ``bytes.find``, in C: no array a character)
_FLAT = bytes(
    48 if c in b"0123456789+" else 101 if c == 69 else 32 if c <= 32 or c == 45 else c
    for c in range(256)
)


@dataclass(frozen=True)
class OddRow:
    frame: int  # the first frame whose row is not its channels' values
    line: int  # its line in the file (1-based)
    detail: str  # what is wrong with it, in words


def odd_row(
    text: str, at: int, first_line: int, n_frames: int, n_channels: int, bound: float = math.inf
) -> OddRow | None:
    """The first of the ``n_frames`` frames of the MOTION block from ``at`` (the block on
    line ``first_line`` on) that holds a value no decimal number is, one beyond ``bound``
    (``1e400``: no finite number), or, one frame a line, other than ``n_channels`` values;
    None where every frame looks whole (``bound`` at least 1e7: a number within it is
    read only where the chunk may hold one past it). A block that is not one frame a line (wrapped
    frames, blank lines) is taken to hold its frames' values (the partial read counts
    them): its words are looked at, not its lines' counts."""
    if n_frames == 0 or n_channels == 0:
        return None
    rows = one_frame_a_line(text, at, n_frames)
    lo, line, words = at, 0, 0
    while lo <= len(text):
        hi = len(text) if lo + _CHUNK >= len(text) else text.rfind("\n", lo, lo + _CHUNK)
        if hi < lo:  # a line longer than a chunk
            hi = text.find("\n", lo + _CHUNK)
            hi = len(text) if hi < 0 else hi
        index, word, detail = _odd_in(text[lo:hi], n_channels, bound, rows)
        if detail:
            frame = line + index if rows else (words + word) // n_channels
            if frame >= n_frames:
                return None
            return OddRow(frame, first_line + line + index, detail)
        line += index
        words += word
        lo = hi + 1
    return None


def _beyond(word: str, bound: float) -> str:
    """What is wrong with ``word`` read as a number ("" where it is one within ``bound``)."""
    try:
        value = float(word)
    except ValueError:
        return f"{word[:20]!r}, not a number"
    if abs(value) <= bound:
        return ""
    if math.isinf(value):
        return f"{word[:20]!r}, out of range (no finite number)"
    return f"{word[:20]!r}, beyond ±{bound:g}"


def _narrowed(chunk: str) -> str:
    """``chunk`` with each character past ASCII a space where ``str.split`` splits there
    (U+3000 too), else ``x`` (no number's): the same words at the same places, looked at
    as any chunk is, by numpy (line by line in Python, 8 MB with one such a line took 2 s)."""
    wide = np.frombuffer(chunk.encode("utf-32-le", "surrogatepass"), dtype=np.uint32)
    space = _SPACES[np.minimum(wide, _SPACES.size - 1)]
    narrow = np.where(wide < 128, wide, np.where(space, 32, 120)).astype(np.uint8)
    return narrow.tobytes().decode("ascii")


def _odd_in(chunk: str, n: int, bound: float, rows: bool) -> tuple[int, int, str]:
    """The first line of ``chunk`` (its index) with a word no number is, one beyond
    ``bound``, or (``rows``) other than ``n`` words; the index of that word (of the chunk's)
    and what is wrong; else the count of its lines and of its words, and ``""``."""
    text = chunk if chunk.isascii() else _narrowed(chunk)
    raw = text.encode("ascii")
    codes = np.frombuffer(raw, dtype=np.uint8)
    space = codes <= 32  # (with no other character, every one up to a space's code is a space)
    starts = np.empty(codes.size, dtype=bool)
    starts[:1] = ~space[:1]
    np.greater(space[:-1], space[1:], out=starts[1:])
    newlines = np.flatnonzero(codes == 10)
    n_words = int(np.count_nonzero(starts))
    big = _may_hold_big(raw)
    wrong = bool(raw.translate(None, _ALLOWED))
    if rows:
        counts = np.add.reduceat(starts, np.r_[0, newlines], dtype=np.int32) if codes.size else [0]
        odd = np.flatnonzero(np.asarray(counts) != n)
    if not (big or wrong or (rows and odd.size)):
        return newlines.size + 1, n_words, ""
    first = np.flatnonzero(starts)  # each word's first character
    found: list[tuple[int, int, str]] = []  # (line, word, detail) of a word no number is
    if wrong:
        at = int(np.flatnonzero(~_NUMBER[codes])[0])
        k = int(np.searchsorted(first, at, side="right")) - 1
        word = _WORD_RE.match(chunk, int(first[k])) if k >= 0 else None
        said = f"{(word.group() if word else chunk[at])[:20]!r}, not a number"
        found.append((int(np.searchsorted(newlines, at)), max(k, 0), said))
    k = _first_beyond(text, bound) if big else -1
    if k >= 0:
        said = _beyond(_WORD_RE.match(chunk, int(first[k])).group(), bound)  # type: ignore[union-attr]
        found.append((int(np.searchsorted(newlines, first[k])), k, said))
    if rows and odd.size:
        i = int(odd[0])
        k = int(np.searchsorted(first, newlines[i - 1] if i else -1, side="right"))
        found.append((i, k, f"{int(counts[i])} values, not {n}"))
    if found:  # one frame a line: the first line (a word's wrong first, on one line);
        # else the first word, whatever its line holds (frames wrapped, or several a line)
        return min(found, key=(lambda f: f[0]) if rows else (lambda f: f[1]))
    return newlines.size + 1, n_words, ""


def _may_hold_big(raw: bytes) -> bool:
    """Whether ``raw`` may hold a number past a bound of 1e7: an exponent not negative, or
    :data:`_LONG` digits in a row not after a point (by ``bytes`` methods, in C: a chunk of a
    writer's file, ``-9.35e-15`` and all, is passed over in a fraction of a millisecond)."""
    flat, run = raw.translate(_FLAT), b"0" * _LONG
    return b"e0" in flat or flat.startswith(run) or b" " + run in flat


def _first_beyond(chunk: str, bound: float) -> int:
    """The index of the first word of ``chunk`` past ``bound`` (``1e400``: infinity), -1
    for none: numpy reads the chunk's numbers (in C: ~20 ms a MB at worst, where a chunk
    holds an exponent not negative; a word a Python ``float`` each took seconds for 8 MB
    of ``1e+01``). Where it does not read every word (``1.2.3``), each word no decimal
    number is stands as ``0`` (one word for one: the same indices) and numpy reads the
    rest: read line by line, a line holding ``1.2.3`` was passed over whole, and a
    ``1e400`` beside it with it (an audit); line by line only where that still fails."""
    values = fromstring(chunk)
    if values is None:
        chunk = _NOT_A_NUMBER_RE.sub("0", chunk)
        values = fromstring(chunk)
    if values is not None:
        far = np.flatnonzero(~(np.abs(values) <= bound))
        return int(far[0]) if far.size else -1
    k = 0
    for line in chunk.split("\n"):
        values = fromstring(line)
        if values is None:  # (a word no number is, made of a number's characters: not told)
            k += len(line.split())
            continue
        far = np.flatnonzero(~(np.abs(values) <= bound))
        if far.size:
            return k + int(far[0])
        k += values.size
    return -1
