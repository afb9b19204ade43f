"""The columnar form of ``POST /v1/solve/batch``: arrays in, arrays out, no per-item
Python objects (docs/limits.md, "The columnar batch").

The body is decoded by orjson into lists, turned into numpy arrays at once and checked
vectorised (shapes, finite numbers, bounds, joint names -> indices, repeats, degenerate
poses); the batch is solved by ``Engine.solve_arrays`` in priced parts and answered with
JSON built from the answer arrays (orjson serialises numpy arrays directly). Every error
names the offending item and field (``poses[17][4]: must be a finite number``), in the
notation and with the messages of the pydantic field errors (``service.errors``).
"""

from __future__ import annotations

import base64
import binascii
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import orjson
from pydantic import ValidationError

from core.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS
from service.bounded import context, errors_of
from service.engine import Engine
from service.errors import MAX_ERRORS, BodyInvalid, too_many_items
from service.field_names import offered, slip_of
from service.limits import Pricing, chunks_of, searched_price
from service.problems import BatchAnswer
from service.responses import starts_warnings
from service.schemas import MAX_COORDINATE, MAX_WEIGHT, SolveOptions
from service.validation import check_bones, check_options, pin_weights

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
WIDTH = 3 * NUM_JOINTS  # numbers per pose row
_FLOAT_MAX = int(np.finfo(np.float64).max)  # a JSON integer beyond it is no float
#: The columnar form's keys (a body with these and ``items`` is in both forms: a 422).
TOP = ("poses", "targets", "pins", "options")
#: A packed column (``poses``, ``targets.positions``): its numbers as one base64 string
#: (RFC 4648, padded) of little-endian float64, row after row; a batch sent with packed
#: ``poses`` is answered with packed ``poses`` (docs/limits.md, "The columnar batch").
PACKED = np.dtype("<f8")
_ROW_BYTES = WIDTH * PACKED.itemsize  # 504: a pose's, a multiple of 3 (no base64 padding)
_TARGETS = ("joints", "positions", "weights")


class _Errors:
    """Field errors in pydantic's shape (``loc``, ``type``, ``msg``, ``ctx``, ``input``),
    so that ``service.errors.validation_problem`` words them as for the other forms."""

    def __init__(self) -> None:
        self.raw: list[dict[str, Any]] = []
        self.total = 0  # errors found, kept or not (the first MAX_ERRORS are kept)
        self.partial = False  # the look stopped before the body's end: more may follow

    def add(self, loc: tuple[Any, ...], kind: str, msg: str, **extra: Any) -> None:
        self.total += 1
        if len(self.raw) < MAX_ERRORS:
            self.raw.append({"loc": loc, "type": kind, "msg": msg, **extra})

    def add_all(self, where: npt.NDArray[np.intp], error: Callable[[int, int], None]) -> None:
        """``error(b, i)`` for the first MAX_ERRORS of ``where`` (``np.argwhere`` rows);
        the others counted."""
        for b, i in where[:MAX_ERRORS].tolist():
            error(b, i)
        self.total += max(0, len(where) - MAX_ERRORS)

    def raise_any(self) -> None:
        if self.raw:
            raise BodyInvalid(self.raw, self.total, self.partial)


def is_columnar(data: Any) -> bool:
    """The columnar form is told from the item list by its ``poses`` key."""
    return isinstance(data, dict) and "poses" in data and "items" not in data


@dataclass(frozen=True)
class Columns:
    """A validated columnar batch: B items, K targets and P pins each."""

    poses: F64  # [B, 21, 3]
    tidx: I64  # [B, K + P] targets, then pins
    tpos: F64  # [B, K + P, 3]
    weights: F64  # [B, K + P]
    n_targets: int
    n_pins: int
    options: SolveOptions
    packed: bool = False  # poses sent packed (:data:`PACKED`): answered packed

    @property
    def size(self) -> int:
        return int(self.poses.shape[0])

    def parts(self, pricing: Pricing) -> list[slice]:
        """Priced parts (``service.limits``): every item costs the same here (``pricing``:
        the engine's, ``Pricing.of``)."""
        each = searched_price(self.options, self.n_targets, self.n_pins > 0, pricing)
        return chunks_of([each] * self.size)


