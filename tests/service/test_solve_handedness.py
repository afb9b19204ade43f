"""``/v1/solve``'s pose form says when its start pose's left and right look mirrored
(``handedness_warning``): an API audit (2026-12-07) sent the docs' example in left-handed
coordinates (x mirrored, as Unity's) and got it solved as a body seen from behind without a
word, where the character form says so (``sides_warning``). The single answer (the hot path
and the route), each item of a batch and each row of the columnar form say it alike, from
one definition (``service.handed``: ``core.sides.facing_score``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.sides import SWAPPED_BELOW, facing_score
from core.skeleton import JOINT_NAMES
from service.handed import _score_one, handedness_warning, handedness_warnings
from tests.conftest import REPO_ROOT
from tests.service.warned import columns, examples, moved, real_poses, said_alike

MIRROR_X = np.array([-1.0, 1.0, 1.0])


def _mirrored(body: dict[str, Any]) -> dict[str, Any]:
    """``body`` (the pose form) in left-handed coordinates: every x negated."""
    return moved(body, lambda p: p * MIRROR_X)


def test_a_pose_in_left_handed_coordinates_is_said_to_look_mirrored(
    client: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    example, soft = examples()
    for body in (example, soft):
        assert client.post("/v1/solve", json=body).json()["handedness_warning"] is None
        out = client.post("/v1/solve", json=_mirrored(body))
        assert out.status_code == 200, out.text
        warning = out.json()["handedness_warning"]
        assert warning is not None and warning.startswith("pose: its left and right look "), warning
        assert "left-handed coordinates" in warning, warning
    bodies = [soft, _mirrored(soft), example, _mirrored(example)]
    listed = said_alike(client, monkeypatch, bodies)
    assert [a["handedness_warning"] is None for a in listed] == [True, False, True, False]
    col = client.post("/v1/solve/batch", json=columns(bodies[:2]))
    assert col.status_code == 200, col.text
    assert col.json()["handedness_warning"] == [a["handedness_warning"] for a in listed[:2]]


def test_real_poses_are_not_warned_and_their_mirror_images_are(small_dataset: Path) -> None:
    """The TEST split's and the held-out bodies' real poses: no warning; their x-mirrored
    images: a warning but for 65 of 26,458 and 18 of 86,635 (feet and legs that say
    nothing, bodies lying down). A lone
    pose's score is ``facing_score``'s (the fast path of the hot path)."""
    for name in ("test", "holdout"):
        poses = real_poses(name, small_dataset)
        assert handedness_warnings(poses) == [None] * len(poses), name
        said = handedness_warnings(poses * MIRROR_X)
        assert sum(w is None for w in said) < 0.005 * len(poses), name
        some = poses[:: max(1, len(poses) // 300)]
        ones = np.array([_score_one(p) for p in some])
        assert np.abs(ones - facing_score(some)).max() < 1e-12, name
        for p in some[:50]:
            for q in (p, p * MIRROR_X):
                assert handedness_warning(q) == handedness_warnings(q[None])[0]


def test_a_pose_lying_down_says_nothing_of_its_sides() -> None:
    """As the character form: a body not upright along +Y (its up_warning's) gets no
    handedness warning, its legs read along another axis."""
    example = json.loads((REPO_ROOT / "docs/examples/solve.json").read_text())
    pose = np.array([example["pose"][n] for n in JOINT_NAMES]) * MIRROR_X
    assert handedness_warning(pose) is not None and facing_score(pose) < SWAPPED_BELOW
    z_up = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    assert handedness_warning(pose @ z_up) is None
