"""``/v1/complete`` says when the body it answers is not the size the request gave
(``scale_warning``): an API audit (2026-12-07) sent real key points with ``bone_lengths``
naming one bone, ``{"left_wrist": 2.0}``, and got a body whose bones total 34 m (3.8 m
without), every key point reached, and no word; and key points in centimetres, a body
whose bones total 365 m, no word either."""

from __future__ import annotations

from typing import Any

import numpy as np

from core.skeleton import BONES, JOINT_INDEX, JOINT_NAMES, bone_lengths
from tests.conftest import PosePairs
from tests.service.test_api import BASE, as_array


def _body(pose: np.ndarray, scale: float = 1.0, joints: list[str] = BASE) -> dict[str, Any]:
    return {"keypoints": [{"joint": j, "position": (pose[JOINT_INDEX[j]] * scale).tolist()}
                          for j in joints]}  # fmt: skip


def test_bone_lengths_naming_some_bones_say_the_others_were_scaled(
    client: Any, real_poses: PosePairs
) -> None:
    pose = real_poses.poses[real_poses.goals[0]]
    plain = client.post("/v1/complete", json=_body(pose)).json()
    assert plain["scale_warning"] is None
    out = client.post(
        "/v1/complete", json={**_body(pose), "bone_lengths": {"left_wrist": 2.0}}
    ).json()  # fmt: skip
    total = float(np.sum(bone_lengths(as_array(out["pose"]))))
    assert total > 5 * float(np.sum(bone_lengths(as_array(plain["pose"])))), total
    warning = out["scale_warning"]
    assert warning.startswith(f"bone_lengths names 1 of the {len(BONES)} bones (left_wrist)")
    assert f"the other {len(BONES) - 1} take the reference skeleton's lengths times" in warning
    assert f"bones total {total:.3g} m" in warning, (warning, total)
    # every bone named: the character's own proportions, nothing scaled
    names = [JOINT_NAMES[c] for c, _ in BONES]
    every = dict(zip(names, bone_lengths(pose).tolist(), strict=True))
    whole = client.post("/v1/complete", json={**_body(pose), "bone_lengths": every}).json()
    assert whole["scale_warning"] is None


def test_key_points_of_a_body_out_of_band_are_said_to_be_scaled(
    client: Any, real_poses: PosePairs
) -> None:
    pose = real_poses.poses[real_poses.goals[1]]
    out = client.post("/v1/complete", json=_body(pose, 100.0)).json()  # centimetres
    warning = out["scale_warning"]
    assert warning is not None and warning.startswith("keypoints: the pelvis and the neck lie")
    assert "key points are metres" in warning
    for k in (0.8, 1.0, 1.2):  # bodies the networks know: no word
        assert client.post("/v1/complete", json=_body(pose, k)).json()["scale_warning"] is None


def test_key_points_not_upright_along_y_are_said_to_be_read_lying_down(
    client: Any, real_poses: PosePairs
) -> None:
    """Key points captured with +Z up (a quarter turn about X of real ones), sent as they
    are, were completed as a body lying down with only the clamped ``floor`` to show it
    (an API audit, 2026-12-07): ``up_warning`` says how they were read."""
    pose = real_poses.poses[real_poses.goals[2]]
    upright = client.post("/v1/complete", json=_body(pose)).json()
    assert upright["up_warning"] is None
    z_up = pose @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # y -> z
    out = client.post("/v1/complete", json=_body(z_up)).json()
    trunk = z_up[JOINT_INDEX["neck"]] - z_up[JOINT_INDEX["pelvis"]]
    assert trunk[2] > 0.8 * np.linalg.norm(trunk)  # (upright along +Z)
    warning = out["up_warning"]
    assert warning is not None and "(it runs along +Z)" in warning, warning
    assert warning.startswith("keypoints: the pelvis-to-neck line leans ")
    # a body lying down is completed as asked: the same key points upright, no word
    assert upright["up_warning"] is None and len(out["pose"]) == len(upright["pose"])


