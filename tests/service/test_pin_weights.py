"""Target weights are relative, pins or not (``service.validation.pin_weights``).

An API audit (2026-12-08): a pin weighed 1 whatever the targets weighed, so giving every
target weight 2 instead of 1 put the pin's solver first and moved joints 6.4 cm (soft),
and all 0.001 in exact reach 29.6 cm; without pins the same scaling changed nothing. Now a
pin weighs as the heaviest target, in every form: the single edit, the batch's item list
and the columnar batch.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_NAMES
from tests.conftest import PosePairs
from tests.service.test_api import solve_body

JOINTS = ["left_wrist", "right_wrist", "head"]
SCALES = (1.0, 2.0, 0.001)


def edit(real_poses: PosePairs, k: int, scale: float, **options: Any) -> dict[str, Any]:
    body = solve_body(real_poses, k, JOINTS, **options)
    for t in body["targets"]:
        t["weight"] = scale
    body["pins"] = ["left_ankle"]
    return body


def poses(answer: dict[str, Any]) -> np.ndarray:
    return np.array([answer["pose"][n] for n in JOINT_NAMES])


@pytest.mark.parametrize(
    "options", [{}, {"reach": "exact"}, {"method": "fabrik"}], ids=["soft", "exact", "fabrik"]
)
def test_scaling_every_target_weight_leaves_a_pinned_answer_as_it_was(
    client: Any, real_poses: PosePairs, options: dict[str, Any]
) -> None:
    for k in range(4):
        got = []
        for scale in SCALES:
            r = client.post("/v1/solve", json=edit(real_poses, k, scale, **options))
            assert r.status_code == 200, r.text
            got.append(poses(r.json()))
        for other in got[1:]:
            assert np.array_equal(other, got[0]), np.abs(other - got[0]).max()


def test_a_pin_weighs_as_the_heaviest_target_in_every_form(
    client: Any, real_poses: PosePairs
) -> None:
    """Mixed weights (1, 3, 0.5) with a pin: the single edit, the item list and the columnar
    batch answer alike, and as the same edit with every weight doubled."""
    body = edit(real_poses, 0, 1.0)
    for t, w in zip(body["targets"], (1.0, 3.0, 0.5), strict=True):
        t["weight"] = w
    double = copy.deepcopy(body)
    for t in double["targets"]:
        t["weight"] *= 2
    single = [client.post("/v1/solve", json=b) for b in (body, double)]
    items = client.post("/v1/solve/batch", json={"items": [body, double]})
    pose = [v for n in JOINT_NAMES for v in body["pose"][n]]
    cols = {
        "poses": [pose, pose],
        "targets": {
            "joints": JOINTS,
            "positions": [[v for t in body["targets"] for v in t["position"]]] * 2,
            "weights": [[t["weight"] for t in b["targets"]] for b in (body, double)],
        },
        "pins": ["left_ankle"],
    }
    columnar = client.post("/v1/solve/batch", json=cols)
    for r in (*single, items, columnar):
        assert r.status_code == 200, r.text
    want = poses(single[0].json())
    assert np.array_equal(poses(single[1].json()), want)
    for answer in items.json()["items"]:
        assert np.array_equal(poses(answer), want)
    got = np.array(columnar.json()["poses"]).reshape(2, len(JOINT_NAMES), 3)
    assert np.array_equal(got[0], want) and np.array_equal(got[1], want)
