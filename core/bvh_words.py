"""The words of a BVH file, read in bounded memory, for :mod:`core.bvh`'s reader: the
HIERARCHY's a window at a time (:class:`Tokens`); numbers as writers write them, ASCII
decimals, not what else Python's ``float()`` reads (:func:`as_number`); the MOTION block's
words counted and checked, its faults found, without a list of them all
(:func:`count_words`, :func:`motion_values`, :func:`explain_count`). An audit's 8 MB bodies
(2026-12-06) took 2-4 s and 130-450 MiB where a hierarchy or a block was split whole.
:class:`BVHError` is here so that these raise it (``core.bvh`` names it too)."""

from __future__ import annotations

import re
from itertools import compress
from typing import NoReturn

import numpy as np
import numpy.typing as npt

from core.io import FileError
from core.text import clip, quoted

FloatArray = npt.NDArray[np.float64]


class BVHError(FileError):
    """A malformed, truncated or unsupported BVH file; names the file and the reason."""


def error(file: str, reason: str) -> BVHError:
    return BVHError(file, reason)


#: a number as BVH writers write one: ASCII digits with a sign, a point and an exponent.
#: ``float()`` also reads ``1_000``, other scripts' digits (``١``) and ``nan``/``inf``, which
#: no writer writes: the reader refuses them (an audit found the first two read, 2026-12-06).
NUMBER = r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
NUMBER_RE = re.compile(NUMBER)
#: a text's leading words that are numbers (each whole: atomic, possessive, no backtracking)
_NUMBERS_RE = re.compile(rf"(?:\s*+(?>{NUMBER})(?!\S))*+\s*+")
_WORD_RE = re.compile(r"\S+")
_SPACE_RE = re.compile(r"\s")
WHOLE_RE = re.compile(r"[+-]?[0-9]+")  # a whole number (a channel or frame count)


def as_number(word: str) -> float | None:
    """``word``'s value if it is a BVH number, else None: what ``float()`` reads of an ASCII
    word without ``_`` is a decimal where finite (else ``nan``, ``inf``, or a decimal past
    the float range: the regex tells them apart). The same as the regex first (a fuzz of
    2 M words agrees), at a third of its cost over ``float()`` alone (60 ns against 200)."""
    try:
        value = float(word)
    except ValueError:
        return None
    if word.isascii() and "_" not in word and (value - value == 0 or NUMBER_RE.fullmatch(word)):
        return value
    return None


def not_a_number(word: str) -> str:
    return f"not a number: {quoted(word)} (BVH numbers are finite decimals: -1.5, 2e-3)"


#: the longest joint name read (the skeleton form's limit too, ``service.characters``), and
#: the longest word of a HIERARCHY (the real files' longest name has 19 characters, their
#: longest word 15): refused where it stands, as a joint past MAX_JOINTS is.
MAX_NAME = 200
_NON_SPACE_RE = re.compile(r"\S")
_CUT_RE = re.compile(r"\r\n|\s")  # where a window of a HIERARCHY may end: after this
#: characters of a HIERARCHY split into words at a time (a real file's whole hierarchy)
WINDOW = 1 << 14


