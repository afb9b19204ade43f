"""``/v1/solve``'s pose form says which floor it used (``floor``) and where that floor
lies far from the start pose (``floor_warning``): an API audit (2026-12-07) sent the docs'
example with ``options.floor`` 5 m above the standing body and got no word, where
``/v1/complete`` takes such a floor into the band the networks know and answers the floor
it used. The single answer (the hot path and the route), each item of a batch and each row
of the columnar form say it alike, from one definition (``service.floors``), the band
``/v1/complete`` clamps its floor to. The poses answered do not change."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_NAMES
from service.floors import FLOOR_REACH, SUNK, floor_warning, floor_warnings
from tests.conftest import REPO_ROOT
from tests.service.test_api import BASE
from tests.service.warned import columns, examples, real_poses, said_alike


def _with_floor(body: dict[str, Any], floor: float) -> dict[str, Any]:
    return {**body, "options": {**body.get("options", {}), "floor": floor}}


def test_a_floor_far_from_the_body_is_said_and_the_floor_used_is_answered(
    client: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    example, soft = examples()
    pelvis = example["pose"]["pelvis"][1]  # 0.93 m: the body stands on y = 0
    torso = float(np.linalg.norm(np.subtract(example["pose"]["neck"], example["pose"]["pelvis"])))
    for body in (example, soft):
        near = client.post("/v1/solve", json=body).json()
        assert near["floor"] == 0.0 and near["floor_warning"] is None, near["floor_warning"]
        # a floor under the feet (or a little over them), or one the body stands well
        # above, is no word
        lowest = min(p[1] for p in example["pose"].values())
        for floor in (-0.05, lowest + 0.4 * torso, pelvis - 3.5 * torso):
            ok = client.post("/v1/solve", json=_with_floor(body, floor)).json()
            assert ok["floor"] == floor and ok["floor_warning"] is None, (floor, ok)
        # a floor by the pelvis, the legs under it (a root at the origin: an API audit,
        # 2026-12-07, a rig built so solved up to 4.3 cm off without a word)
        legs = client.post("/v1/solve", json=_with_floor(body, pelvis - 0.01)).json()
        assert "above the start pose's lowest joint" in legs["floor_warning"], legs
        assert "legs under its ground" in legs["floor_warning"]
        above = client.post("/v1/solve", json=_with_floor(body, 5.0))
        assert above.status_code == 200, above.text
        said = above.json()
        assert said["floor"] == 5.0
        warning = said["floor_warning"]
        assert warning is not None and warning.startswith("options.floor: the floor (y = 5 m)"), (
            warning
        )
        assert "4.07 m above the start pose's pelvis" in warning, warning
        # solved as asked: the pose is the one a floor of 5 gives without the warning
        assert said["pose"] == client.post("/v1/solve", json=_with_floor(body, 5.0)).json()["pose"]
        below = client.post("/v1/solve", json=_with_floor(body, -50.0)).json()["floor_warning"]
        assert below is not None and "50.9 m below the start pose's pelvis" in below, below
        assert f"stood more than {FLOOR_REACH:g} times higher" in below, below
    # each item of a batch, and each row of the columnar form, as the single answer says
    bodies = [soft, _with_floor(soft, 5.0), example, _with_floor(example, -50.0)]
    listed = said_alike(client, monkeypatch, bodies)
    assert [a["floor_warning"] is None for a in listed] == [True, False, True, False]
    for floor, item in ((0.0, listed[0]), (5.0, listed[1])):
        col = client.post("/v1/solve/batch", json=columns([soft, soft], floor=floor))
        assert col.status_code == 200, col.text
        assert col.json()["floor"] == floor
        assert col.json()["floor_warning"] == [item["floor_warning"]] * 2


def test_the_solve_warns_where_the_completion_clamps(client: Any) -> None:
    """One band: a floor ``/v1/complete`` takes as given gets no ``floor_warning`` from a
    solve of the same body, and one it moves does."""
    example = json.loads((REPO_ROOT / "docs/examples/solve.json").read_text())
    pose = np.array([example["pose"][n] for n in JOINT_NAMES])
    keypoints = [{"joint": j, "position": example["pose"][j]} for j in BASE]
    for floor in (-5.0, -1.0, -0.5, 0.0, 0.5, 0.92, 0.94, 2.0):
        done = client.post("/v1/complete", json={"keypoints": keypoints, "floor": floor}).json()
        (warning,) = floor_warnings(pose[None], np.array([floor]))
        assert (warning is None) == (done["floor"] == floor), (floor, done["floor"], warning)


def test_no_real_pose_over_its_own_floor_is_warned(small_dataset: Path) -> None:
    """The TEST split's and the held-out bodies' real poses (every frame over its own
    floor, y = 0): no warning (their pelvis stands 0.45-3.5 pelvis-to-neck distances up)."""
    for name in ("test", "holdout"):
        poses = real_poses(name, small_dataset)
        assert floor_warnings(poses, 0.0) == [None] * len(poses), name


def test_a_lone_pose_is_told_as_a_batch_is(small_dataset: Path) -> None:
    """The hot path's lone-pose checks (Python floats) say what the batch's numpy passes
    say, word for word: real TEST poses over floors at, near and past both ends of the
    band, and turned to lean at, near and past the up warning's bound (each of the three
    warnings of ``service.floors``, ``service.upright`` and ``service.handed``)."""
    from scipy.spatial.transform import Rotation

    from service.handed import handedness_warning, handedness_warnings
    from service.upright import LEAN, pose_warning, pose_warnings

    every = real_poses("test", small_dataset)
    poses = every[np.random.default_rng(4).choice(len(every), 200)]
    pelvis, neck = JOINT_NAMES.index("pelvis"), JOINT_NAMES.index("neck")
    torso = np.linalg.norm(poses[:, neck] - poses[:, pelvis], axis=1)
    told = 0
    for b, pose in enumerate(poses):
        py, t = float(pose[pelvis, 1]), float(torso[b])
        legs = float(pose[:, 1].min()) + SUNK * t  # (a floor over it: the legs under it)
        for floor in (0.0, legs, legs + 1e-9, py, py + 1e-12, py - FLOOR_REACH * t, py - 5 * t):
            want = floor_warnings(pose[None], float(floor))[0]
            assert floor_warning(pose, float(floor)) == want
            told += want is not None
        # turned about +X so its trunk leans near the bound (and past it, and upside down)
        trunk = pose[neck] - pose[pelvis]
        now = np.degrees(np.arctan2(np.hypot(trunk[0], trunk[2]), trunk[1]))
        for lean in (LEAN - 1e-6, LEAN + 1e-6, LEAN + 20.0, 175.0):
            turned = (pose - pose[pelvis]) @ Rotation.from_euler(
                "x", lean - now, degrees=True
            ).as_matrix().T
            assert pose_warning(turned) == pose_warnings(turned[None])[0]
            assert handedness_warning(turned) == handedness_warnings(turned[None])[0]
    # past both ends of the band and over the legs' bound: said (at the pelvis too, the
    # body standing); at them: not
    assert 3 * len(poses) < told <= 4 * len(poses), told
