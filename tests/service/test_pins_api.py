"""Pins hold over HTTP whatever the targets: an absurd target never drags a pinned joint."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from core.rest import rest_pose
from core.skeleton import JOINT_INDEX, JOINT_NAMES


@pytest.mark.parametrize("reach", ["soft", "exact"])
@pytest.mark.parametrize("method", ["neural", "fabrik"])
@pytest.mark.parametrize("distance", [2.0, 9_999.0])
def test_pinned_ankles_stay_put_under_a_far_target(
    client: Any, reach: str, method: str, distance: float
) -> None:
    pose = rest_pose()
    target = pose[JOINT_INDEX["left_wrist"]] + np.array([0.0, 0.0, distance])  # ahead
    body = {
        "pose": dict(zip(JOINT_NAMES, pose.tolist(), strict=True)),
        "pins": ["left_ankle", "right_ankle"],
        "targets": [{"joint": "left_wrist", "position": target.tolist()}],
        "options": {"reach": reach, "method": method},
    }
    r = client.post("/v1/solve", json=body)
    assert r.status_code == 200, r.text
    out = r.json()
    assert max(p["error"] for p in out["pins"]) < 2e-3  # metres: the pins did not move
    wrist = np.asarray(out["pose"]["left_wrist"])
    start = pose[JOINT_INDEX["left_wrist"]]
    assert wrist[2] > start[2] + 0.1  # approached as far as the pins allow ...
    assert out["targets"][0]["reached"] is False  # ... and reported as not reached
