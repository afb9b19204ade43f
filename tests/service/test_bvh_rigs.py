"""A file's rig (its skeleton and joint map) is made once per hierarchy and joint map
(``service.character_bvh.rig_of``, kept in ``BVH.memo``), read-only, and an edit of a file
whose rig was kept is answered byte for byte as the first edit of it."""

from __future__ import annotations

import json
from typing import Any

import pytest

from core import bvh as bvh_module
from service.bvh_models import BVHSolveRequest
from service.character_bvh import RIGS_PER_HIERARCHY, read_request_bvh, rig_of
from tests.conftest import REPO_ROOT

EXAMPLE = json.loads((REPO_ROOT / "docs/examples/bvh_solve.json").read_text())


def _request(**extra: Any) -> BVHSolveRequest:
    return BVHSolveRequest.model_validate({**EXAMPLE, **extra})


def test_an_edit_answered_from_a_kept_rig_is_the_first_answer_byte_for_byte(client: Any) -> None:
    for reach in ("soft", "exact"):
        body = {**EXAMPLE, "options": {"reach": reach}}
        bvh_module._shared.cache_clear()
        cold = client.post("/v1/bvh/solve", json=body)
        warm = client.post("/v1/bvh/solve", json=body)
        assert cold.status_code == 200, cold.text
        assert json.loads(cold.content)["targets"][0]["error"] < 0.5  # a real edit (cm)
        assert cold.content == warm.content


def test_a_rig_is_kept_per_joint_map_read_only_and_bounded() -> None:
    bvh_module._shared.cache_clear()
    req = _request()
    bvh = read_request_bvh(req.bvh, req.frame)
    skel, jmap = rig_of(bvh, req)
    again = read_request_bvh(req.bvh, req.frame)  # another request with the same file
    kept = rig_of(again, req)
    assert kept[0] is skel and kept[1] is jmap
    with pytest.raises(ValueError, match="read-only"):
        skel.offsets[0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        jmap.offsets[0, 0, 0] = 1.0
    # another joint map: its own rig on the same skeleton
    named = jmap.describe()
    skel2, jmap2 = rig_of(again, _request(joint_map={"head": named["head"]}))
    assert skel2 is skel and jmap2 is not jmap
    assert jmap2.scheme.endswith("explicit") and not jmap.scheme.endswith("explicit")
    # past RIGS_PER_HIERARCHY maps, rigs are made each time and not kept
    maps = [
        {joint: named[joint]}
        for joint in ("neck", "pelvis", "left_ankle", "right_ankle", "left_knee")
    ]
    for m in maps:
        rig_of(again, _request(joint_map=m))
    assert sum(k.startswith("rig ") for k in again.memo) == RIGS_PER_HIERARCHY
    assert (
        rig_of(again, _request(joint_map=maps[-1]))[1]
        is not rig_of(again, _request(joint_map=maps[-1]))[1]
    )