def test_bone_lengths_the_key_points_body_does_not_have_are_said(
    client: Any, real_poses: PosePairs
) -> None:
    """Every bone at 1 mm (each within the 1 mm-2 m a bone may be, so no 422) was answered
    200 with key points up to 0.66 m off and no word; at 2 m, a body whose bones total 40 m
    reached every key point folded up, no word either (an API audit, 2026-12-07). The
    answer's ``scale_warning`` says so: the bones' total against the body the key points
    imply, and the key points the bones cannot reach. A body's own bones, at any size the
    networks know and any key point set, get no word."""
    names = [JOINT_NAMES[c] for c, _ in BONES]
    pose = real_poses.poses[real_poses.goals[2]]
    tiny = client.post(
        "/v1/complete", json={**_body(pose), "bone_lengths": dict.fromkeys(names, 0.001)}
    )  # fmt: skip
    assert tiny.status_code == 200, tiny.text
    out = tiny.json()
    assert max(k["error"] for k in out["keypoints"]) > 0.3  # (as answered before: missed)
    warning = out["scale_warning"]
    assert warning is not None and warning.startswith("bone_lengths: the bones total 0.02 m, ")
    assert "times the body the key points imply" in warning, warning
    assert "bone_lengths: these bones cannot reach the key points: neck lies " in warning
    big = client.post(
        "/v1/complete", json={**_body(pose), "bone_lengths": dict.fromkeys(names, 2.0)}
    ).json()  # fmt: skip
    said = big["scale_warning"]
    assert said is not None and said.startswith("bone_lengths: the bones total 40 m, "), said
    assert "cannot reach" not in said  # (every key point reached, folded up)
    for n in (0, 3, 5):
        own = real_poses.poses[real_poses.goals[n]]
        for k in (0.8, 1.0, 1.2):
            every = dict(zip(names, (bone_lengths(own) * k).tolist(), strict=True))
            for joints in (BASE, list(JOINT_NAMES)):
                body = {**_body(own, k, joints), "bone_lengths": every}
                got = client.post("/v1/complete", json=body).json()
                assert got["scale_warning"] is None, (n, k, len(joints), got["scale_warning"])


def test_every_key_point_of_a_body_ten_times_the_size_is_held(
    client: Any, real_poses: PosePairs
) -> None:
    """All 21 joints as key points hold at any size: a bone two key points fix takes their
    distance over 2 m too (a body 10 times ours took the networks' estimate for those bones
    and missed key points by up to 1.56 m, under a warning that it was answered back at the
    key points' size: an API audit, 2026-12-07)."""
    pose = real_poses.poses[real_poses.goals[2]]
    for k in (1.0, 10.0):
        out = client.post("/v1/complete", json=_body(pose, k, list(JOINT_NAMES))).json()
        errors = [p["error"] for p in out["keypoints"]]
        assert max(errors) <= 1e-3 * k, (k, max(errors))
        ratio = bone_lengths(as_array(out["pose"])) / bone_lengths(pose * k)
        np.testing.assert_allclose(ratio, 1.0, atol=1e-6)


def test_a_floor_over_the_key_points_is_read_under_the_lowest(
    client: Any, real_poses: PosePairs
) -> None:
    """A floor above the feet (or the pelvis) is taken down to the lowest key point: it
    read standing key points as a body crouched or lying on that floor, 93-106 mm off (an
    API audit, 2026-12-07). The answer's ``floor`` says the one used; a floor under the
    key points is used as given."""
    pose = real_poses.poses[real_poses.goals[3]]
    lowest = float(min(pose[JOINT_INDEX[j], 1] for j in BASE))
    plain = client.post("/v1/complete", json={**_body(pose), "floor": lowest - 0.01}).json()
    assert plain["floor"] == lowest - 0.01
    for floor in (lowest + 0.3, float(pose[0, 1]) + 0.5, 1e4):
        out = client.post("/v1/complete", json={**_body(pose), "floor": floor}).json()
        assert out["floor"] == lowest, (floor, out["floor"])
        assert all(p["reached"] for p in out["keypoints"]), (floor, out["keypoints"])
