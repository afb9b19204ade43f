"""The columnar batch and the hot path of /v1/solve (issue 14, part B), on real poses:
the same answers, bit for bit, as the item list and as single requests, run after run;
every bad input a problem naming the item and the field."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX, JOINT_NAMES
from core.text import clip, shown
from service.middleware import fastpath
from tests.conftest import PosePairs, make_client

PROBLEM = "application/problem+json"
SETS = [["left_wrist", "right_wrist"], ["head", "left_ankle"], ["right_wrist", "spine2"]]


def columns(pairs: PosePairs, n: int, **options: Any) -> dict[str, Any]:
    """``n`` real edits in the columnar form: target joints per item (three sets in
    turn), goals from the pair's goal pose."""
    k = [i % len(pairs.starts) for i in range(n)]
    starts = pairs.poses[pairs.starts[k]]
    goals = pairs.poses[pairs.goals[k]]
    joints = [SETS[i % len(SETS)] for i in range(n)]
    idx = np.array([[JOINT_INDEX[j] for j in row] for row in joints])
    return {
        "poses": starts.reshape(n, -1).tolist(),
        "targets": {
            "joints": joints,
            "positions": np.take_along_axis(goals, idx[:, :, None], 1).reshape(n, -1).tolist(),
        },
        "options": options,
    }


def items(body: dict[str, Any]) -> list[dict[str, Any]]:
    """The same edits as items of the item list (pose form)."""
    out = []
    for b, row in enumerate(body["poses"]):
        joints = body["targets"]["joints"]
        joints = joints if isinstance(joints[0], str) else joints[b]
        xyz = body["targets"]["positions"][b]
        item: dict[str, Any] = {
            "pose": {n: row[3 * j : 3 * j + 3] for j, n in enumerate(JOINT_NAMES)},
            "targets": [
                {"joint": name, "position": xyz[3 * i : 3 * i + 3]} for i, name in enumerate(joints)
            ],
            "options": body["options"],
        }
        pins = body.get("pins")
        if pins:
            item["pins"] = pins
        out.append(item)
    return out


def assert_same(col: dict[str, Any], answers: list[dict[str, Any]]) -> None:
    """Item b of the columnar answer equals ``answers[b]`` exactly (floats after JSON)."""
    assert len(col["poses"]) == len(answers)
    for b, a in enumerate(answers):
        assert col["poses"][b] == [v for n in JOINT_NAMES for v in a["pose"][n]], b
        assert col["errors"][b] == [t["error"] for t in a["targets"]], b
        assert col["reached"][b] == [t["reached"] for t in a["targets"]], b
        assert col["pin_errors"][b] == [t["error"] for t in a["pins"]], b
        assert col["max_bone_length_error"][b] == a["max_bone_length_error"], b
        assert col["iterations"][b] == a["iterations"], b
        assert col["solvers"][col["solver_of"][b]] == a["solvers"], b
        assert col["up_warning"][b] == a["up_warning"], b
        assert col["method"] == a["method"] and col["model"] == a["model"]


@pytest.mark.parametrize(
    ("options", "pins", "n"),
    [
        ({}, None, 300),  # more than one priced part (6 units an item, CHUNK_PRICE a part)
        ({"reach": "exact"}, ["left_foot"], 24),
        ({"method": "fabrik"}, None, 24),
        ({"preserve_bone_lengths": False, "floor": 0.0, "tolerance": 0.01}, None, 24),
    ],
)
def test_columnar_equals_item_list_and_singles(
    client: Any, real_poses: PosePairs, options: dict[str, Any], pins: list[str] | None, n: int
) -> None:
    body = columns(real_poses, n, **options)
    if pins:
        body["pins"] = pins
    col = client.post("/v1/solve/batch", json=body)
    assert col.status_code == 200, col.text
    assert float(col.headers["x-compute-time"].removesuffix("ms")) > 0
    listed = client.post("/v1/solve/batch", json={"items": items(body)})
    assert listed.status_code == 200, listed.text
    assert_same(col.json(), listed.json()["items"])
    singles = [client.post("/v1/solve", json=item).json() for item in items(body)[:6]]
    assert singles == listed.json()["items"][:6]
    again = client.post("/v1/solve/batch", json=body)
    assert again.content == col.content  # run to run, byte for byte


