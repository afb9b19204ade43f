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

import bisect
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

#: Bytes of the body looked at for commas at once (a whole number of quarter steps).
_CHUNK = 256 * 1024
Hook = Callable[[list[tuple[str, Any]]], Any]
_PY: Any = json.decoder  # the standard library's Python readers (untyped)
_WS = _PY.WHITESPACE.match
_BLANK = _PY.WHITESPACE_STR
_C_SCANNER: Any = json.scanner.c_make_scanner  # type: ignore[attr-defined]


Plan = dict[int, list[int]]


def plan(body: bytes | memoryview) -> Plan:
    """Where (character offsets) the objects and arrays of ``body`` (UTF-8 JSON text) that
    span more than ``STEP`` bytes open, one never closed counting as spanning to the end:
    what :func:`loads` reads member by member; for an array, some of the commas between
    its members, where a run of them may end (~``STEP`` / 4 apart). Called before the text
    is decoded (its arrays, ~30 bytes a bracket or comma, are freed before the decoding's
    objects are made)."""
    if len(body) <= STEP:
        return {}
    return _big_containers(body)


def loads(text: str, big: Plan, object_pairs_hook: Hook) -> Any:
    """``json.loads(text, object_pairs_hook=...)``, the containers opening at ``big``
    (:func:`plan`) read member by member (an array's in runs of up to ``STEP`` characters
    where they read as one), every other value by the C decoder at once (raises
    ``json.JSONDecodeError`` as ``json.loads`` does, at the same place)."""
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
        return array(s, idx + 1, big[idx])

    def run(s: str, start: int, cuts: list[int]) -> tuple[list[Any], int] | None:
        """The members from ``start`` to the last of ``cuts`` within ``STEP`` of it, read by
        the C decoder as one array, and that comma's place; None if they do not read so
        (the members are then read one by one, which raises where ``json.loads`` would)."""
        k = bisect.bisect_right(cuts, start + STEP) - 1
        if k < 0 or cuts[k] <= start:
            return None
        try:
            value, end = whole("[" + s[start : cuts[k]] + "]", 0)
        except Exception:  # (any: read again one by one, it is raised as it would be)
            return None
        return (value, cuts[k]) if end == cuts[k] - start + 2 else None

    def array(s: str, end: int, cuts: list[int]) -> tuple[list[Any], int]:
        """``json.decoder.JSONArray``, but for its runs of members (:func:`run`)."""
        values: list[Any] = []
        nextchar = s[end : end + 1]
        if nextchar in _BLANK:
            end = _WS(s, end + 1).end()
            nextchar = s[end : end + 1]
        if nextchar == "]":
            return values, end + 1
        while True:
            if cuts and (got := run(s, end, cuts)) is not None:
                values += got[0]
                end = got[1]
                nextchar = ","
            else:
                try:
                    value, end = scan_once(s, end)
                except StopIteration as err:
                    raise json.JSONDecodeError("Expecting value", s, err.value) from None
                values.append(value)
                nextchar = s[end : end + 1]
                if nextchar in _BLANK:
                    end = _WS(s, end + 1).end()
                    nextchar = s[end : end + 1]
            end += 1
            if nextchar == "]":
                break
            if nextchar != ",":
                raise json.JSONDecodeError("Expecting ',' delimiter", s, end - 1)
            end = _WS(s, end).end()
        return values, end

    idx = _WS(text, 0).end()
    try:
        value, end = scan_once(text, idx)
    except StopIteration as err:
        raise json.JSONDecodeError("Expecting value", text, err.value) from None
    end = _WS(text, end).end()
    if end != len(text):
        raise json.JSONDecodeError("Extra data", text, end)
    return value


def _where(a: npt.NDArray[np.uint8], chars: bytes) -> npt.NDArray[np.int32]:
    """Where in ``a`` any of ``chars`` stand, a ``_CHUNK`` at a time (4 bytes a place, not
    numpy's 8, nor a mask of the whole body besides)."""
    found = []
    for lo in range(0, a.size, _CHUNK):
        part = a[lo : lo + _CHUNK]
        mask = part == chars[0]
        for c in chars[1:]:
            mask |= part == c
        found.append(np.flatnonzero(mask).astype(np.int32) + np.int32(lo))
    out: npt.NDArray[np.int32] = np.concatenate(found) if found else np.zeros(0, np.int32)
    return out


