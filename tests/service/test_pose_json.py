"""The hot path's own read of the pose form (``service.pose_json``): it takes a body only
where ``SolveRequest`` takes it, and gives the problem the model's path gives, bit for
bit; what it does not take goes to the model (and so to the route's words)."""

from __future__ import annotations

import copy
import dataclasses
import json
import random
from typing import Any

import numpy as np
import orjson
import pytest

from core.rest import rest_pose
from core.skeleton import JOINT_NAMES
from service.errors import PoseError
from service.middleware.fastpath import plain_problem, pose_form
from service.pose_json import plain
from service.problems import SolveProblem
from service.validation import poses, solve_problem

Outcome = tuple[SolveProblem, bool] | str | None


def _base() -> dict[str, Any]:
    rest = rest_pose()
    return {
        "pose": {n: [float(v) for v in rest[i]] for i, n in enumerate(JOINT_NAMES)},
        "targets": [
            {"joint": "left_wrist", "position": [0.3, 1.4, 0.2]},
            {"joint": "right_wrist", "position": [-0.3, 1.2, 0.1], "weight": 2.0},
        ],
        "options": {"method": "neural", "preserve_bone_lengths": True, "reach": "soft"},
    }


def by_models(body: bytes) -> Outcome:
    req = pose_form(body)
    if req is None:
        return None
    try:
        return solve_problem(req, poses([req], ["pose"])[0]), bool(req.pins)
    except PoseError:
        return "refused"


def by_plain(body: bytes) -> Outcome:
    """The hot path's own read (``fastpath.plain_problem``, as ``FastPath`` calls it) of a
    body ``pose_json`` takes; None where it does not take it, or the read leaves the body
    to the route (a repeated key, a check of ``problem_of``)."""
    try:
        taken = plain(orjson.loads(body)) is not None
    except orjson.JSONDecodeError:
        return None
    return plain_problem(body) if taken else None


def same(a: Outcome, b: Outcome) -> bool:
    if not isinstance(a, tuple) or not isinstance(b, tuple):
        return a == b
    (p, pinned), (q, pinned_q) = a, b
    if pinned != pinned_q:
        return False
    for field in dataclasses.fields(p):
        u, v = getattr(p, field.name), getattr(q, field.name)
        if isinstance(u, np.ndarray):
            if u.dtype != v.dtype or u.shape != v.shape or u.tobytes() != v.tobytes():
                return False
        elif type(u) is not type(v) or (u.hex() != v.hex() if type(u) is float else u != v):
            return False  # (a float by its bits: -0.0 is not 0.0 here)
    return True


VALUES: list[Any] = [
    0, 1, -1, 2.5, 1e4, 1e4 + 1, -1e5, 2**60, 10**400, -0.0, 1000, 1000.5, 1e-7, 2.0,
    True, False, None, "x", "left_wrist", "pelvis", "neural", "fabrik", "exact",
    [], {}, [1, 2], [1, 2, 3], [1, 2, 3, 4], {"a": 1},
]  # fmt: skip
KEYS = ["weight", "pins", "options", "extra", "joint", "position", "method", "passes",
        "tolerance", "mirror", "reach", "preserve_bone_lengths"]  # fmt: skip


def mutated(data: Any, rng: random.Random) -> Any:
    """``data`` with one value replaced, removed or added somewhere."""
    data = copy.deepcopy(data)
    places: list[list[Any]] = []

    def walk(node: Any, path: list[Any]) -> None:
        places.append(path)
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(
            node, list) else ()  # fmt: skip
        for k, v in items:
            walk(v, [*path, k])

    walk(data, [])
    if len(places) < 2:
        return data
    path = rng.choice(places[1:])
    parent = data
    for k in path[:-1]:
        parent = parent[k]
    r = rng.random()
    if r < 0.6:
        parent[path[-1]] = rng.choice(VALUES)
    elif r < 0.8:
        del parent[path[-1]]
    elif isinstance(parent, dict):
        parent[rng.choice(KEYS)] = rng.choice(VALUES)
    else:
        parent.append(rng.choice(VALUES))
    return data


