"""Bounded validation: what an invalid body costs grows with the errors a problem shows
(``MAX_ERRORS``), not with how many errors the body holds.

pydantic keeps one record for every error of a body, and a body of 8 MiB can hold
millions: an object with 700,000 unknown keys, 990 items of 2,000 empty joints (2 errors
per 3 bytes). Built, turned into dicts and worded, they took seconds and gigabytes while
a problem lists 20. Every request model (:class:`Bounded`) validates under an
:class:`ErrorBudget` passed in pydantic's validation context (:func:`context`), which
keeps pydantic's own errors, in its own order, only where they can be shown:

- an object's unknown keys past its first ``MAX_ERRORS`` are counted, not validated (each
  is one ``extra_forbidden`` error, and pydantic lists them after all the object's others);
- a model validated once ``MAX_ERRORS`` errors before it are known is validated, its
  errors counted and replaced by one stand-in error (none of its errors can be shown);
- once ``COUNT_LIMIT`` errors are known, a model not yet validated is not looked at: the
  count becomes "at least" (the partial count the columnar form gives too).

So a problem names the same first errors, worded as before, and the same total (up to
``COUNT_LIMIT``); :func:`errors_of` reads them. The hot path's own look at a body, which
only asks whether it is valid, counts up to one error (:func:`look`); without a budget in
the context a model validates as plain pydantic.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, get_args, get_origin

from annotated_types import MaxLen
from pydantic import (
    BaseModel,
    ConfigDict,
    ValidationError,
    ValidationInfo,
    ValidatorFunctionWrapHandler,
    model_validator,
)
from pydantic_core import ErrorDetails, PydanticCustomError, PydanticKnownError

from service.errors import MAX_ERRORS

BUDGET = "pose.errors"  # the validation context's key of the ErrorBudget
#: Errors counted exactly; past them, models not yet validated are not looked at.
COUNT_LIMIT = 100_000
STAND_IN = "pose_counted"  # the type of the error that stands for a model's counted ones


class ErrorBudget:
    """The errors of one validation, as the :class:`Bounded` models find them."""

    __slots__ = ("counted", "limit", "seen", "skipped", "stand_ins")

    def __init__(self, limit: int) -> None:
        self.limit = limit  # errors counted exactly (COUNT_LIMIT)
        self.seen = 0  # errors known to come before the model being entered (a lower bound)
        self.counted = 0  # errors counted but not kept: stood in for, or unknown keys dropped
        self.stand_ins = 0  # stand-in errors raised and not since stood in for themselves
        self.skipped = False  # a model was not looked at: the count is a lower bound


def context(settings: Any = None, limit: int | None = None) -> dict[str, Any]:
    """A validation context with a fresh :class:`ErrorBudget` counting up to ``limit``
    errors (default ``COUNT_LIMIT``), and the service's ``settings`` (the batch reads
    them)."""
    return {"settings": settings, BUDGET: ErrorBudget(COUNT_LIMIT if limit is None else limit)}


def look() -> dict[str, Any]:
    """A validation context for a look that only asks whether a body is valid (the hot
    path's, ``service.pose_json``, ``fastpath.pose_form``): its errors counted up to one,
    so that the models after a failing one are not entered and an object's unknown keys
    past the first ``MAX_ERRORS`` are not validated. A valid body validates as without it.
    (Without it such a look validated every error of a refused body, twice before the
    route's own bounded read: a pose-form body of 64 kB with 8,567 unknown option keys
    took the event loop 12.4 against 2.6 ms with the hot path off: an audit, 2026-12-06.)"""
    return context(limit=1)


def _stand_in() -> PydanticCustomError:
    return PydanticCustomError(STAND_IN, "errors counted past those shown")


_KNOWN: dict[type[BaseModel], frozenset[str]] = {}


def _known(cls: type[BaseModel]) -> frozenset[str]:
    """Every key ``cls`` reads: its fields, their aliases, and the properties its JSON
    schema documents (an earlier name a before-validator renames: ``skeleton``)."""
    if cls not in _KNOWN:
        keys = set(cls.model_fields)
        for field in cls.model_fields.values():
            keys.update(a for a in (field.alias, field.validation_alias) if isinstance(a, str))
        keys.update(cls.model_json_schema().get("properties", {}))
        _KNOWN[cls] = frozenset(keys)
    return _KNOWN[cls]


_CAPPED: dict[type[BaseModel], tuple[tuple[str, int], ...]] = {}


def _capped(cls: type[BaseModel]) -> tuple[tuple[str, int], ...]:
    """``cls``'s fields holding a list of models of at most so many items. pydantic
    validates the first ``cap + 1`` items of a longer list, then drops their errors for one
    ``too_long``: counted, they would make a later model look past those shown. The list is
    handed over as as many ``None`` (the same error, no model entered)."""
    if cls not in _CAPPED:
        capped = []
        for name, field in cls.__pydantic_fields__.items():
            item = get_args(field.annotation)[0] if get_origin(field.annotation) is list else None
            cap = next((m.max_length for m in field.metadata if isinstance(m, MaxLen)), None)
            if isinstance(item, type) and issubclass(item, BaseModel) and cap is not None:
                capped.append((field.alias or name, cap))
        _CAPPED[cls] = tuple(capped)
    return _CAPPED[cls]


def _unknown_keys(cls: type[BaseModel], data: dict[str, Any], budget: ErrorBudget) -> Any:
    """``data`` without its unknown keys past the first MAX_ERRORS, those counted."""
    known = _known(cls)
    kept: dict[str, Any] = {}
    unknown = 0
    for key, value in data.items():
        if key in known:
            kept[key] = value
        else:
            unknown += 1
            if unknown <= MAX_ERRORS:
                kept[key] = value
    if unknown <= MAX_ERRORS:
        return data
    budget.counted += unknown - MAX_ERRORS
    return kept


class Bounded(BaseModel):
    """A request model: strict, no unknown keys, validated within an :class:`ErrorBudget`
    when the context holds one (see the module doc)."""

    model_config = ConfigDict(extra="forbid", strict=True)

    @model_validator(mode="wrap")
    @classmethod
    def _bounded(
        cls, data: Any, handler: ValidatorFunctionWrapHandler, info: ValidationInfo
    ) -> Any:
        # one frame, cheap when valid: it runs for every model of every body (~0.5 us)
        ctx = info.context
        if type(data) is not dict or type(ctx) is not dict or BUDGET not in ctx:
            return handler(data)  # (an instance, one type error; or no budget)
        budget: ErrorBudget = ctx[BUDGET]
        seen, counted, stand_ins = budget.seen, budget.counted, budget.stand_ins
        if seen >= budget.limit:
            budget.skipped = True
            budget.stand_ins += 1
            raise _stand_in()
        if len(data) > len(cls.__pydantic_fields__):
            data = _unknown_keys(cls, data, budget)
        for key, cap in _capped(cls):
            value = data.get(key)
            if type(value) is list and len(value) > cap:  # see _capped
                data = {**data, key: [None] * len(value)}
        try:
            return handler(data)
        except ValidationError as exc:
            found = exc.error_count() - (budget.stand_ins - stand_ins) + budget.counted - counted
            budget.seen = seen + found
            if seen < MAX_ERRORS:  # some of them may be shown
                raise
            budget.counted = counted + found
            budget.stand_ins = stand_ins + 1
            raise _stand_in() from None


def errors_of(
    exc: ValidationError, ctx: Any, data: Any = None
) -> tuple[list[ErrorDetails], int, bool]:
    """The first MAX_ERRORS errors of a bounded validation (``ctx``: its context) of
    ``data`` (the JSON validated, to place a key's error: :func:`keyed`), in pydantic's
    shape, how many there are in all, and whether that count is a lower bound."""
    raw = exc.errors(include_url=False, include_context=True)
    budget = ctx.get(BUDGET) if isinstance(ctx, dict) else None
    shown = [keyed(e, data) for e in raw if e["type"] != STAND_IN][:MAX_ERRORS]
    n = sum(e["type"] != STAND_IN for e in raw)
    if budget is None:
        return shown, n, False
    return shown, n + budget.counted, budget.skipped


def keyed(error: ErrorDetails, data: Any) -> ErrorDetails:
    """``error`` placed at the key it is about, where it is about an object's key: pydantic
    places a key that is no string (a lone surrogate, ``"\\udfff"``, valid JSON that no
    UTF-8 encodes) at the object, as its own input; its place is then the object's with the
    key after it (``options.\\udfff``), as an unknown key's is, and ``ctx.key`` says so
    (false: a string value; absent: not known).
    (The key was reported at the object, ``body`` for a top-level one: an audit,
    2026-12-06.)"""
    key = error.get("input")
    if error["type"] != "string_unicode" or not isinstance(key, str) or data is None:
        return error
    node = data
    for part in error["loc"]:
        step = isinstance(node, list) and isinstance(part, int) and -len(node) <= part < len(node)
        if not (step or (isinstance(node, dict) and part in node)):
            return error  # a step of pydantic's own (a union's member): not placed
        node = node[part]
    if isinstance(node, str):  # a string value: its place is right
        return {**error, "ctx": {"key": False}}
    if not (isinstance(node, dict) and key in node):
        return error
    return {**error, "loc": (*error["loc"], key), "ctx": {"key": True}}


def at_most(n: int) -> Callable[[Any], Any]:
    """A before-validator refusing a JSON object of more than ``n`` entries before its
    entries are validated (pydantic checks a dict's ``max_length`` after: every entry's
    errors first)."""

    def check(value: Any) -> Any:
        if isinstance(value, dict) and len(value) > n:
            given = {"field_type": "Dictionary", "max_length": n, "actual_length": len(value)}
            raise PydanticKnownError("too_long", given)
        return value

    return check
