"""How an error message quotes a client's input: at most :data:`QUOTE` characters of any
one value (a joint name, a token of a file), so a detail stays short whatever was sent.
Shared by the core's readers and the service's errors (``service.errors``)."""

from __future__ import annotations

import difflib
import itertools
import json
import math
from collections.abc import Iterable

QUOTE = 100  # characters of client input an error detail may quote
_DEPTH = 3  # levels of a nested JSON value a message shows ([[…]] below them)
_ITEMS = 4  # elements of a list or object a message shows (…, then how many in all)
_DIGITS = 30  # digits of an integer a message shows (longer ones: their digit count)


def printable(text: str) -> str:
    """``text`` with any lone surrogate (``"\\ud800"`` is valid JSON; no UTF-8 encodes it)
    written as its escape, so that an answer quoting it can be encoded."""
    if text.isascii():
        return text
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return text.encode("utf-8", "backslashreplace").decode("utf-8")
    return text


def clip(text: object, limit: int = QUOTE) -> str:
    """``text`` as a string of at most ``limit`` characters (``…`` marks a cut), lone
    surrogates escaped. A value that is not a string is shown as :func:`shown` shows it."""
    s = printable(text) if isinstance(text, str) else shown(text)
    return s if len(s) <= limit else s[: limit - 1] + "…"


def shown(value: object, depth: int = _DEPTH) -> str:
    """A value from a client's JSON as JSON writes it (``null``, ``true``, ``[1, 2]``, ``1e300``,
    ``{"x": [null, "a"]}``; its strings in JSON's double quotes, where Python's ``repr``
    wrote ``{'x': [None, 'a']}``: an API audit, 2026-12-07), bounded: strings clipped,
    lists and objects cut after a few elements and a few levels,
    huge integers by their digit count. Never recursive beyond ``depth``: a list nested a
    thousand deep costs three levels (Python's own ``repr`` of it exhausts the stack)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        if abs(value) < 10**_DIGITS:
            return str(value)
        # no str() of it (Python refuses past 4,300 digits): log10(2) per bit, then exact
        digits = max(1, int((value.bit_length() - 1) * 0.30102999566398114))
        while abs(value) >= 10**digits:
            digits += 1
        return f"{'-' if value < 0 else ''}<an integer of {digits} digits>"
    if isinstance(value, float):  # (Python's json: 1e+300, Infinity; a client writes 1e300)
        if math.isnan(value) or math.isinf(value):
            return "NaN" if math.isnan(value) else ("-" if value < 0 else "") + "Infinity"
        return repr(value).replace("e+", "e")
    if isinstance(value, str):  # (JSON's quotes and escapes: ``{"x": 1}``, not ``{'x': 1}``)
        text = value if len(value) <= QUOTE else value[: QUOTE - 1] + "…"
        return json.dumps(text, ensure_ascii=False)
    if isinstance(value, list | tuple | dict):
        opening, closing = ("{", "}") if isinstance(value, dict) else ("[", "]")
        if not value:
            return opening + closing
        if depth <= 0:
            return f"{opening}…{closing}"
        if isinstance(value, dict):
            head = itertools.islice(value.items(), _ITEMS)
            parts = [f"{shown(k, 0)}: {shown(v, depth - 1)}" for k, v in head]
        else:
            parts = [shown(v, depth - 1) for v in itertools.islice(value, _ITEMS)]
        more = f", … {len(value)} in all" if len(value) > _ITEMS else ""
        return opening + ", ".join(parts) + more + closing
    return repr(value)[:QUOTE]


def quoted(value: object) -> str:
    """How a message names what a client sent: a string in quotes, clipped to
    :data:`QUOTE` characters; anything else as :func:`shown` shows it."""
    if isinstance(value, str):  # repr escapes a lone surrogate itself (once: "'\\ud800'")
        return repr(value if len(value) <= QUOTE else value[: QUOTE - 1] + "…")
    return clip(shown(value))


def close_match(name: str, candidates: Iterable[str], cutoff: float = 0.6) -> str | None:
    """The candidate ``name`` was probably meant to be: the same but for case, else the
    closest by :func:`difflib.get_close_matches` (``cutoff``); ``None`` if none is close
    (a map's joint, a setting's variable: "did you mean ...?")."""
    names = list(dict.fromkeys(candidates))
    folded = name.casefold()
    for c in names:
        if c.casefold() == folded:
            return c
    found = difflib.get_close_matches(name, names, n=1, cutoff=cutoff)
    return found[0] if found else None


#: The most characters (the name's length times its candidates' together) a "did you
#: mean" hint compares by spelling; past it, a name is matched for case alone. difflib is
#: pure Python: 8 names of 97 characters against 2,000 joints of 96 took 1.5 s of a
#: request (a review, 2026-12-06); a skeleton of 60 joints of ~12 characters is ~10,000.
SPELLING_WORK = 200_000


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """`` (did you mean 'Hips'?)`` for a name that is a slip of a candidate
    (:func:`near_name`), else ''."""
    near = near_name(name, candidates)
    return f" (did you mean {quoted(near)}?)" if near is not None else ""


def name_key(name: str) -> str:
    """A joint name as a suggestion compares it: no case, ``-`` and each run of blanks
    (spaces, tabs) as ``_``: a file's ``Left  Hand`` for a client's ``Left Hand``."""
    return "_".join(name.lower().replace("-", "_").split())


def near_name(name: str, names: Iterable[str]) -> str | None:
    """The one of ``names`` that ``name`` is a slip of: the same by :func:`name_key`, else
    the one nearest by spelling (difflib's ratio of the keys 0.85 or more: a typo, not a
    neighbour such as 'left_hand' for 'right_hand'), where one alone is nearest; else None.
    Spellings are compared only within :data:`SPELLING_WORK` characters (difflib is pure
    Python). One rule for the names a request gives (the pose form's joints; a character's
    targets, pins, parents and ``joint_map``: they were offered for case alone, or not)."""
    keys: dict[str, str] = {}
    for n in names:
        keys.setdefault(name_key(n), n)
    key = name_key(name)
    if key in keys:
        return keys[key]
    if len(key) * sum(map(len, keys)) > SPELLING_WORK:
        return None
    near = difflib.get_close_matches(key, list(keys), 2, 0.85)
    ratio = [difflib.SequenceMatcher(None, key, n).ratio() for n in near]
    if not near or (len(near) == 2 and ratio[0] == ratio[1]):  # none, or no one nearest
        return None
    return keys[near[0]]