def _shared(row: list[Any], loc: tuple[Any, ...], width: int, n: int, errs: _Errors,
            suspect: bool) -> F64 | None:  # fmt: skip
    """One row of ``width`` numbers shared by all ``n`` items, as ``[n, width]``; its
    errors are named where they are (``targets.weights[0]``), once, not once per item."""
    one = _Errors()
    got = _numbers([row], loc, width, 1, one, suspect, None)
    for e in one.raw:  # drop the row index _numbers gave them
        extra = {key: v for key, v in e.items() if key not in ("loc", "type", "msg")}
        errs.add((*loc, *e["loc"][len(loc) + 1 :]), e["type"], e["msg"], **extra)
    errs.total += one.total - len(one.raw)  # those found past the ones kept
    errs.partial = errs.partial or one.partial
    return None if got is None else np.repeat(got, n, axis=0)


def _meant(key: Any, fields: Iterable[str]) -> dict[str, Any]:
    """An unknown key's context: the field it is a slip of, as the item list's
    (``service.field_names``), where one is."""
    meant = slip_of(key, list(fields))
    return {} if meant is None else {"ctx": {"meant": meant}}


def _n(count: int, noun: str) -> str:
    """``count`` ``noun`` s, in words: ``1 pose``, ``2 poses``, ``0 rows``."""
    return f"{count} {noun}{'' if count == 1 else 's'}"


def _numbers(rows: Any, loc: tuple[Any, ...], width: int, n: int, errs: _Errors,
             suspect: bool, bound: float | None = MAX_COORDINATE) -> F64 | None:  # fmt: skip
    """``rows`` (a list of ``n`` lists of ``width`` numbers) as a ``[n, width]`` array, or
    None with the errors added. ``suspect``: the body may hold booleans among numbers
    (numpy would take ``true`` for 1.0), so every element's type is checked."""
    if isinstance(rows, str):
        got = _unpack(rows, loc, width, n, errs)
        return None if got is None else _checked(got, loc, errs, bound)
    if not isinstance(rows, list):
        errs.add(loc, "list_type", "Input should be a valid list", input=rows)
        return None
    if len(rows) != n:
        if rows and not isinstance(rows[0], list):  # one row, as joints and weights may be
            errs.add(loc, "rows", f"a list of {_n(n, 'row')} (one per pose), not one row of "
                     f"{_n(len(rows), 'number')}: {loc[-1]} are never shared")  # fmt: skip
        else:
            errs.add(loc, "rows", f"{_n(len(rows), 'row')} for {_n(n, 'pose')}: one row per pose")
        return None
    arr: np.ndarray[Any, Any] | None = None
    if not suspect:
        try:
            arr = np.array(rows)
        except ValueError:  # ragged rows
            arr = None
    if arr is None or arr.dtype.kind not in "fi" or arr.shape != (n, width):
        for b, row in enumerate(rows):  # the precise (slow) look, only for a bad body
            if not isinstance(row, list):
                errs.add((*loc, b), "list_type", "Input should be a valid list", input=row)
            elif len(row) != width:
                errs.add(
                    (*loc, b),
                    "row_length",
                    f"must hold {_n(width, 'number')}, got {len(row)}",
                )
            else:
                for i, v in enumerate(row):
                    no_number = type(v) is not float and type(v) is not int
                    if no_number or (type(v) is int and not -_FLOAT_MAX < v < _FLOAT_MAX):
                        msg = "Input should be a valid number"  # (an int: 309+ digits)
                        errs.add((*loc, b, i), "float_type", msg, input=v)
            if len(errs.raw) >= MAX_ERRORS:
                errs.partial = b + 1 < len(rows)
                break
        if errs.raw:
            return None
        arr = np.array(rows, dtype=np.float64)
    return _checked(np.ascontiguousarray(arr, dtype=np.float64), loc, errs, bound)