def _cuts(
    a: npt.NDArray[np.uint8],
    quotes: npt.NDArray[np.int32],
    pos: npt.NDArray[np.int32],
    depth_after: npt.NDArray[np.int32],
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32]]:
    """The commas outside strings where a run of an array's members may end: at each depth,
    the last in each quarter ``STEP`` of the body; with their depths (the array's own: the
    depth after the bracket before them, ``pos`` and ``depth_after``), ordered by depth,
    then place. Found a ``_CHUNK`` of the body at a time (a body of commas would take ~30
    bytes a comma at once)."""
    found, depths = [], []
    quarter = STEP // 4
    for lo in range(0, a.size, _CHUNK):
        at = _where(a[lo : lo + _CHUNK], b",") + np.int32(lo)
        at = at[np.searchsorted(quotes, at) % 2 == 0]
        before = np.searchsorted(pos, at)
        depth = np.where(before > 0, depth_after[np.maximum(before, 1) - 1], 0).astype(np.int32)
        order = np.argsort(depth, kind="stable")
        at, depth = at[order], depth[order]
        last = np.ones(at.size, dtype=np.bool_)
        bucket = at // quarter
        last[:-1] = (bucket[1:] != bucket[:-1]) | (depth[1:] != depth[:-1])
        found.append(at[last])
        depths.append(depth[last])
    at, depth = np.concatenate(found), np.concatenate(depths)
    order = np.argsort(depth, kind="stable")
    return at[order], depth[order]


def _big_containers(body: bytes | memoryview) -> Plan:
    """:func:`plan`'s offsets: quotes not escaped pair into strings; brackets outside them
    pair by depth (an open and its close share a level, and alternate within it); a comma
    outside them is a member's end in the container last opened at its depth."""
    a = np.frombuffer(body, dtype=np.uint8)
    quotes = _where(a, b'"')
    slashes = _where(a, b"\\")
    if slashes.size and quotes.size:  # a quote after an odd run of backslashes is escaped
        run_start = np.r_[True, np.diff(slashes) != 1]
        first = slashes[np.maximum.accumulate(np.where(run_start, np.arange(slashes.size), 0))]
        at = np.maximum(np.searchsorted(slashes, quotes) - 1, 0)
        escaped = (slashes[at] == quotes - 1) & ((quotes - first[at]) % 2 == 1)
        quotes = quotes[~escaped]
        del run_start, first, at, escaped
    del slashes
    pos = _where(a, b"[{]}")
    pos = pos[np.searchsorted(quotes, pos) % 2 == 0]  # outside strings
    char = a[pos]
    step = np.where((char == ord("[")) | (char == ord("{")), 1, -1).astype(np.int8)
    del char
    level = np.cumsum(step, dtype=np.int32)  # the depth after each bracket
    below = np.flatnonzero(level < 0)
    if below.size:  # a close with no open: the body is not well formed by there
        pos, step, level = pos[: below[0]], step[: below[0]], level[: below[0]]
    commas, depth = _cuts(a, quotes, pos, level)
    del quotes
    level[step < 0] += 1  # a close's level: the depth before it
    order = np.argsort(level, kind="stable")  # by level, in order of place within one
    pos, is_open, level = pos[order], step[order] > 0, level[order]
    del order, step
    # (a level's last event may be an open never closed; the next level's first is an open)
    closed = np.zeros(pos.size, dtype=np.bool_)
    closed[:-1] = is_open[:-1] & ~is_open[1:]
    ends = np.full(pos.size, a.size, dtype=np.int64)
    ends[:-1][closed[:-1]] = pos[1:][closed[:-1]]
    big = np.flatnonzero(is_open & (ends - pos > STEP))
    opens, until, levels = pos[big].astype(np.int64), ends[big], level[big]
    wide = int(a.max(initial=0)) >= 0x80
    cont = np.flatnonzero((a & 0xC0) == 0x80) if wide else None

    def chars(x: npt.NDArray[Any]) -> list[int]:  # byte offsets to character offsets
        x = x.astype(np.int64)
        out: list[int] = (x - np.searchsorted(cont, x) if cont is not None else x).tolist()
        return out

    out: Plan = {}
    for p, e, lv, at_open in zip(
        chars(opens), until.tolist(), levels.tolist(), opens.tolist(), strict=True
    ):
        if a[at_open] != ord("["):
            out[p] = []
            continue
        lo, hi = np.searchsorted(depth, [lv, lv + 1])
        group = commas[lo:hi]
        inside = group[np.searchsorted(group, at_open) : np.searchsorted(group, e)]
        out[p] = chars(inside)
    return out
