"""``options.carry`` over HTTP (the branch below a dragged joint, per request), on real
poses: absent means the models' default (``GET /v1/models`` says which); an explicit value
answers bit for bit what an engine built with it answers, alone, in a batch mixing values
and in the columnar form; only the branch below the target changes; a bad value is a 422
naming ``options.carry``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX
from service.engine import Engine
from tests.conftest import PosePairs
from tests.service.test_api import as_array, engine_pose, solve_body
from tests.service.test_columnar import assert_same, columns, items
from tests.service.test_passes_api import assert_bad_option

ELBOW = ["left_elbow"]


@pytest.fixture(scope="module")
def by_carry(models_dir: Path) -> dict[float, Engine]:
    return {c: Engine(models_dir, serving={"carry": c}) for c in (0.0, 1.0)}


def test_models_say_their_default(client: Any, engine: Engine) -> None:
    r = client.get("/v1/models")
    assert r.status_code == 200
    assert r.json()["carry"] == engine.manifest.serving.carry == engine.serving.carry == 0.5


def test_pose_form_carry_equals_an_engine_built_with_it(
    client: Any, engine: Engine, by_carry: dict[float, Engine], real_poses: PosePairs
) -> None:
    wrist = JOINT_INDEX["left_wrist"]
    for k in range(6):
        body = solve_body(real_poses, k, ELBOW)
        default = client.post("/v1/solve", json=body).json()
        explicit = client.post("/v1/solve", json={**body, "options": {"carry": 0.5}}).json()
        assert explicit == default  # absent = the models' default
        assert np.array_equal(as_array(default["pose"]), engine_pose(engine, body))
        poses = {}
        for c, other in by_carry.items():
            out = client.post("/v1/solve", json={**body, "options": {"carry": c}})
            assert out.status_code == 200, out.text
            poses[c] = as_array(out.json()["pose"])
            assert np.array_equal(poses[c], engine_pose(other, body)), c
        # integers are numbers too
        one = client.post("/v1/solve", json={**body, "options": {"carry": 1}}).json()
        assert np.array_equal(as_array(one["pose"]), poses[1.0])
        # in one pass only the wrist (below the elbow) differs; the next pass starts
        # from that answer, so with two everything may
        single = {
            c: as_array(
                client.post(
                    "/v1/solve", json={**body, "options": {"carry": c, "passes": 1}}
                ).json()["pose"]
            )
            for c in (0, 1)
        }
        rest = np.setdiff1d(np.arange(21), [wrist])
        assert np.array_equal(single[0][rest], single[1][rest])
        assert np.abs(single[0][wrist] - single[1][wrist]).max() > 1e-4


def test_batch_and_columnar_carry(client: Any, real_poses: PosePairs) -> None:
    bodies = [solve_body(real_poses, k, ELBOW, carry=k % 3 / 2) for k in range(9)]
    bodies[4]["options"]["reach"] = "exact"
    batch = client.post("/v1/solve/batch", json={"items": bodies})
    assert batch.status_code == 200, batch.text
    for b, got in zip(bodies, batch.json()["items"], strict=True):
        assert got == client.post("/v1/solve", json=b).json()
    body = columns(real_poses, 30, carry=1.0)
    col = client.post("/v1/solve/batch", json=body)
    assert col.status_code == 200, col.text
    assert_same(
        col.json(), client.post("/v1/solve/batch", json={"items": items(body)}).json()["items"]
    )


@pytest.mark.parametrize("value", [-0.1, 1.5, "0.5", True, [0.5]])
def test_bad_carry_is_422_naming_the_field(
    client: Any, real_poses: PosePairs, value: object
) -> None:
    assert_bad_option(client, real_poses, "carry", value)
