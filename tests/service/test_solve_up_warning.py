"""``/v1/solve``'s pose form says when its start pose is not upright along +Y
(``up_warning``), as ``/v1/complete`` says it of key points: an API audit (2026-12-07) sent
the docs' example pose captured with +Z up and got it solved lying down without a word.
The single answer (the hot path and the route), each item of a batch and each row of the
columnar form say it alike, from one definition (``service.upright``)."""

from __future__ import annotations

import json
import re
from typing import Any

import numpy as np
import pytest

from tests.conftest import REPO_ROOT
from tests.service.test_api import BASE
from tests.service.warned import columns, examples, moved, said_alike

#: +Y up -> +Z up: y -> z, z -> -y (a quarter turn about X)
Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def _turned(body: dict[str, Any]) -> dict[str, Any]:
    """``body`` (the pose form) with its pose and targets captured with +Z up."""
    return moved(body, lambda p: p @ Z_UP)


def test_a_start_pose_captured_z_up_is_said_to_be_solved_lying_down(
    client: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    example, soft = examples()
    for body in (example, soft):
        upright = client.post("/v1/solve", json=body).json()
        assert upright["up_warning"] is None
        out = client.post("/v1/solve", json=_turned(body))
        assert out.status_code == 200, out.text
        warning = out.json()["up_warning"]
        assert warning is not None and warning.startswith("pose: the pelvis-to-neck line leans "), (
            warning
        )
        assert "(it runs along +Z)" in warning and "solved lying down" in warning, warning
    # the same words as /v1/complete's of the same body's key points (one definition)
    turned = _turned(soft)["pose"]
    keypoints = [{"joint": j, "position": turned[j]} for j in BASE]
    done = client.post("/v1/complete", json={"keypoints": keypoints}).json()["up_warning"]
    lean = re.compile(r"leans (\d+) degrees from \+Y \(it runs along ([+-][XYZ])\)")
    said, was = lean.search(warning), lean.search(done)
    assert said is not None and was is not None and said.groups() == was.groups()
    # each item of a batch, and each row of the columnar form, as the single answer says
    bodies = [soft, _turned(soft), example, _turned(example)]
    listed = said_alike(client, monkeypatch, bodies)
    assert [a["up_warning"] is None for a in listed] == [True, False, True, False]
    col = client.post("/v1/solve/batch", json=columns(bodies[:2]))
    assert col.status_code == 200, col.text
    assert col.json()["up_warning"] == [a["up_warning"] for a in listed[:2]]


def test_a_body_upside_down_is_said_to_be_upside_down(client: Any) -> None:
    """A pose (or key points) turned half a turn about X, head below the pelvis, was said
    to be answered "lying down" (an audit); it is said to be upside down."""
    example = json.loads((REPO_ROOT / "docs/examples/solve.json").read_text())
    flip = np.diag([1.0, -1.0, -1.0])  # (a half turn about X)
    pose = {n: (np.array(p) @ flip).tolist() for n, p in example["pose"].items()}
    targets = [{"joint": "left_wrist", "position": pose["left_wrist"]}]
    keypoints = [{"joint": j, "position": pose[j]} for j in BASE]
    said = [
        client.post("/v1/solve", json={"pose": pose, "targets": targets}).json()["up_warning"],
        client.post("/v1/complete", json={"keypoints": keypoints}).json()["up_warning"],
    ]
    for warning, done in zip(said, ("solved", "completed"), strict=True):
        assert warning is not None and "(it runs along -Y)" in warning, warning
        assert f"this body was {done} upside down;" in warning and "lying" not in warning