class Tokens:
    """The words of a HIERARCHY, ``text[:end]``, with their 1-based line numbers, split a
    window of :data:`WINDOW` characters at a time as the parser asks for them (lines, then
    words, as ``str.split()`` splits: in C), a window's words dropped once read. So a
    hierarchy is refused at its first fault or limit whatever follows, in bounded memory:
    an audit's 8 MiB hierarchy of 4 M words was split whole first, 2.2-3.9 s and ~420 MiB a
    request (2026-12-06). A word longer than :data:`MAX_NAME` is refused where it stands.
    Lines end at \\n, \\r\\n or \\r only: ``str.splitlines()`` also breaks at U+0085,
    U+2028 and some control characters, which a Latin-1 joint name may hold (0x85, '…')."""

    def __init__(self, file: str, text: str, end: int) -> None:
        self.file = file
        self._text, self._end = text, end
        # a UTF-8 byte order mark opening the file (Windows exporters write one) is no word
        self._from = 1 if text.startswith("\ufeff") else 0  # the next window's start
        self._next_line = 1  # the line there
        self.items: list[tuple[str, int]] = []  # the window's words and their lines
        self.pos = 0
        self._long = 0  # the index in items of a word past MAX_NAME (len(items): none)
        self._last = 1  # the line of the last word taken
        self._start = 0  # where the window's first word starts in the text
        self._seek = (-1, 0, 0)  # (a window's start, a word's index in it, where it starts)

    def _more(self) -> bool:
        """Split the next window into words (False at the end of the text). It ends just
        after whitespace: a word is whole in it, or cut past MAX_NAME characters."""
        text, at, end = self._text, self._from, self._end
        found = _NON_SPACE_RE.search(text, at, end)  # (blank lines skipped in C)
        if found is None:
            return False
        start = found.start()  # (a \r\n lies within [at, start): at follows whitespace)
        first = self._next_line + text.count("\n", at, start) + text.count("\r", at, start)
        first -= text.count("\r\n", at, start)
        cut = min(start + WINDOW, end)
        if cut < end:  # (+2: a \r\n after a word of MAX_NAME characters is whole)
            space = _CUT_RE.search(text, cut, min(cut + MAX_NAME + 2, end))
            cut = min(cut + MAX_NAME + 1, end) if space is None else space.end()
        window = text[start:cut]
        lines = window.replace("\r\n", "\n").replace("\r", "\n").split("\n")
        numbered = compress(enumerate(lines, start=first), map(str.strip, lines))
        self.items = [(word, k) for k, line in numbered for word in line.split()]
        self.pos, self._start = 0, start
        self._long = len(self.items)
        if max(map(len, lines)) > MAX_NAME:  # a line that may hold one (rare): word by word
            long = (i for i, (w, _) in enumerate(self.items) if len(w) > MAX_NAME)
            self._long = next(long, self._long)
        self._from, self._next_line = cut, first + len(lines) - 1
        return True

    def _ready(self) -> bool:
        """Whether a word is left (refused if longer than MAX_NAME)."""
        while self.pos >= len(self.items):
            if not self._more():
                return False
        if self.pos == self._long:
            word, line = self.items[self.pos]
            raise error(
                self.file, f"line {line}: a word of more than {MAX_NAME} characters: "
                f"{quoted(word)} (no joint name, keyword or number is so long)",
            )  # fmt: skip
        return True

    # (each first asks whether the word is one of the window's before any past MAX_NAME:
    # a real file's hierarchy reads as fast as when it was split whole)
    def line(self) -> int:
        """The current word's line (at the end: the last word's)."""
        if self.pos < self._long or self._ready():
            return self.items[self.pos][1]
        return self._last

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < self._long or self._ready() else None

    def next(self, what: str) -> str:
        if self.pos >= self._long and not self._ready():
            if self.pos == 0:  # (was "unexpected end of HIERARCHY, expected 'HIERARCHY'")
                raise error(self.file, "not a BVH file (no HIERARCHY keyword): nothing comes "
                            f"before its MOTION line, expected {what}")  # fmt: skip
            raise self._ended(what)
        word, self._last = self.items[self.pos]
        self.pos += 1
        return word

    def _ended(self, what: str) -> BVHError:
        """The words run out before the hierarchy is whole: where its text ends, the MOTION
        line (it said no line: an API audit, 2026-12-07). A file with no MOTION line says
        it otherwise (``core.bvh._no_motion``, which words this one anew)."""
        text, end = self._text, self._end
        line = 1 + text.count("\n", 0, end) + text.count("\r", 0, end) - text.count("\r\n", 0, end)
        return error(
            self.file, f"line {line}: unexpected end of HIERARCHY where its MOTION line begins, "
            f"expected {what}: a joint's '{{' is not closed (a '}}' or a joint's lines lost?)",
        )  # fmt: skip

    def expect(self, word: str) -> None:
        line = self.line()
        tok = self.next(repr(word))
        if tok != word:
            raise error(self.file, f"line {line}: expected {word!r}, got {quoted(tok)}")

    def _where(self, start: int, index: int) -> int:
        """Where in the text the word ``index`` of the window that starts at ``start``
        starts: found from the last one asked for where it can (the words of a name are
        asked for in order: each window is searched once)."""
        at, first, where = self._seek
        if at != start or first > index:
            first, where = 0, start
        words = _WORD_RE.finditer(self._text, where, self._end)
        for k, found in enumerate(words, start=first):
            if k == index:
                self._seek = (start, k, found.start())
                return found.start()
        raise AssertionError("a word of a window past its end")  # pragma: no cover

    def rest_of_line(self, what: str) -> str:
        """The words left on the current word's line, up to a '{' (a joint name may have
        spaces), as written: the text from the first to the last, whitespace and all (was
        joined by one space: a file's ``Left  Hand`` was called ``Left Hand``, and a map
        that named it as written refused); at most :data:`MAX_NAME` characters."""
        line = self.line()
        if self.peek() is None:
            raise self._ended(what)
        first = (self._start, self.pos)  # (where its first word is: asked for if not alone)
        words: list[str] = []
        size = -1  # of the words joined by one space (no more than as written)
        while (word := self.peek()) is not None and self.line() == line and word != "{":
            size += 1 + len(word)
            if size > MAX_NAME:
                self._too_long(line, " ".join([*words, word]))
            words.append(self.next(what))
        if len(words) < 2:
            return "".join(words)
        text, at = self._text, self._where(*first)
        end = at + len(words[0])
        for word in words[1:]:  # (on one line: only spaces, tabs and the like between)
            found = _NON_SPACE_RE.search(text, end)
            assert found is not None and text.startswith(word, found.start())
            end = found.start() + len(word)
        name = text[at:end]
        if len(name) > MAX_NAME:
            self._too_long(line, name)
        return name

    def _too_long(self, line: int, name: str) -> NoReturn:
        raise error(
            self.file,
            f"line {line}: a joint name of more than {MAX_NAME} characters: {quoted(name)}",
        )

    def floats(self, n: int, what: str) -> list[float]:
        out: list[float] = []
        for _ in range(n):
            line = self.line()
            tok = self.next(what)
            value = as_number(tok)
            if value is None:
                raise error(self.file, f"line {line}: {quoted(what)}: {not_a_number(tok)}")
            out.append(value)
        return out