def test_answer_written_in_parts_is_the_whole_answer_written_at_once(
    engine: Any, real_poses: PosePairs
) -> None:
    """Each part writes its own poses' rows as it is solved; the answer spliced from them
    is byte for byte the whole answer written at once (one part, several, and a part of
    one item)."""
    import orjson

    from service import columnar

    body = columns(real_poses, 7)
    cols = columnar.parse({**body, "targets": {**body["targets"], "joints": SETS[0]},
                           "pins": ["left_ankle"]}, 100)  # fmt: skip
    whole = columnar.solve(engine, cols, slice(0, 7))
    ans = whole.ans
    k = cols.n_targets
    errors = np.ascontiguousarray(ans.errors[:, :k])
    want = orjson.dumps(
        {
            "poses": np.ascontiguousarray(ans.pose).reshape(7, -1),
            "errors": errors,
            "reached": errors <= cols.options.tolerance,
            "pin_errors": np.ascontiguousarray(ans.errors[:, k : k + cols.n_pins]),
            "max_bone_length_error": ans.max_bone_error,
            "iterations": ans.iterations,
            "solvers": [list(path) for path in ans.paths],
            "solver_of": ans.path_of,
            "model": engine.version,
            "method": "neural",
            "floor": 0.0,
            "up_warning": [None] * 7,  # (real poses, upright)
            "floor_warning": [None] * 7,  # (over their own floor)
            "handedness_warning": [None] * 7,  # (right-handed)
        },
        option=orjson.OPT_SERIALIZE_NUMPY,
    )
    for cuts in ([7], [3, 7], [1, 2, 6, 7]):
        bounds = zip([0, *cuts[:-1]], cuts, strict=True)
        parts = [columnar.solve(engine, cols, slice(a, b)) for a, b in bounds]
        got = columnar.answer(cols, columnar.merge(parts), engine.version)
        assert got == want, cuts
        assert len(orjson.loads(got)["poses"]) == 7


def test_shared_joints_weights_and_pins_per_item(client: Any, real_poses: PosePairs) -> None:
    body = columns(real_poses, 8)
    body["targets"]["joints"] = ["left_wrist", "right_wrist"]
    body["targets"]["weights"] = [1.0, 3.0]
    idx = [JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]]
    goals = real_poses.poses[real_poses.goals[:8]][:, idx]
    body["targets"]["positions"] = goals.reshape(8, -1).tolist()
    body["pins"] = [["left_ankle"] if b % 2 else ["right_ankle"] for b in range(8)]
    col = client.post("/v1/solve/batch", json=body)
    assert col.status_code == 200, col.text
    listed = items(body)
    for b, item in enumerate(listed):
        item["targets"] = [
            {"joint": j, "position": goals[b, i].tolist(), "weight": w}
            for i, (j, w) in enumerate(zip(["left_wrist", "right_wrist"], [1.0, 3.0], strict=True))
        ]
        item["pins"] = body["pins"][b]
    answers = [client.post("/v1/solve", json=item).json() for item in listed]
    assert_same(col.json(), answers)
    out = col.json()
    assert np.array(out["poses"]).shape == (8, 63) and np.array(out["pin_errors"]).shape == (8, 1)


