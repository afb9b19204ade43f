"""A character's answers say the floor they used and where it lies far from the body, as
the pose form's do (``floor``, ``floor_warning``, ``service.floors``): the character form,
``/v1/bvh/solve``, a clip's edits and a batch's character items. The words name the
character's own up axis (a child captured in inches with +Z up is told ``z = ... m``),
its heights in metres as ``options.floor`` is given. Before (2026-12-07) a floor 5 m above
the docs' character, or 50 m below it, moved the answer without a word."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from core.retarget import canonical_points
from core.skeleton import JOINT_INDEX
from service.bvh_models import BVHSolveRequest
from service.character_bvh import character_from_bvh, read_request_bvh
from tests.character_files import FILES
from tests.conftest import REPO_ROOT

_PELVIS, _NECK = JOINT_INDEX["pelvis"], JOINT_INDEX["neck"]


def _floored(body: dict[str, Any], floor: float) -> dict[str, Any]:
    return {**body, "options": {**body.get("options", {}), "floor": floor}}


def test_the_character_form_says_a_floor_far_from_the_body(client: Any) -> None:
    example = json.loads((REPO_ROOT / "docs/examples/character_solve.json").read_text())
    form = {"character": example.pop("skeleton"), **example}  # (/v1/solve's name for it)
    said = {}
    for floor in (0.0, -0.05, 5.0, -50.0):
        answers = [
            client.post("/v1/character/solve", json=_floored({"skeleton": form["character"],
                        **example}, floor)).json(),
            client.post("/v1/solve", json=_floored(form, floor)).json(),
            client.post("/v1/solve/batch", json={"items": [_floored(form, floor)]}).json()[
                "items"][0],
        ]  # fmt: skip
        for a in answers:
            assert a["floor"] == floor, a
            assert a["floor_warning"] == answers[0]["floor_warning"], (floor, a)
        said[floor] = answers[0]["floor_warning"]
    assert said[0.0] is None and said[-0.05] is None, said
    over, under = said[5.0], said[-50.0]
    assert over.startswith("options.floor: the floor (y = 5 m) lies ") and "above" in over
    assert "solved standing under its ground" in over, over
    assert "(y = -50 m) lies 5" in under and "below the start pose's pelvis (y = " in under


def test_a_bvh_child_in_inches_with_z_up_is_told_in_its_own_axis(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    name = "fair1-child-inches-zup"
    _, _, units, frame = FILES[name]
    text = bvh_files[name].read_text()
    body = {"bvh": text, "units": units, "frame": frame,
            "targets": [{"joint": "left_wrist", "position": [0.0, 0.0, 0.0]}]}  # fmt: skip
    ch = character_from_bvh(read_request_bvh(text), BVHSolveRequest.model_validate(body), frame)
    points = ch.to_service(canonical_points(ch.skel, ch.pose, ch.jmap))  # metres, +Y up
    wrist = canonical_points(ch.skel, ch.pose, ch.jmap)[JOINT_INDEX["left_wrist"]]
    body["targets"][0]["position"] = (wrist + ch.from_service(np.array([0.05, 0.1, 0.0]))).tolist()
    pelvis = float(points[_PELVIS, 1])  # the child's pelvis height, m along its +Z
    torso = float(np.linalg.norm(points[_NECK] - points[_PELVIS]))
    assert 0.3 < pelvis < 0.9, pelvis  # (a child standing on z = 0)
    quiet = client.post("/v1/bvh/solve", json=body).json()
    assert quiet["floor"] == 0.0 and quiet["floor_warning"] is None, quiet["floor_warning"]
    high = pelvis + 1.0
    said = client.post("/v1/bvh/solve", json=_floored(body, high)).json()
    assert said["floor"] == high
    assert said["floor_warning"].startswith(
        f"options.floor: the floor (z = {high:.3g} m) lies 1 m above the start pose's "
        f"pelvis (z = {pelvis:.3g} m)"
    ), said["floor_warning"]
    low = pelvis - 4.5 * torso  # below the band by half a torso
    deep = client.post("/v1/bvh/solve", json=_floored(body, low)).json()["floor_warning"]
    assert f"(z = {low:.3g} m) lies" in deep and f"{4.5:.3g} times its pelvis-to-neck" in deep
    # a clip's edits say it each, as the frame alone does
    clip = {"bvh": text, "units": units, "edits": [
        {"frame": frame, "targets": body["targets"], "options": {"floor": high}},
        {"frame": frame + 1, "targets": body["targets"]},
    ]}  # fmt: skip
    edits = client.post("/v1/bvh/solve/batch", json=clip).json()["edits"]
    assert [e["floor"] for e in edits] == [high, 0.0]
    assert edits[0]["floor_warning"] == said["floor_warning"]
    assert edits[1]["floor_warning"] is None
