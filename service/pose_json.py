"""The pose form of ``/v1/solve`` read straight from its decoded JSON, without pydantic's
models: the hot path's first look at a body (``service.middleware.fastpath``).

It takes only what ``SolveRequest`` plainly takes, and is stricter where that is simpler:
the top-level keys among ``pose``, ``targets``, ``pins``, ``options``; exactly the 21
joints, each three JSON numbers (not booleans) within ±``MAX_COORDINATE``; 1-21 targets of
``joint``, ``position`` and an optional ``weight`` (a number, 0 < w ≤ ``MAX_WEIGHT``); at
most 21 pins, each a joint name; ``options`` validated by ``SolveOptions`` itself (the
same options object reused for the same options). Anything else is None, and the hot path
reads the body as before (``pose_form``: the model), so every refusal is the model's.
What it gives is what the model's path gives: the same numbers as float64 arrays, the
same options, the same ``problem_of`` (its checks too).

Why: the models' validation (five models, each with a Python validator) and their
objects turned into arrays cost ~0.1 ms of a ~0.4 ms request on a server, ~20 µs here
(docs/limits.md, "The hot path").
"""

from __future__ import annotations

from itertools import chain
from typing import Any

import numpy as np
from pydantic import ValidationError

from core.skeleton import JOINT_INDEX, JOINT_NAMES
from service.bounded import look
from service.schemas import MAX_COORDINATE, MAX_WEIGHT, SolveOptions

_TOP = frozenset({"pose", "targets", "pins", "options"})
_TARGET = frozenset({"joint", "position", "weight"})
_JOINTS = frozenset(JOINT_NAMES)
_flat = chain.from_iterable
_NUMBERS = frozenset({float, int})
_LIST = frozenset({list})
_THREE = frozenset({3})
#: ``SolveOptions`` validated, by the options' keys, value types and values (bounded).
_OPTIONS: dict[tuple[tuple[str, type, Any], ...], SolveOptions] = {}
_OPTIONS_HELD = 64
_OPTION_KEYS = len(SolveOptions.model_fields)  # (no aliases: each field one key)
_DEFAULT = SolveOptions()  # (never assigned to: the problem copies its fields)


class Plain:
    """A pose-form body as ``problem_of`` takes it."""

    __slots__ = ("goals", "keys", "options", "pins", "pose", "targets", "weights")

    def __init__(self, pose: Any, targets: list[int], goals: Any, weights: list[float],
                 pins: list[int], options: SolveOptions, keys: int) -> None:  # fmt: skip
        self.pose = pose  # [1, 21, 3] float64
        self.targets, self.goals, self.weights = targets, goals, weights
        self.pins, self.options = pins, options
        self.keys = keys  # object keys in the body (see fastpath.pose_form)


def _rows(rows: list[Any]) -> Any:
    """``rows`` of three JSON numbers each (ints and floats, no booleans) within
    ±MAX_COORDINATE as a float64 array ``[N, 3]``, else None."""
    if set(map(type, rows)) != _LIST or set(map(len, rows)) != _THREE:
        return None
    if not set(map(type, _flat(rows))) <= _NUMBERS:
        return None
    try:
        arr = np.fromiter(_flat(rows), np.float64, 3 * len(rows)).reshape(-1, 3)
    except OverflowError:  # an integer past float64
        return None
    return arr if bool((np.abs(arr) <= MAX_COORDINATE).all()) else None


def _options(data: Any) -> SolveOptions | None:
    if type(data) is not dict or len(data) > _OPTION_KEYS:  # (more: unknown keys)
        return None
    try:
        # (a float by its bits: -0.0 == 0.0 and hash alike, and a floor of -0.0 is kept as
        # the model keeps it; a review found the one served the other's options)
        key = tuple((k, type(v), v.hex() if type(v) is float else v) for k, v in data.items())
        known = _OPTIONS.get(key)
    except TypeError:  # a value that is a list or an object: not held
        key, known = None, None
    if known is not None:
        return known
    try:
        options = SolveOptions.model_validate(data, context=look())
    except ValidationError:
        return None
    if key is not None:
        if len(_OPTIONS) >= _OPTIONS_HELD:
            _OPTIONS.clear()
        _OPTIONS[key] = options
    return options


def plain(data: Any) -> Plain | None:
    """The decoded body ``data`` when it is plainly a valid pose-form request, else None."""
    if type(data) is not dict or not data.keys() <= _TOP:
        return None
    pose, targets, pins = data.get("pose"), data.get("targets"), data.get("pins", [])
    if type(pose) is not dict or pose.keys() != _JOINTS:
        return None
    if type(targets) is not list or not 1 <= len(targets) <= len(JOINT_NAMES):
        return None
    if type(pins) is not list or len(pins) > len(JOINT_NAMES):
        return None
    keys = len(data) + len(pose)
    idx, positions, weights = [], [], []
    for t in targets:
        if type(t) is not dict or not t.keys() <= _TARGET:
            return None
        joint, weight = t.get("joint"), t.get("weight", 1.0)
        if type(joint) is not str or joint not in JOINT_INDEX or "position" not in t:
            return None
        if type(weight) not in _NUMBERS or not 0.0 < weight <= MAX_WEIGHT:
            return None
        idx.append(JOINT_INDEX[joint])
        positions.append(t["position"])
        weights.append(float(weight))
        keys += len(t)
    if any(type(p) is not str or p not in JOINT_INDEX for p in pins):
        return None
    options = _DEFAULT
    if "options" in data:
        options = _options(data["options"])  # type: ignore[assignment]
        if options is None:
            return None
        keys += len(data["options"])
    arr = _rows([pose[n] for n in JOINT_NAMES] + positions)  # (one array: split below)
    if arr is None:
        return None
    n = len(JOINT_NAMES)
    pinned = [JOINT_INDEX[p] for p in pins]
    return Plain(arr[:n].reshape(1, n, 3), idx, arr[n:], weights, pinned, options, keys)
