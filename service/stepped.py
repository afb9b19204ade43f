"""JSON decoded in steps, each holding the GIL briefly, so a big body decoded in a worker
thread never stalls the event loop.

The C decoder (``json.loads``, as orjson) holds the GIL from a value's first byte to its
last; only an object's hook (``object_pairs_hook``) runs Python between. A body of one
long list of numbers or strings was decoded in one hold: 6.5 MiB of ``{"pose": [1.25,
…]}`` kept a ``/v2/health/live`` probe waiting 0.38-0.48 s (a real uvicorn, this 2-core
host; 6.5 MiB of strings ~0.17 s), the loop idle but its thread without the GIL.

Here a container spanning more than ``STEP`` characters is read member by member by the
standard library's own Python readers (``json.decoder.JSONObject``, ``JSONArray``: the
same values and the same error messages, at the same places), and every smaller value by
the C decoder in one call. The containers' spans come from a vectorised pass over the
bytes (numpy: the GIL released): quotes not escaped pair into strings, brackets outside
them pair by depth. A body that is not well formed only makes a span wrong, which never
changes what is decoded or which error is raised, only how it is cut into steps.
"""

from __future__ import annotations

import json
import json.decoder
import json.scanner
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

#: Characters one C call decodes at most, but for a single string or number (a string is
#: copied at ~1 GB/s): the slowest shape measured, empty lists, ~0.2 µs a byte (~13 ms).
STEP = 64 * 1024

Hook = Callable[[list[tuple[str, Any]]], Any]
_PY: Any = json.decoder  # the standard library's Python readers (untyped)
_WS = _PY.WHITESPACE.match
_C_SCANNER: Any = json.scanner.c_make_scanner  # type: ignore[attr-defined]


def plan(body: bytes | memoryview) -> frozenset[int]:
    """Where (character offsets) the objects and arrays of ``body`` (UTF-8 JSON text) that
    span more than ``STEP`` bytes open, one never closed counting as spanning to the end:
    what :func:`loads` reads member by member. Called before the text is decoded (its
    arrays, ~30 bytes a bracket, are freed before the decoding's objects are made)."""
    if len(body) <= STEP:
        return frozenset()
    return frozenset(_big_containers(body).tolist())


def loads(text: str, big: frozenset[int], object_pairs_hook: Hook) -> Any:
    """``json.loads(text, object_pairs_hook=...)``, the containers opening at ``big``
    (:func:`plan`) read member by member, every other value by the C decoder at once
    (raises ``json.JSONDecodeError`` as ``json.loads`` does, at the same place)."""
    if not big:
        return json.loads(text, object_pairs_hook=object_pairs_hook)
    keys: dict[str, str] = {}  # one string for each key (the C decoder's memo is per call)

    def hook(pairs: list[tuple[str, Any]]) -> Any:  # (an object the C decoder read)
        for i, (k, v) in enumerate(pairs):
            if (shared := keys.setdefault(k, k)) is not k:
                pairs[i] = (shared, v)
        return object_pairs_hook(pairs)

    whole = _C_SCANNER(json.JSONDecoder(object_pairs_hook=hook))

    def scan_once(s: str, idx: int) -> tuple[Any, int]:
        if idx not in big:
            return whole(s, idx)  # type: ignore[no-any-return]
        if s[idx] == "{":
            return _PY.JSONObject(  # type: ignore[no-any-return]
                (s, idx + 1), True, scan_once, None, object_pairs_hook, keys
            )
        return _PY.JSONArray((s, idx + 1), scan_once)  # type: ignore[no-any-return]

    idx = _WS(text, 0).end()
    try:
        value, end = scan_once(text, idx)
    except StopIteration as err:
        raise json.JSONDecodeError("Expecting value", text, err.value) from None
    end = _WS(text, end).end()
    if end != len(text):
        raise json.JSONDecodeError("Extra data", text, end)
    return value


def _where(mask: npt.NDArray[np.bool_]) -> npt.NDArray[np.int32]:
    out: npt.NDArray[np.int32] = np.flatnonzero(mask).astype(np.int32)
    return out


def _big_containers(body: bytes | memoryview) -> npt.NDArray[np.int64]:
    """:func:`plan`'s offsets: quotes not escaped pair into strings; brackets outside them
    pair by depth (an open and its close share a level, and alternate within it)."""
    a = np.frombuffer(body, dtype=np.uint8)
    quotes = _where(a == ord('"'))
    slashes = _where(a == ord("\\"))
    if slashes.size and quotes.size:  # a quote after an odd run of backslashes is escaped
        run_start = np.r_[True, np.diff(slashes) != 1]
        first = slashes[np.maximum.accumulate(np.where(run_start, np.arange(slashes.size), 0))]
        at = np.maximum(np.searchsorted(slashes, quotes) - 1, 0)
        escaped = (slashes[at] == quotes - 1) & ((quotes - first[at]) % 2 == 1)
        quotes = quotes[~escaped]
        del run_start, first, at, escaped
    del slashes
    mask = a == ord("[")
    mask |= a == ord("{")
    mask |= a == ord("]")
    mask |= a == ord("}")
    pos = _where(mask)
    del mask
    pos = pos[np.searchsorted(quotes, pos) % 2 == 0]  # outside strings
    del quotes
    char = a[pos]
    step = np.where((char == ord("[")) | (char == ord("{")), 1, -1).astype(np.int8)
    del char
    level = np.cumsum(step, dtype=np.int32)  # the depth after each bracket
    below = np.flatnonzero(level < 0)
    if below.size:  # a close with no open: the body is not well formed by there
        pos, step, level = pos[: below[0]], step[: below[0]], level[: below[0]]
    level[step < 0] += 1  # a close's level: the depth before it
    order = np.argsort(level, kind="stable")  # by level, in order of place within one
    del level
    pos, is_open = pos[order], step[order] > 0
    del order, step
    # (a level's last event may be an open never closed; the next level's first is an open)
    closed = np.zeros(pos.size, dtype=np.bool_)
    closed[:-1] = is_open[:-1] & ~is_open[1:]
    ends = np.full(pos.size, a.size, dtype=np.int64)
    ends[:-1][closed[:-1]] = pos[1:][closed[:-1]]
    big: npt.NDArray[np.int64] = pos[is_open & (ends - pos > STEP)].astype(np.int64)
    if int(a.max(initial=0)) >= 0x80:  # byte offsets to character offsets
        cont = np.flatnonzero((a & 0xC0) == 0x80)
        big -= np.searchsorted(cont, big)
    return big