def fromstring(text: str) -> FloatArray | None:
    """The numbers of ``text`` as numpy's own reader reads them, no Python object per value
    (an 8 MB file: 84 -> 30 MB peak); None where it does not read every word (none of
    whitespace alone, where it reads -1)."""
    try:
        values = np.fromstring(text, dtype=np.float64, sep=" ")
    except ValueError:  # a word numpy does not read
        return None
    return np.zeros(0) if values.size == 1 and text.isspace() else values


def count_words(text: str, end: int | None = None) -> int:
    """``len(text[:end].split())``, split :data:`WINDOW` characters at a time (no list of
    every word: a line of 2 M values took 128 MiB to count)."""
    count, at, end = 0, 0, len(text) if end is None else end
    while at < end:
        cut = min(at + WINDOW, end)
        if cut < end:  # to the next whitespace: no word is cut
            space = _SPACE_RE.search(text, cut, end)
            cut = end if space is None else space.start()
        count += len(text[at:cut].split())
        at = cut
    return count


def motion_values(
    name: str,
    text: str,
    first_line: int,
    values: FloatArray | None,
    columns: list[tuple[str, str]],
    frame: int,
) -> FloatArray:
    """The values of ``text``'s words (numpy's ``values`` where it read them all), each a BVH
    number, else a BVHError naming the first other word, its line, frame (``text``'s first
    is ``frame``) and channel (one regex in C). numpy reads ``nan`` and ``inf`` too, and no
    finite value of any other word (a fuzz: 300,000)."""
    if values is not None and np.isfinite(values).all():
        return values
    numbers = _NUMBERS_RE.match(text)  # (always matches: maybe nothing)
    word = _WORD_RE.search(text, numbers.end() if numbers else 0)
    if word is not None:
        start = word.start()
        line = first_line + text.count("\n", 0, start)
        frame_of, column = divmod(count_words(text, start), len(columns))
        joint, channel = columns[column]
        at = f"frame {frame + frame_of}, channel {clip(joint)}.{channel}"
        shown = text[start : min(word.end(), start + MAX_NAME)]
        raise error(name, f"line {line}: {at}: {not_a_number(shown)}")
    return values if values is not None else np.array(text.split(), dtype=np.float64)


def explain_count(name: str, body: str, first_line: int, n_frames: int, n_channels: int) -> None:
    """Raise a BVHError pointing at the first MOTION line with the wrong number of values,
    else at the block's last line of values (the line before it where it has none), where
    it holds fewer frames than declared (the lines found one at a time: no list of them)."""
    seen, offset, at, last = 0, 0, 0, -1  # (last: the offset of the last line of values)
    while at <= len(body):
        end = body.find("\n", at)
        end = len(body) if end < 0 else end
        line = body[at:end]
        count = len(line.split()) if len(line) <= WINDOW else count_words(line)
        if count and seen >= n_frames:
            raise error(
                name,
                f"line {first_line + offset}: more frame lines than the {clip(n_frames)} "
                "declared in 'Frames:'",
            )
        if count and count != n_channels:
            raise error(
                name,
                f"line {first_line + offset}: expected {n_channels} values per frame, got {count}",
            )
        seen, last = (seen + 1, offset) if count else (seen, last)
        offset, at = offset + 1, end + 1
    ends = f"line {first_line + last}: truncated"  # (where the block ends)
    raise error(name, f"{ends}: 'Frames:' declares {clip(n_frames)} frames, found {seen}")


def after_newlines(text: str, at: int, k: int) -> int:
    """The offset just after the ``k``-th newline of ``text`` from ``at`` (it holds at least
    ``k``; ``at`` itself for 0): spans doubling from ``at`` until one holds it, then a
    bisection on ``str.count`` (in C) and ``str.find`` steps over the last few hundred
    characters (a bisection over all the rest took a clip ~1 ms a frame of 3.6 MB)."""
    lo, lo_n, span = at, 0, 256
    while True:  # the k-th newline: in text[lo:hi]
        hi = min(len(text), lo + span)
        n = text.count("\n", lo, hi)
        if lo_n + n >= k or hi == len(text):
            break
        lo, lo_n, span = hi, lo_n + n, 2 * span
    while hi - lo > 256 and lo_n < k:
        mid = (lo + hi) // 2
        n = lo_n + text.count("\n", lo, mid)
        if n < k:
            lo, lo_n = mid, n
        else:
            hi = mid
    for _ in range(k - lo_n):
        lo = text.find("\n", lo) + 1
    return lo
