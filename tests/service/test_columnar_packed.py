"""The columnar batch's packed columns: ``poses`` and ``targets.positions`` sent as base64
of little-endian float64 (``service.columnar.PACKED``), answered with packed ``poses``.
Exact: a packed batch is answered bit for bit as the same batch in JSON numbers, in one
part or several, through the fast path and through the route's models; every bad packed
column a problem naming its field (and a number's row and place)."""

from __future__ import annotations

import base64
from pathlib import Path
from typing import Any

import numpy as np
import orjson
import pytest

from service import columnar
from service.schemas import ColumnarBatch
from tests.conftest import PosePairs, make_client
from tests.service.test_api import assert_problem
from tests.service.test_columnar import columns


def pack(rows: Any) -> str:
    return base64.b64encode(np.asarray(rows, dtype="<f8").tobytes()).decode()


def unpack(text: str, width: int = 63) -> np.ndarray:
    return np.frombuffer(base64.b64decode(text), dtype="<f8").reshape(-1, width)


def packed(body: dict[str, Any], positions: bool = True) -> dict[str, Any]:
    out = {**body, "poses": pack(body["poses"])}
    if positions:
        out["targets"] = {**body["targets"], "positions": pack(body["targets"]["positions"])}
    return out


@pytest.mark.parametrize(
    ("options", "pins", "n", "positions"),
    [
        ({}, None, 300, True),  # several priced parts, their base64 joined
        ({"reach": "exact"}, ["left_foot"], 24, False),  # positions left as JSON numbers
        ({"method": "fabrik"}, None, 7, True),
    ],
)
def test_a_packed_batch_is_answered_as_the_same_batch_in_numbers(
    client: Any, real_poses: PosePairs, options: dict[str, Any], pins: list[str] | None,
    n: int, positions: bool,
) -> None:  # fmt: skip
    body = columns(real_poses, n, **options)
    if pins:
        body["pins"] = pins
    plain = client.post("/v1/solve/batch", json=body)
    sent = packed(body, positions)
    got = client.post("/v1/solve/batch", json=sent)
    assert plain.status_code == 200 and got.status_code == 200, got.text
    want, answer = plain.json(), got.json()
    poses = unpack(answer["poses"])
    assert poses.shape == (n, 63) and len(base64.b64decode(answer["poses"])) == n * 504
    assert np.array_equal(poses, np.asarray(want["poses"]))  # bit for bit
    assert {k: v for k, v in answer.items() if k != "poses"} == {
        k: v for k, v in want.items() if k != "poses"
    }
    assert client.post("/v1/solve/batch", json=sent).content == got.content  # run to run
    # the route's models take it too, and read the same columns
    model = ColumnarBatch.model_validate(sent)
    a, b = (
        columnar.parse(model.model_dump(), 8192),
        columnar.parse(orjson.loads(orjson.dumps(sent)), 8192),
    )
    assert a.packed and b.packed and np.array_equal(a.poses, b.poses)
    assert np.array_equal(a.tpos, b.tpos)


def test_bad_packed_columns_are_named(models_dir: Path, real_poses: PosePairs) -> None:
    body = packed(columns(real_poses, 8))
    poses = unpack(body["poses"])
    nan = poses.copy()
    nan[3, 5] = np.nan
    far = poses.copy()
    far[6, 61] = 2e6
    cases = [
        ({"poses": body["poses"][:-4]}, "poses: 4029 bytes packed: not whole rows of 63 "
         "float64 numbers (504 bytes each)"),
        ({"poses": "!!!!" + body["poses"][4:]}, "poses: a packed column is base64 (RFC 4648"),
        ({"poses": body["poses"][:100] + "\n" + body["poses"][100:]}, "is base64"),
        ({"poses": "é" * 8}, "is base64"),
        ({"poses": ""}, "poses: at least one pose packed: 504 bytes, 672 base64 characters"),
        ({"poses": pack(nan)}, "poses[3][5]: must be a finite number"),
        ({"poses": pack(far)}, "poses[6][61]"),
        ({"targets": {**body["targets"], "positions": body["targets"]["positions"][:40]}},
         "targets.positions: 30 bytes packed for 8 poses: one row of 6 float64 numbers "
         "(48 bytes) per pose, 384 bytes"),
        ({"poses": pack(poses[:7])}, "targets.joints: 8 rows for 7 poses"),  # (counted packed)
        # only poses and positions are packed (the schema's), on the hot path as on the
        # route: packed weights were taken there (an API audit, 2026-12-08)
        ({"targets": {**body["targets"], "weights": pack(np.ones((8, 2)))}},
         "targets.weights: a JSON array is required, not a string"),
    ]  # fmt: skip
    with make_client(models_dir, max_batch_items=8) as c:
        for change, said in cases:
            r = c.post("/v1/solve/batch", json={**body, **change})
            assert_problem(r, 422, said)
        # more poses than a batch may hold: a 413, said before the column is decoded
        nine = pack(np.concatenate([poses, poses[:1]]))
        assert_problem(c.post("/v1/solve/batch", json={**body, "poses": nine}), 413,
                       "9 items exceed the limit of 8 per batch")  # fmt: skip
        assert c.post("/v1/solve/batch", json=body).status_code == 200
