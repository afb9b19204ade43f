"""The field an unknown key of a request was probably meant to be: ``options.tolerence``
is offered ``tolerance``, ``target`` ``targets`` (pydantic says "Extra inputs are not
permitted" alone; an API audit, 2026-12-07, found every other name a request gives, a
joint's, a setting's, a config key's, offered the one meant).

The object a key is in is found by walking the request model along the error's location,
the body itself choosing a union's member (the pose or the character form), so a key is
only ever offered a field of its own object: ``options.frame`` is offered nothing, though
``frame`` is a field of the BVH routes."""

from __future__ import annotations

import types
from collections.abc import Sequence
from typing import Annotated, Any, Union, get_args, get_origin

from pydantic import BaseModel, RootModel
from pydantic_core import ErrorDetails

from core.text import near_name

#: the most steps a location takes (a request's objects nest a few deep)
_MAX_DEPTH = 12


def offered(errors: list[ErrorDetails], model: type[BaseModel], data: Any) -> None:
    """Give each unknown key of ``errors`` (``extra_forbidden``, validating ``data`` as
    ``model``) the field it is a slip of, in its context (``ctx.meant``), where one is."""
    for error in errors:
        loc = error.get("loc", ())
        if error.get("type") != "extra_forbidden" or not loc or not isinstance(loc[-1], str):
            continue
        meant = slip_of(loc[-1], fields_at(model, data, tuple(loc[:-1])))
        if meant is not None:
            error["ctx"] = {**(error.get("ctx") or {}), "meant": meant}


def slip_of(key: Any, names: Sequence[str]) -> str | None:
    """The one of ``names`` an unknown ``key`` is a slip of (:func:`core.text.near_name`; a
    key of more than 40 characters is none, and never the key itself: a key unknown where
    it is may be a field of another form, which the client did not mean)."""
    if not isinstance(key, str) or not names or len(key) > 40:
        return None
    meant = near_name(key, names)
    return None if meant == key else meant


def fields_at(model: Any, data: Any, loc: tuple[Any, ...]) -> list[str]:
    """The field names (as a client spells them: aliases) of the object at ``loc`` in a
    body ``data`` of ``model``; none where the walk loses its way."""
    tp: Any = model
    if len(loc) > _MAX_DEPTH:
        return []
    for part in loc:
        tp = _member(tp, data)
        if isinstance(tp, type) and issubclass(tp, BaseModel) and isinstance(part, str):
            field = tp.model_fields.get(part) or next(
                (f for f in tp.model_fields.values() if f.alias == part), None
            )
            if field is None:
                return []
            tp = field.annotation
        elif get_origin(tp) is list and isinstance(part, int):
            tp = get_args(tp)[0]
        elif get_origin(tp) is dict and isinstance(part, str):
            tp = get_args(tp)[1]
        else:  # (a step of pydantic's own: a union member's tag, a function's name)
            continue
        data = _child(data, part)
    tp = _member(tp, data)
    if not (isinstance(tp, type) and issubclass(tp, BaseModel)):
        return []
    return _names(tp)


def _member(tp: Any, data: Any) -> Any:
    """``tp`` unwrapped (``Annotated``, a root model's root, ``X | None``), and of a union
    of models the one the object ``data`` is (the one whose fields hold most of its keys)."""
    for _ in range(_MAX_DEPTH):
        if isinstance(tp, type) and issubclass(tp, RootModel):
            tp = tp.model_fields["root"].annotation
        elif get_origin(tp) is Annotated:
            tp = get_args(tp)[0]
        elif get_origin(tp) in (Union, types.UnionType):
            members = [m for m in get_args(tp) if m is not type(None)]
            models = [_member(m, data) for m in members]
            keys = set(data) if isinstance(data, dict) else set()
            fits = [m for m in models if isinstance(m, type) and issubclass(m, BaseModel)]
            if not fits:
                return members[0] if len(members) == 1 else tp
            return max(fits, key=lambda m: len(keys & set(_names(m))))
        else:
            return tp
    return tp


def _names(model: type[BaseModel]) -> list[str]:
    """The keys a client may give ``model``: its fields (as spelled: aliases), then the
    earlier names it still takes (``EARLIER_NAMES``: ``skeleton`` for ``character`` on
    ``/v1/character/solve``)."""
    earlier: dict[str, str] = getattr(model, "EARLIER_NAMES", {})
    return [f.alias or name for name, f in model.model_fields.items()] + list(earlier)


def _child(data: Any, part: Any) -> Any:
    if isinstance(data, dict):
        return data.get(part)
    if isinstance(data, list) and isinstance(part, int) and -len(data) <= part < len(data):
        return data[part]
    return None
