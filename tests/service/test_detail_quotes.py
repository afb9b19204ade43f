"""A problem's detail quotes a client's value as JSON writes it: an API audit (2026-12-07)
got ``not an object ({'x': 1})``, ``(['a', null])`` and ``2 roots ['Hips', 'Spine']``,
Python's ``repr``, where a JSON client sent ``{"x": 1}``. Every route's detail quoting an
object or a list now writes it as JSON (``core.text.shown``, which ``service.errors``
quotes with), so that what it quotes reads back as what was sent."""

from __future__ import annotations

import copy
import json
import re
from typing import Any

from tests.conftest import REPO_ROOT

#: what a detail must not hold: Python's literals and quotes of a value
PYTHON = re.compile(r"\bNone\b|\bTrue\b|\bFalse\b|\{'|\['|', '|': ")
SENT: Any = {"x": 1, "y": [None, True, "a"], "z": {"w": False}}


def _example(name: str) -> dict[str, Any]:
    return json.loads((REPO_ROOT / "docs/examples" / name).read_text())


def _with(body: dict[str, Any], path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    out = copy.deepcopy(body)
    at = out
    for key in path[:-1]:
        at = at[key]
    at[path[-1]] = value
    return out


def test_a_detail_quotes_an_object_or_a_list_as_json(client: Any) -> None:
    solve, complete = _example("solve.json"), _example("complete.json")
    character, bvh = _example("solve_character.json"), _example("bvh_solve.json")
    columns = {"poses": [[0.0] * 63], "targets": {"joints": ["head"], "positions": [[0, 1, 0]]}}
    cases = [
        ("/v1/solve", _with(solve, ("targets", 0, "joint"), SENT), SENT),
        ("/v1/solve", _with(solve, ("pins", 0), ["a", None]), ["a", None]),
        ("/v1/solve/batch", {"items": [_with(solve, ("pins", 1), {"k": True})]}, {"k": True}),
        ("/v1/solve/batch", _with(columns, ("targets", "joints", 0), SENT), SENT),
        ("/v1/complete", _with(complete, ("keypoints", 0, "joint"), SENT), SENT),
        ("/v1/solve", _with(character, ("character", "units"), SENT), SENT),
        ("/v1/bvh/solve", _with(bvh, ("targets", 0, "joint"), SENT), SENT),
        ("/v1/bvh/inspect", {"bvh": bvh["bvh"], "frame": 0, "units": SENT}, SENT),
    ]
    for route, body, sent in cases:
        r = client.post(route, json=body)
        assert r.status_code == 422, (route, r.text)
        problem = r.json()
        said = [problem["detail"], *(e["message"] for e in problem["errors"])]
        assert not any(PYTHON.search(s) for s in said), (route, said)
        quoted = json.dumps(sent)  # (what the detail quotes: the value as JSON writes it)
        assert quoted in problem["detail"], (route, problem["detail"])
        assert json.loads(quoted) == sent
    # names the client gave, listed: a JSON list of them
    two_roots = _with(character, ("character", "joints", 1, "parent"), None)
    detail = client.post("/v1/solve", json=two_roots).json()["detail"]
    name = character["character"]["joints"][1]["name"]
    root = character["character"]["joints"][0]["name"]
    assert f"2 roots {json.dumps([root, name])}; one is needed" in detail, detail
    cycle = _with(character, ("character", "joints", 2, "parent"), name)  # 1 <-> 2
    cycle = _with(
        cycle, ("character", "joints", 1, "parent"), cycle["character"]["joints"][2]["name"]
    )
    detail = client.post("/v1/solve", json=cycle).json()["detail"]
    two = [j["name"] for j in cycle["character"]["joints"][1:3]]
    assert f"parent cycle through joints {json.dumps(two)[:-1]}, " in detail, detail


def test_a_field_that_is_no_object_is_told_in_json_s_words(client: Any) -> None:
    """A field that must be an object and is not was told in pydantic's Python words,
    naming the service's own classes (``pose: Input should be a valid dictionary or
    instance of Pose``; ``instance of ColumnarTargets``: an API audit, 2026-12-07)."""
    solve = _example("solve.json")
    target = solve["targets"][0]
    cases = [
        ("/v1/solve", _with(solve, ("pose",), 5), "pose", "a number (5)"),
        ("/v1/solve", _with(solve, ("pose",), ["a"]), "pose", 'an array (["a"])'),
        ("/v1/solve", _with(solve, ("options",), None), "options", "null"),
        ("/v1/solve/batch", {"poses": [[0.0] * 63], "targets": [target]}, "targets",
         f"an array ({json.dumps([target])})"),
        ("/v1/complete", {"keypoints": ["pelvis"]}, "keypoints[0]", 'a string ("pelvis")'),
    ]  # fmt: skip
    for route, body, where, what in cases:
        problem = client.post(route, json=body).json()
        said = f"{where}: a JSON object is required, not {what}"
        assert problem["detail"].startswith(said), (route, problem["detail"])
        assert "instance of" not in json.dumps(problem), problem


def test_a_pose_keyed_by_a_rigs_own_names_is_told_the_pose_form_s_joints(client: Any) -> None:
    """A game tool's pose keyed by its rig's names (``Head``, ``LeftHand``) was told
    ``pose.Head: Extra inputs are not permitted``, no word of what the form takes (an API
    audit, 2026-12-07); it is told the canonical joints, the one it may mean, and the form
    a rig of its own goes in, in both forms of a batch's item."""
    solve = _example("solve.json")
    pose = dict(solve["pose"])
    pose["Head"] = pose.pop("head")
    pose["LeftHand"] = pose.pop("left_wrist")
    body = {"pose": pose, "targets": solve["targets"]}
    for route, sent, at in (("/v1/solve", body, ""), ("/v1/solve/batch", {"items": [body]},
                                                      "items[0].")):  # fmt: skip
        errors = {
            e["location"]: e["message"] for e in client.post(route, json=sent).json()["errors"]
        }
        head, hand = errors[f"{at}pose.Head"], errors[f"{at}pose.LeftHand"]
        assert head.startswith("unknown joint 'Head' (did you mean 'head'?): the pose form takes")
        assert hand.startswith("unknown joint 'LeftHand': the pose form takes the 21 canonical")
        assert "character form" in hand and errors[f"{at}pose.head"] == "Field required"