def _packed_rows(value: str, width: int) -> int:
    """How many rows of ``width`` numbers a packed column's base64 text holds, read off
    its length (a 413 is said before it is decoded)."""
    return (len(value) * 3 // 4) // (width * PACKED.itemsize)


def _unpack(value: str, loc: tuple[Any, ...], width: int, n: int | None, errs: _Errors
            ) -> F64 | None:  # fmt: skip
    """A packed column (:data:`PACKED`) of ``n`` rows of ``width`` numbers (None: as many
    as it holds, ``poses``) as a ``[n, width]`` array, or None with the error added."""
    try:
        raw = base64.b64decode(value, validate=True)
    except (binascii.Error, ValueError):  # (ValueError: a character beyond ASCII)
        errs.add(loc, "packed", "a packed column is base64 (RFC 4648, padded, no line breaks) "
                 "of little-endian float64 numbers, row after row")  # fmt: skip
        return None
    row = width * PACKED.itemsize
    if n is None:
        if len(raw) % row:
            errs.add(loc, "rows", f"{_n(len(raw), 'byte')} packed: not whole rows of "
                     f"{_n(width, 'float64 number')} ({row} bytes each)")  # fmt: skip
            return None
        n = len(raw) // row
    elif len(raw) != n * row:
        numbers = _n(width, "float64 number")
        errs.add(loc, "rows", f"{_n(len(raw), 'byte')} packed for {_n(n, 'pose')}: one row "
                 f"of {numbers} ({row} bytes) per pose, {n * row} bytes")  # fmt: skip
        return None
    return np.frombuffer(raw, dtype=PACKED).astype(np.float64).reshape(n, width)


def _checked(out: F64, loc: tuple[Any, ...], errs: _Errors, bound: float | None) -> F64 | None:
    """``out`` where every number is finite and within ``bound``, else None with the errors
    added, naming each (``poses[17][4]``)."""
    bad = ~np.isfinite(out)
    if bad.any():
        errs.add_all(
            np.argwhere(bad),
            lambda b, i: errs.add((*loc, b, i), "finite_number", "Input should be a finite number"),
        )
        return None
    far = np.abs(out) > (np.inf if bound is None else bound)
    if far.any():

        def beyond(b: int, i: int) -> None:
            v = float(out[b, i])
            kind, key = ("less_than_equal", "le") if v > 0 else ("greater_than_equal", "ge")
            sign = MAX_COORDINATE if v > 0 else -MAX_COORDINATE
            errs.add((*loc, b, i), kind, f"beyond {sign:g}", ctx={key: sign}, input=v)

        errs.add_all(np.argwhere(far), beyond)
        return None
    return out


def _names(value: Any, loc: tuple[Any, ...], n: int, errs: _Errors, least: int
           ) -> I64 | None:  # fmt: skip
    """Joint names, shared (a list of names) or per item (``n`` rows of as many names),
    as ``[n, k]`` canonical indices; unknown names are errors naming where."""
    if not isinstance(value, list):
        errs.add(loc, "list_type", "Input should be a valid list of joint names", input=value)
        return None
    shared = not value or not isinstance(value[0], list)
    rows = [value] if shared else value
    if not shared and len(rows) != n:
        errs.add(loc, "rows", f"{_n(len(rows), 'row')} for {_n(n, 'pose')}: one row per pose")
        return None
    k = len(rows[0])
    if not all(isinstance(r, list) and len(r) == k for r in rows):
        errs.add(loc, "rows", "rows of joint names, all of one length")
        return None
    if not least <= k <= NUM_JOINTS:
        errs.add(loc, "length", f"from {least} to {NUM_JOINTS} joints per item, got {k}")
        return None
    idx = np.array(
        [[JOINT_INDEX.get(x, -1) if type(x) is str else -1 for x in r] for r in rows],
        dtype=np.int64,
    ).reshape(len(rows), k)
    if (idx < 0).any():

        def unknown(b: int, i: int) -> None:
            where = (*loc, i) if shared else (*loc, b, i)
            errs.add(where, "literal_error", "unknown joint", ctx={"expected": "'spine1'"},
                     input=rows[b][i])  # fmt: skip

        errs.add_all(np.argwhere(idx < 0), unknown)
        return None
    out: I64 = np.require(np.broadcast_to(idx, (n, k)), requirements=["C", "W"])
    return out


def _repeats(tidx: I64, k: int, shared_t: bool, shared_p: bool) -> None:
    """A joint targeted twice, pinned twice or both is a 422 naming every such row (its
    first repeat; the first ``MAX_ERRORS`` rows, the others counted, as the item list's
    ``service.errors.every_item``); one in joints every item shares, once."""
    s = np.sort(tidx, axis=1)
    rep = (s[:, 1:] == s[:, :-1]).any(axis=1)
    if not rep.any():
        return
    errs = _Errors()
    told: set[tuple[int, int]] = set()  # repeats in shared joints, told once
    for b in np.flatnonzero(rep).tolist():
        row = tidx[b].tolist()
        i = next(i for i, j in enumerate(row) if j in row[:i])
        first = row.index(row[i])
        name = JOINT_NAMES[row[i]]
        loc: tuple[Any, ...]
        if i < k:
            msg = f"duplicate target for joint {name!r}"
            loc = ("targets", "joints", i) if shared_t else ("targets", "joints", b, i)
        else:
            loc = ("pins", i - k) if shared_p else ("pins", b, i - k)
            both = first < k
            msg = f"joint {name!r} is both pinned and targeted" if both else (
                f"joint {name!r} is pinned twice")  # fmt: skip
        if all(shared_t if x < k else shared_p for x in (first, i)):  # every item's
            if (first, i) not in told:
                told.add((first, i))
                errs.add(loc, "repeat", f"{msg} (every item)")
            continue
        errs.add(loc, "repeat", f"{msg} (item {b})")
    errs.raise_any()


def parse(data: dict[str, Any], max_items: int, suspect: bool = True) -> Columns:
    """Validate a decoded columnar body into :class:`Columns`; raises ``BodyInvalid``
    (422, field errors), ``TooManyItems`` (413) or ``InvalidRequest`` (422)."""
    errs = _Errors()
    for key in data:
        if key not in TOP:
            errs.add(
                (key,), "extra_forbidden", "Extra inputs are not permitted", **_meant(key, TOP)
            )
    targets = data.get("targets")
    for key in ("poses", "targets"):
        if key not in data:
            errs.add((key,), "missing", "Field required")
    errs.raise_any()
    rows = data["poses"]
    packed = isinstance(rows, str)
    n = len(rows) if isinstance(rows, list) else _packed_rows(rows, WIDTH) if packed else 0
    if n > max_items:  # (a packed column's count read off its length, before decoding)
        raise too_many_items("poses", n, max_items)
    if isinstance(rows, list) and n == 0:
        errs.add(
            ("poses",), "too_short", "List should have at least 1 item after validation, not 0"
        )  # pydantic's
    errs.raise_any()
    if packed:
        got = _unpack(rows, ("poses",), WIDTH, None, errs)
        n = 0 if got is None else len(got)
        if got is not None and n == 0:
            errs.add(("poses",), "too_short", f"at least one pose packed: {_ROW_BYTES} bytes, "
                     f"{_ROW_BYTES * 4 // 3} base64 characters")  # fmt: skip
        errs.raise_any()
        poses = _checked(got, ("poses",), errs, MAX_COORDINATE) if got is not None else None
    else:
        poses = _numbers(rows, ("poses",), WIDTH, n, errs, suspect)
    if not isinstance(targets, dict):
        errs.add(
            ("targets",),
            "model_type",  # pydantic's words, as the other forms have them
            "Input should be a valid dictionary or instance of ColumnarTargets",
            input=targets,  # (service.errors words it: a JSON object is required, not ...)
        )
        errs.raise_any()
        raise AssertionError  # unreachable
    for key in targets:
        if key not in _TARGETS:
            errs.add(("targets", key), "extra_forbidden", "Extra inputs are not permitted",
                     **_meant(key, _TARGETS))  # fmt: skip
    for key in ("joints", "positions"):
        if key not in targets:
            errs.add(("targets", key), "missing", "Field required")
    errs.raise_any()
    tj = _names(targets["joints"], ("targets", "joints"), n, errs, 1)
    pj = _names(data.get("pins", []), ("pins",), n, errs, 0)
    try:
        given = data.get("options", {})
        options = SolveOptions.model_validate(given, context=(ctx := context()))
    except ValidationError as exc:
        shown, total, partial = errors_of(exc, ctx, given)
        offered(shown, SolveOptions, given)  # (an unknown key's "did you mean")
        for e in shown:
            errs.add(("options", *e["loc"]), e["type"], e["msg"], ctx=e.get("ctx"),
                     input=e.get("input"))  # fmt: skip
        errs.total += total - len(shown)
        errs.partial = errs.partial or partial
    errs.raise_any()
    assert poses is not None and tj is not None and pj is not None
    k, p = tj.shape[1], pj.shape[1]
    check_options(options, p > 0)  # (as every other form's, by problem_of)
    goals = _numbers(targets["positions"], ("targets", "positions"), 3 * k, n, errs, suspect)
    weights = np.ones((n, k))  # (the pins' columns added below: pin_weights)
    if targets.get("weights") is not None:
        w = targets["weights"]
        shared = isinstance(w, list) and bool(w) and not isinstance(w[0], list)
        got = None
        if isinstance(w, str):  # (packed are only poses and positions: the schema's)
            errs.add(("targets", "weights"), "list_type", "not packed", input=w)
        elif shared:
            got = _shared(w, ("targets", "weights"), k, n, errs, suspect)
        else:
            got = _numbers(w, ("targets", "weights"), k, n, errs, suspect, None)
        if got is not None and not ((got > 0) & (got <= MAX_WEIGHT)).all():
            weights_in = got[:1] if shared else got

            def weight(b: int, i: int) -> None:  # pydantic's words (the item list's)
                loc = ("targets", "weights", i) if shared else ("targets", "weights", b, i)
                v = float(weights_in[b, i])
                if v <= 0:
                    errs.add(loc, "greater_than", "Input should be greater than 0", input=v)
                else:
                    most = f"Input should be less than or equal to {MAX_WEIGHT:g}"
                    errs.add(loc, "less_than_equal", most, input=v)

            errs.add_all(np.argwhere(~((weights_in > 0) & (weights_in <= MAX_WEIGHT))), weight)
        if got is not None:
            weights[:] = got
    weights = pin_weights(weights, p)
    errs.raise_any()
    assert goals is not None
    tidx = np.concatenate([tj, pj], axis=1)
    _repeats(tidx, k, not isinstance(targets["joints"][0], list),
             not (data.get("pins") and isinstance(data["pins"][0], list)))  # fmt: skip
    pose3 = poses.reshape(n, NUM_JOINTS, 3)
    check_bones(pose3, lambda b: f"poses[{b}]")
    tpos = np.concatenate([goals.reshape(n, k, 3), np.take_along_axis(pose3, pj[:, :, None], 1)],
                          axis=1)  # fmt: skip
    return Columns(pose3, tidx, tpos, weights, k, p, options, packed)


@dataclass(frozen=True)
class Part:
    """A part's answers, and its answered poses already written as the answer's JSON rows
    (in the compute thread that solved them, beside the other parts: the rows are most of
    the answer's bytes, 1.5 of a 1,024-edit batch's 1.8 ms of writing)."""

    ans: BatchAnswer
    poses: bytes  # a JSON list of rows of WIDTH numbers


def solve(engine: Engine, cols: Columns, part: slice) -> Part:
    """One part of the batch, as arrays."""
    o = cols.options
    ans = engine.solve_arrays(
        cols.poses[part], cols.tidx[part], cols.tpos[part], n_targets=cols.n_targets,
        weights=cols.weights[part], fabrik=o.method == "fabrik",
        preserve_bone_lengths=o.preserve_bone_lengths, exact=o.reach == "exact",
        tolerance=o.tolerance, floor=o.floor, passes=o.passes, carry=o.carry,
        turn_search=o.turn_search is not False, mirror=o.mirror, soft_ik=o.soft_ik,
    )  # fmt: skip
    rows = np.ascontiguousarray(ans.pose, dtype=np.float64).reshape(len(ans.pose), WIDTH)
    if cols.packed:  # (a part's base64 is whole: 504 bytes a row, no padding to join)
        return Part(ans, b'"' + base64.b64encode(rows.astype(PACKED, copy=False).tobytes()) + b'"')
    return Part(ans, orjson.dumps(rows, option=orjson.OPT_SERIALIZE_NUMPY))


def merge(parts: Sequence[Part]) -> Part:
    """The answers of consecutive parts as one (solver paths renumbered)."""
    if len(parts) == 1:
        return parts[0]
    ends = np.cumsum([len(p.ans.pose) for p in parts])
    rows = [np.arange(e - len(p.ans.pose), e) for p, e in zip(parts, ends, strict=True)]
    ans = BatchAnswer.scatter(int(ends[-1]), [(r, p.ans) for r, p in zip(rows, parts, strict=True)])
    if parts[0].poses[:1] == b'"':  # packed: the parts' base64 joined (each whole)
        return Part(ans, b'"' + b"".join(p.poses[1:-1] for p in parts) + b'"')
    poses = b"[" + b",".join(p.poses[1:-1] for p in parts if len(p.ans.pose)) + b"]"
    return Part(ans, poses)


def answer(cols: Columns, part: Part, version: str) -> bytes:
    """The columnar answer, encoded from the arrays (no per-item objects), its poses the
    rows :func:`solve` wrote."""
    ans = part.ans
    k, p = cols.n_targets, cols.n_pins
    errors = np.ascontiguousarray(ans.errors[:, :k], dtype=np.float64)
    said = starts_warnings(cols.poses, cols.options.floor)  # each row's start pose's
    body = {
        "errors": errors,
        "reached": errors <= cols.options.tolerance,
        "pin_errors": np.ascontiguousarray(ans.errors[:, k : k + p], dtype=np.float64),
        "max_bone_length_error": np.ascontiguousarray(ans.max_bone_error, dtype=np.float64),
        "iterations": np.ascontiguousarray(ans.iterations, dtype=np.int64),
        "solvers": [list(path) for path in ans.paths],
        "solver_of": np.ascontiguousarray(ans.path_of, dtype=np.int64),
        "model": version,
        "method": "fabrik" if cols.options.method == "fabrik" else "neural",
        "floor": cols.options.floor,
        "up_warning": [w[0] for w in said],
        "floor_warning": [w[1] for w in said],
        "handedness_warning": [w[2] for w in said],
    }
    rest = orjson.dumps(body, option=orjson.OPT_SERIALIZE_NUMPY)
    return b'{"poses":' + part.poses + b"," + rest[1:]