def test_single_hot_path_equals_the_route(
    client: Any, real_poses: PosePairs, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The pose form answered without the router gives the route's bytes, read without
    the models (``service.pose_json``) or with them; what the hot path does not take
    (here: everything) the route answers."""
    bodies = items(columns(real_poses, 6, reach="soft"))
    bodies[1]["pins"] = ["right_foot"]
    bodies[2]["options"] = {"reach": "exact"}
    bodies[3]["targets"][0]["weight"] = 3
    del bodies[4]["options"]
    fast = [client.post("/v1/solve", json=b) for b in bodies]
    monkeypatch.setattr(fastpath, "plain", lambda data: None)
    models = [client.post("/v1/solve", json=b) for b in bodies]
    monkeypatch.setattr(fastpath, "pose_form", lambda body, data=None: None)
    slow = [client.post("/v1/solve", json=b) for b in bodies]
    for f, m, s in zip(fast, models, slow, strict=True):
        assert f.status_code == m.status_code == s.status_code == 200
        assert f.content == m.content == s.content
        assert f.headers["content-type"] == s.headers["content-type"] == "application/json"
        for h in ("x-compute-time", "x-total-time", "x-request-id", "content-security-policy"):
            assert h in f.headers and h in m.headers and h in s.headers


@pytest.mark.parametrize(
    "body",
    [
        b"",
        b"true",
        b"false",
        b'{"a": true, "b": [false, 1e-5, 2E3], "c": "untrue falsehood"}',
        b"e:e:true:false:truefalse:fals:rue:eeee",
    ],
)
def test_tokens_count_as_bytes_count_does(body: bytes, real_poses: PosePairs) -> None:
    assert fastpath.tokens(body) == (
        body.count(b":"),
        body.count(b"true") + body.count(b"false"),
        body.count(b'"'),
    )
    real = json.dumps(columns(real_poses, 50, preserve_bone_lengths=True)).encode()
    assert fastpath.tokens(real) == (real.count(b":"), 1, real.count(b'"'))


def test_hot_path_leaves_bad_bodies_to_the_route(client: Any, real_poses: PosePairs) -> None:
    body = json.dumps(items(columns(real_poses, 1))[0])
    twice = body[:-1] + ', "options": {}, "options": {}}'
    resp = client.post("/v1/solve", content=twice, headers={"content-type": "application/json"})
    assert resp.status_code == 400 and "duplicate key 'options'" in resp.json()["detail"]
    bad = json.loads(body)
    bad["pose"]["head"] = bad["pose"]["neck"]  # a zero-length bone
    resp = client.post("/v1/solve", json=bad)
    assert resp.status_code == 422 and "degenerate pose" in resp.json()["detail"]
    assert resp.headers["content-type"] == PROBLEM


def _problem(client: Any, body: Any, status: int = 422, raw: str | None = None) -> str:
    content = json.dumps(body) if raw is None else raw  # NaN and Infinity tokens as written
    headers = {"content-type": "application/json"}
    resp = client.post("/v1/solve/batch", content=content, headers=headers)
    assert resp.status_code == status, resp.text
    assert resp.headers["content-type"] == PROBLEM
    detail: str = resp.json()["detail"]
    return detail


def test_columnar_errors_name_item_and_field(client: Any, synthetic_poses: PosePairs) -> None:
    good = columns(synthetic_poses, 20)
    assert client.post("/v1/solve/batch", json=good).status_code == 200

    def edited(path: str, value: Any) -> dict[str, Any]:
        body = json.loads(json.dumps(good))
        *keys, last = path.split("/")
        node: Any = body
        for key in keys:
            node = node[int(key)] if isinstance(node, list) else node[key]
        node[int(last) if isinstance(node, list) else last] = value
        return body

    row0 = good["poses"][0]
    cases = [
        (edited("poses/17/4", "1.0"), 'poses[17][4]: a number is required, not a string ("1.0")'),
        (edited("poses/3/0", True), "poses[3][0]: a number is required, not a boolean (true)"),
        (edited("poses/5/2", 2e4), "poses[5][2]: coordinate 20000.0 beyond ±10000 m"),
        (edited("poses/6", row0[:60]), "poses[6]: must hold 63 numbers, got 60"),
        (edited("targets/joints/4/1", "left_wirst"), "targets.joints[4][1]: unknown joint"),
        (edited("targets/joints/4/1", SETS[1][0]), "targets.joints[4][1]: duplicate target"),
        (edited("targets/positions/9/5", float("inf")), "targets.positions[9][5]: must be a fin"),
        (edited("targets/positions", good["targets"]["positions"][:3]), "3 rows for 20 poses"),
        (
            edited("targets/positions", good["targets"]["positions"][0]),  # one row, as joints
            "targets.positions: a list of 20 rows (one per pose), not one row of",
        ),
        (edited("targets/extra", 1), "targets.extra: Extra inputs are not permitted"),
        (edited("pins", ["left_foot", "left_foot"]), "pins[1]: joint 'left_foot' is pinned twice"),
        (edited("options/reach", "close"), "options.reach"),
        (edited("poses/8", [0.0] * 63), "poses[8]: degenerate pose"),
    ]
    for body, needle in cases:
        assert needle in _problem(client, body), needle
    pinned = edited("pins", [["left_wrist"]] * 20)
    assert "pins[0][0]: joint 'left_wrist' is both pinned and targeted" in _problem(client, pinned)
    nan = edited("poses/0/1", float("nan"))  # json.dumps writes the NaN token
    assert "poses[0][1]: must be a finite number" in _problem(client, nan)
    assert "malformed JSON" in _problem(client, None, 400, raw=json.dumps(good)[:-1])
    twice = json.dumps(good)[:-1] + ', "options": {"reach": "exact"}}'
    assert "duplicate key 'options'" in _problem(client, None, 400, raw=twice)
    inner = json.dumps(good).replace('"targets": {', '"targets": {"joints": ["head"], ', 1)
    assert "duplicate key 'joints'" in _problem(client, None, 400, raw=inner)
    colon = edited("targets/joints/0/0", "a:b")  # a colon in a string: the strict decoder
    assert "targets.joints[0][0]: unknown joint 'a:b'" in _problem(client, colon)
    del good["targets"]
    assert "targets: Field required" in _problem(client, good)


def test_columnar_errors_are_counted_and_worded_as_the_item_lists(
    client: Any, synthetic_poses: PosePairs
) -> None:
    """A batch audit's finds: 40 bad rows were "and 17 more" (the item list: 37), the
    columnar form stopping its count where it stops listing; a bad weight had its own
    words, and only the first was named; a lone surrogate in a key (valid JSON) was a 500
    (the answer quoting it could not be encoded), now a 422 quoting its escape."""
    good = columns(synthetic_poses, 40)
    bad = json.loads(json.dumps(good))
    for row in bad["poses"]:
        row[0] = float("inf")
    listed = json.loads(json.dumps(items(bad)).replace("Infinity", '"x"'))  # 40 bad items
    want = "; and 37 more"
    assert _problem(client, bad).endswith(want)
    assert _problem(client, {"items": listed}).endswith(want)
    for w, words in ((0.0, "greater than 0"), (1001.0, "less than or equal to 1000")):
        weights = [[1.0, w]] * 40
        col = {**good, "targets": {**good["targets"], "weights": weights}}
        resp = client.post("/v1/solve/batch", json=col)
        errors = resp.json()["errors"]
        assert [e["location"] for e in errors] == [f"targets.weights[{b}][1]" for b in range(20)]
        assert errors[0]["message"] == f"Input should be {words}, got {w!r}", errors[0]
        item = items(good)[:1]
        item[0]["targets"][1]["weight"] = w
        one = client.post("/v1/solve/batch", json={"items": item}).json()["errors"][0]
        assert one["message"] == errors[0]["message"] and resp.json()["detail"].endswith("37 more")
    # a shared row's errors counted past the 20 listed too (21 names: "17 more" was 18)
    every = {
        "poses": good["poses"][:2],
        "targets": {
            "joints": list(JOINT_NAMES),
            "positions": [[0.0, 1.0, 0.0] * len(JOINT_NAMES)] * 2,
            "weights": ["heavy"] * len(JOINT_NAMES),
        },
    }
    assert _problem(client, every).endswith("; and 18 more")
    for raw, where in (
        (json.dumps(good)[:-1] + ', "\\ud800": 1}', "\\ud800"),
        (
            json.dumps(good).replace('"targets": {', '"targets": {"\\udc00x": 1, ', 1),
            "targets.\\udc00x",
        ),
    ):
        resp = client.post(
            "/v1/solve/batch", content=raw, headers={"content-type": "application/json"}
        )
        assert resp.status_code == 422, resp.text
        assert "Extra inputs are not permitted" in resp.json()["detail"]
        assert resp.json()["errors"][0]["location"] == where, resp.text  # a backslash, "ud800"


def test_columnar_limits(models_dir: Path, synthetic_poses: PosePairs) -> None:
    body = columns(synthetic_poses, 5)
    with make_client(models_dir, max_batch_items=4) as small:
        detail = _problem(small, body, 413)
        assert "5 items exceed the limit of 4 per batch" in detail
    with make_client(models_dir, unchecked={"deadline_seconds": 1e-9}) as late:
        resp = late.post("/v1/solve/batch", json=body)
        assert resp.status_code == 504 and resp.headers["retry-after"] == "1"  # no work done
        assert "0 of 5 items done" in resp.json()["detail"]
        assert (resp.json()["done"], resp.json()["total"]) == (0, 5)
    with make_client(models_dir) as c:
        assert c.post("/v1/solve/batch", json=body).status_code == 200
        metrics = c.get("/metrics").text
        assert 'pose_solves_total{method="neural",solvers="composed"}' in metrics
        assert 'pose_requests_total{route="/v1/solve/batch",status="200"} 1.0' in metrics


def test_a_columnar_batch_is_told_every_rows_repeats(
    client: Any, synthetic_poses: PosePairs
) -> None:
    """Rows that repeat a joint (a target twice, a pin on a target): every bad row is named,
    in order, as the item list names every bad item (only the first row was, and a client
    fixed one row a round trip); past 20, the count. A repeat in the joints every item
    shares is one error, named once."""
    body = columns(synthetic_poses, 30)
    joints = body["targets"]["joints"]
    for b in (2, 5, 7):
        joints[b] = [joints[b][0], joints[b][0]]
    resp = client.post("/v1/solve/batch", json=body)
    assert resp.status_code == 422 and resp.headers["content-type"] == PROBLEM
    errors = resp.json()["errors"]
    assert [e["location"] for e in errors] == [
        "targets.joints[2][1]", "targets.joints[5][1]", "targets.joints[7][1]"
    ]  # fmt: skip
    assert errors[0]["message"] == f"duplicate target for joint {joints[2][0]!r} (item 2)"
    body = columns(synthetic_poses, 30)
    body["pins"] = [[row[0]] for row in body["targets"]["joints"]]  # each on its own target
    resp = client.post("/v1/solve/batch", json=body)
    assert len(resp.json()["errors"]) == 20 and resp.json()["detail"].endswith("; and 27 more")
    assert resp.json()["errors"][19]["location"] == "pins[19][0]"
    body = columns(synthetic_poses, 30)
    body["targets"]["joints"] = ["left_wrist", "left_wrist"]
    body["targets"]["positions"] = [row[:6] for row in body["targets"]["positions"]]
    resp = client.post("/v1/solve/batch", json=body)
    assert resp.json()["errors"] == [
        {
            "location": "targets.joints[1]",
            "message": "duplicate target for joint 'left_wrist' (every item)",
        }
    ]


def test_a_string_among_the_numbers_costs_no_more_than_its_bytes(
    client: Any, real_poses: PosePairs
) -> None:
    """A string where a number goes is named as any bad number is; its rows are never
    handed to numpy to guess a type for (it built a text array of every row as wide as
    the string: 4,000 characters in a 653 kB body took a worker to 1.3 GiB, 200,000 were a
    500; an audit, 2026-12-06). The read of such a body stays within a few MB."""
    import tracemalloc

    from service.middleware.types import Scope

    body = columns(real_poses, 16)
    body["poses"][3][7] = "x" * 10_000  # (numpy's guess: 16 x 63 x 40 kB, 40 MB)
    raw = json.dumps(body).encode()
    scope: Scope = {}
    tracemalloc.start()
    try:
        with pytest.raises(fastpath.BodyInvalid):
            fastpath.read_columns(raw, 1024, scope)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 * len(raw) + (1 << 20), peak
    r = client.post("/v1/solve/batch", content=raw, headers={"content-type": "application/json"})
    assert r.status_code == 422
    said = f"poses[3][7]: a number is required, not a string ({clip(shown('x' * 10_000))})"
    assert r.json()["detail"] == said, r.json()["detail"]


def test_an_integer_past_64_bits_is_named_as_the_routes_name_it(
    client: Any, real_poses: PosePairs
) -> None:
    """orjson reads an integer past 64 bits as a float; a body it refuses is read again as
    the routes read it, so its problem is theirs (the hot path said a plainly written
    integer had "a fraction or an exponent")."""
    body = columns(real_poses, 2)
    body.setdefault("options", {})["passes"] = "__BIG__"
    text = json.dumps(body).replace('"__BIG__"', "12345678901234567890123")
    r = client.post("/v1/solve/batch", content=text, headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text
    assert "options.passes: Input should be less than or equal to 4" in r.json()["detail"]
