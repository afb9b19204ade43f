"""``/v1/complete`` without ``bone_lengths`` says when a wrist or an ankle lies farther
from the neck or the pelvis than a person's limb reaches (``scale_warning``,
``service.completion.LIMB_REACH``): an API audit (2026-12-07) moved the docs' example's
left wrist 1.5 m out and got an arm of 1.44 m from collar to wrist (0.67 before), every key
point reached, and no word. Real bodies, the held-out ones included, are never told."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS
from service.completion import LIMB_MARGIN, LIMB_REACH, limb_reaches
from tests.conftest import REPO_ROOT
from tests.service.warned import real_poses

_EXAMPLE = json.loads((REPO_ROOT / "docs/examples/complete.json").read_text())


def _moved(joint: str, by: list[float]) -> dict[str, Any]:
    body = json.loads(json.dumps(_EXAMPLE))
    for k in body["keypoints"]:
        if k["joint"] == joint:
            k["position"] = np.add(k["position"], by).tolist()
    return body


def _limb(pose: dict[str, list[float]], bones: list[str]) -> float:
    """The answer's bones ending at ``bones`` (their child joints), summed (m)."""
    at = {j: np.asarray(pose[j]) for j in JOINT_NAMES}
    return sum(
        float(np.linalg.norm(at[b] - at[JOINT_NAMES[PARENTS[JOINT_INDEX[b]]]])) for b in bones
    )


_ARM = ["left_collar", "left_shoulder", "left_elbow", "left_wrist"]
_LEG = ["right_hip", "right_knee", "right_ankle"]


@pytest.mark.parametrize("split", ["test", "holdout"])
def test_no_real_body_reaches_as_far(split: str, small_dataset: Path) -> None:
    """Every frame's wrists and ankles lie within :data:`LIMB_REACH` of the neck and the
    pelvis (measured here apart from ``limb_reaches``, in one numpy pass), and the function
    reads a frame as this does."""
    poses = real_poses(split, small_dataset)
    torso = np.linalg.norm(poses[:, JOINT_INDEX["neck"]] - poses[:, JOINT_INDEX["pelvis"]], axis=1)
    for end, (root, most) in LIMB_REACH.items():
        at = JOINT_INDEX[end]
        reach = np.linalg.norm(poses[:, at] - poses[:, JOINT_INDEX[root]], axis=1) / torso
        assert reach.max() <= most, (split, end, reach.max())
        if (REPO_ROOT / "data/poses.npz").is_file() and split == "holdout":
            assert reach.max() > most - 0.1, (end, reach.max())  # (the figures it gives)
        far = int(reach.argmax())
        keys = {k["joint"]: poses[far, JOINT_INDEX[k["joint"]]] for k in _EXAMPLE["keypoints"]}
        assert limb_reaches(keys)[end] == pytest.approx(reach[far], rel=1e-12)


def test_real_key_points_get_no_word(client: Any, small_dataset: Path) -> None:
    """The held-out bodies' key points that reach the farthest (each limb's farthest frame)
    are completed without a word."""
    poses = real_poses("holdout", small_dataset)
    torso = np.linalg.norm(poses[:, JOINT_INDEX["neck"]] - poses[:, JOINT_INDEX["pelvis"]], axis=1)
    for j, root in (("left_wrist", "neck"), ("right_ankle", "pelvis")):
        far = poses[
            int(
                np.argmax(
                    np.linalg.norm(poses[:, JOINT_INDEX[j]] - poses[:, JOINT_INDEX[root]], axis=1)
                    / torso
                )
            )
        ]
        points = [(k["joint"], far[JOINT_INDEX[k["joint"]]]) for k in _EXAMPLE["keypoints"]]
        body = {"keypoints": [{"joint": k, "position": at.tolist()} for k, at in points]}
        assert client.post("/v1/complete", json=body).json()["scale_warning"] is None, j


def test_a_wrist_or_an_ankle_out_of_reach_is_said(client: Any) -> None:
    plain = client.post("/v1/complete", json=_EXAMPLE).json()
    assert plain["scale_warning"] is None
    arm = _limb(plain["pose"], _ARM)
    assert 0.6 < arm < 0.75, arm  # a person's arm, collar to wrist
    for joint, by, bones, limb in (
        ("left_wrist", [1.5, 0.0, 0.0], _ARM, "arm (collar to wrist)"),
        ("right_ankle", [2.0, 0.0, 0.0], _LEG, "leg (hip to ankle)"),
    ):
        out = client.post("/v1/complete", json=_moved(joint, by)).json()
        said = out["scale_warning"]
        assert said is not None and said.startswith(f"keypoints: {joint} lies "), said
        drawn = _limb(out["pose"], bones)
        assert f"the answer's {limb} is {drawn:.3g} m" in said, (drawn, said)
        assert drawn > 1.5 * arm if limb.startswith("arm") else drawn > 1.2, drawn
        # given the body's own bones, the bones' reach says it instead
        own = {
            JOINT_NAMES[c]: _limb(plain["pose"], [JOINT_NAMES[c]]) for c in range(1, len(PARENTS))
        }
        kept = client.post("/v1/complete", json={**_moved(joint, by), "bone_lengths": own}).json()
        assert "cannot reach the key points" in kept["scale_warning"], kept["scale_warning"]
        assert f"keypoints: {joint} lies" not in kept["scale_warning"]
    # the band's edge: just inside it, no word; just past it, said
    neck = np.asarray(next(k["position"] for k in _EXAMPLE["keypoints"] if k["joint"] == "neck"))
    pelvis = np.asarray(
        next(k["position"] for k in _EXAMPLE["keypoints"] if k["joint"] == "pelvis")
    )
    wrist = np.asarray(
        next(k["position"] for k in _EXAMPLE["keypoints"] if k["joint"] == "left_wrist")
    )
    torso = float(np.linalg.norm(neck - pelvis))
    away = (wrist - neck) / np.linalg.norm(wrist - neck)
    for k, word in ((0.99, False), (1.01, True)):
        at = neck + away * torso * LIMB_REACH["left_wrist"][1] * LIMB_MARGIN * k
        out = client.post("/v1/complete", json=_moved("left_wrist", (at - wrist).tolist())).json()
        assert (out["scale_warning"] is not None) == word, (k, out["scale_warning"])