def test_plain_bodies_give_the_models_problem() -> None:
    base = _base()
    variants = [base]
    for change in (
        {"pins": ["left_ankle", "right_ankle"]},
        {"options": {"passes": 2.0, "mirror": False}},
        {"options": {}},
        {"pins": []},
    ):
        variants.append({**copy.deepcopy(base), **change})
    bare = copy.deepcopy(base)
    del bare["options"]
    bare["pose"]["pelvis"] = [0, 1, 0]  # integers are numbers
    bare["targets"][0]["weight"] = 1000
    variants.append(bare)
    for v in variants:
        body = json.dumps(v).encode()
        got = by_plain(body)
        assert isinstance(got, tuple) and same(got, by_models(body))


@pytest.mark.parametrize("seed", range(4))
def test_plain_takes_nothing_the_models_refuse(seed: int) -> None:
    """Random changes to a valid body: wherever the hot path's own read takes one, the
    models take it too and give the same problem (or refuse it alike)."""
    rng = random.Random(seed)
    taken = 0
    for _ in range(600):
        data = _base()
        for _ in range(rng.randint(1, 3)):
            data = mutated(data, rng)
        body = json.dumps(data).encode()
        got = by_plain(body)
        if got is not None:
            taken += 1
            assert same(got, by_models(body)), body[-300:]
    assert taken > 0


@pytest.mark.parametrize(
    "change",
    [
        lambda d: d.update(options=None),
        lambda d: d["targets"][0]["position"].__setitem__(0, True),
        lambda d: d["targets"][0].update(weight=0),
        lambda d: d["targets"][0].update(weight=1000.5),
        lambda d: d["pose"]["pelvis"].append(1.0),
        lambda d: d["pose"].update(extra=[0.0, 0.0, 0.0]),
        lambda d: d["pose"]["pelvis"].__setitem__(1, 10001.0),
        lambda d: d["pose"]["pelvis"].__setitem__(1, "1.0"),
        lambda d: d.update(targets=[]),
        lambda d: d.update(pins=["nose"]),
        lambda d: d.update(extra=1),
        lambda d: d["options"].update(method="nope"),
    ],
)
def test_what_the_models_refuse_plain_leaves_to_them(change: Any) -> None:
    data = _base()
    change(data)
    body = json.dumps(data).encode()
    assert by_plain(body) is None and by_models(body) is None


def test_options_read_before_do_not_stand_for_others_equal_to_them() -> None:
    """The options read are kept by their values (``pose_json._options``): values that
    compare equal but are not the same (``-0.0`` and ``0.0``; ``1``, ``1.0`` and ``True``)
    are not taken for one another, whichever came first (a floor of -0.0 once came back as
    the 0.0 read before it)."""
    for key, values in [("floor", [0.0, -0.0, 0.0]), ("carry", [-0.0, 0.0]),
                        ("soft_ik", [0.0, -0.0]), ("passes", [1, 1.0, 2, 2.0])]:  # fmt: skip
        for value in values:
            data = _base()
            data["options"] = {**data["options"], key: value}
            body = json.dumps(data).encode()
            got = by_plain(body)
            assert isinstance(got, tuple) and same(got, by_models(body)), (key, value)


def test_a_repeated_key_is_left_to_the_route() -> None:
    body = json.dumps(_base()).encode().replace(b'"options": {', b'"options": {"reach": "exact", ')
    assert by_plain(body) is None and by_models(body) is None


@pytest.mark.parametrize("where", ["options", "pose", "target"])
def test_a_refused_bodys_look_stops_at_its_first_errors(
    where: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The hot path only asks whether a body is valid, so its look at one the models
    refuse builds about as many of its errors as a problem shows (``service.bounded.look``):
    a body of 8,000 unknown keys was validated whole, twice, before the route's own read
    (an audit: 12.4 against 2.6 ms of the event loop with the hot path off)."""
    from pydantic import ValidationError

    from service.errors import MAX_ERRORS
    from service.schemas import SolveOptions, SolveRequest

    body = _base()
    extra = {f"k{i}": i for i in range(8000)}
    {"options": body["options"], "pose": body["pose"], "target": body["targets"][0]}[where].update(
        extra
    )
    built: list[int] = []
    for model in (SolveOptions, SolveRequest):

        def spy(data: Any, *args: Any, _check: Any = model.model_validate, **kw: Any) -> Any:
            try:
                return _check(data, *args, **kw)
            except ValidationError as exc:
                built.append(exc.error_count())
                raise

        monkeypatch.setattr(model, "model_validate", spy)
    assert plain_problem(orjson.dumps(body)) is None
    assert built and max(built) < 2 * MAX_ERRORS, built  # (8,000 and more before)
