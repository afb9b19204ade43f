"""A character's rig (its skeleton and joint map) is made once for the requests that send
it again (``service.rigs``): a BVH file's per hierarchy and joint map (kept in
``BVH.memo``), a JSON character's per joints and joint map; read-only and bounded, and an
edit answered from a kept rig is the first answer byte for byte. A kept rig's refusals
still name the request's own fields."""

from __future__ import annotations

import json
from typing import Any

import pytest

from core import bvh as bvh_module
from service import rigs
from service.bvh_models import BVHSolveRequest
from service.character_bvh import read_request_bvh, rig_of
from service.rigs import MAPS_PER_SKELETON, SKELETONS
from tests.conftest import REPO_ROOT

EXAMPLE = json.loads((REPO_ROOT / "docs/examples/bvh_solve.json").read_text())
_FORM = json.loads((REPO_ROOT / "docs/examples/character_solve.json").read_text())
#: the example in /v1/solve's character form (its ``skeleton`` sent as ``character``)
CHARACTER = {("character" if k == "skeleton" else k): v for k, v in _FORM.items()}


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
    # past MAPS_PER_SKELETON maps, rigs are made each time and not kept
    maps = [
        {joint: named[joint]}
        for joint in ("neck", "pelvis", "left_ankle", "right_ankle", "left_knee")
    ]
    for m in maps:
        rig_of(again, _request(joint_map=m))
    assert sum(k.startswith("rig ") for k in again.memo) == MAPS_PER_SKELETON
    assert (
        rig_of(again, _request(joint_map=maps[-1]))[1]
        is not rig_of(again, _request(joint_map=maps[-1]))[1]
    )


def test_two_threads_keep_no_more_rigs_than_the_bound(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two threads each making a rig when the memo held 3 both saw room for one and both
    kept theirs: 5 rigs past the bound of 4. Here both are held, with real threads, just
    before keeping (the map made read-only) until both have made theirs; the bound holds,
    and each thread answers its own map's rig."""
    import threading

    bvh_module._shared.cache_clear()
    req = _request()
    bvh = read_request_bvh(req.bvh, req.frame)
    named = rig_of(bvh, req)[1].describe()
    for joint in ("neck", "pelvis"):  # 3 rigs kept: the plain map's and these two
        rig_of(bvh, _request(joint_map={joint: named[joint]}))
    assert sum(k.startswith("rig ") for k in bvh.memo) == MAPS_PER_SKELETON - 1
    both = threading.Barrier(2, timeout=10)
    made = rigs._read_only_map

    def held(jmap: Any) -> Any:
        both.wait()  # (each thread has made its rig, neither has kept it)
        return made(jmap)

    monkeypatch.setattr(rigs, "_read_only_map", held)
    answers: dict[str, Any] = {}

    def edit(joint: str) -> None:
        answers[joint] = rig_of(read_request_bvh(req.bvh, req.frame),
                                _request(joint_map={joint: named[joint]}))  # fmt: skip

    threads = [threading.Thread(target=edit, args=(j,)) for j in ("left_ankle", "right_ankle")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert sorted(answers) == ["left_ankle", "right_ankle"]
    assert sum(k.startswith("rig ") for k in bvh.memo) == MAPS_PER_SKELETON
    for joint, (_, jmap) in answers.items():
        assert jmap.describe()[joint] == named[joint]


def _forget() -> None:
    rigs._SKELETONS.clear()
    rigs._MAPS.clear()


@pytest.mark.parametrize("reach", ["soft", "exact"])
def test_a_characters_edit_from_a_kept_rig_is_the_first_answer_byte_for_byte(
    client: Any, reach: str
) -> None:
    body = {**CHARACTER, "options": {**CHARACTER.get("options", {}), "reach": reach}}
    _forget()
    cold = client.post("/v1/solve", json=body)
    assert cold.status_code == 200, cold.text
    assert len(rigs._SKELETONS) == 1 and len(rigs._MAPS) == 1
    warm = client.post("/v1/solve", json=body)
    assert cold.content == warm.content
    # the same character in a batch's items: one rig, each item's answer the single one's
    batch = client.post("/v1/solve/batch", json={"items": [body, body]})
    assert batch.status_code == 200, batch.text
    assert len(rigs._SKELETONS) == 1
    one = json.loads(cold.content)
    for item in batch.json()["items"]:
        assert item["rotations"] == one["rotations"]


def test_a_characters_kept_rig_is_read_only_and_bounded_and_its_refusals_name_the_field(
    client: Any,
) -> None:
    _forget()
    assert client.post("/v1/solve", json=CHARACTER).status_code == 200
    ((skel, _),) = rigs._SKELETONS.values()
    ((_, jmap),) = rigs._MAPS.items()
    with pytest.raises(ValueError, match="read-only"):
        skel.offsets[0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        jmap.offsets[0, 0, 0] = 1.0
    # other characters (a joint's offset changed) push the first one out, SKELETONS kept
    joints = CHARACTER["character"]["joints"]
    for k in range(SKELETONS + 1):
        moved = [dict(j) for j in joints]
        moved[-1]["offset"] = [o + 0.001 * (k + 1) for o in moved[-1]["offset"]]
        body = {**CHARACTER, "character": {**CHARACTER["character"], "joints": moved}}
        assert client.post("/v1/solve", json=body).status_code == 200
    assert len(rigs._SKELETONS) == SKELETONS
    # a map the skeleton refuses: the request's field named, a batch item's as its own
    bad = {**CHARACTER, "joint_map": {"left_wrist": joints[0]["name"]}}
    single = client.post("/v1/solve", json=bad)
    batch = client.post("/v1/solve/batch", json={"items": [CHARACTER, bad]})
    assert single.status_code == batch.status_code == 422, (single.text, batch.text)
    assert single.json()["errors"][0]["location"].startswith("joint_map")
    assert batch.json()["errors"][0]["location"].startswith("items[1].joint_map"), batch.text
    # so does a skeleton's refusal (a parent no joint has), alone and in a batch
    orphan = [dict(j) for j in joints]
    orphan[-1]["parent"] = "nobody"
    lost = {**CHARACTER, "character": {**CHARACTER["character"], "joints": orphan}}
    for body, at in ((lost, "character.joints"), ({"items": [lost]}, "items[0].")):
        r = client.post("/v1/solve/batch" if "items" in body else "/v1/solve", json=body)
        assert r.status_code == 422 and at in r.text, r.text
