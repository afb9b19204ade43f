"""An item-list batch tells every bad item's cross-field errors in one 422, character items
as pose items (``service.routes.solve.solve_batch``): the pose items' errors were raised
before any character item was read, and the character items were read one by one until
the first bad one, so a batch of three bad characters was told of items[0] alone, and a
bad character beside a bad pose item of nothing (an API audit, 2026-12-06)."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

from tests.conftest import REPO_ROOT
from tests.service.test_api import assert_problem

EXAMPLES = REPO_ROOT / "docs" / "examples"
Body = dict[str, Any]


def _example(name: str) -> Body:
    body: Body = json.loads((EXAMPLES / f"{name}.json").read_text())
    return body


def _char(change: Callable[[Body], object]) -> Body:
    """The example character item (a real 22-joint skeleton), changed by ``change``."""
    body = _example("solve_character")
    change(body)
    return body


BAD_CHARACTERS = {  # each refused by the reading of the character, with its location
    "character.joints[3].parent": lambda b: b["character"]["joints"][3].update(parent="Hip"),
    "character.units": lambda b: b["character"].update(units=1e-6),  # a body of 4 um
    "targets[0].joint": lambda b: b["targets"][0].update(joint="LeftHnad"),
    "joint_map.left_wrist": lambda b: b.update(joint_map={"left_wrist": "Nope"}),
    "rotations.LeftHand": lambda b: b["rotations"].update(LeftHand=[1e-12, 0.0, 0.0, 0.0]),
}


def _locations(resp: Any) -> list[str]:
    return [e["location"] for e in resp.json()["errors"]]


def test_every_bad_character_item_is_told(client: Any) -> None:
    """Three bad character items: all three listed, each where it is (a location holding
    the client's joint name too: ``rotations.LeftHand``), for every kind of reading error."""
    for field, change in BAD_CHARACTERS.items():
        items = [_char(change) for _ in range(3)]
        resp = client.post("/v1/solve/batch", json={"items": items})
        assert_problem(resp, 422, f"items[0].{field}", f"items[2].{field}")
        assert _locations(resp) == [f"items[{i}].{field}" for i in range(3)], field
        assert "more" not in resp.json()["detail"]


def test_character_and_pose_items_are_told_together_in_item_order(client: Any) -> None:
    """A bad character item before a bad pose item (a pin on its target) and a degenerate
    pose after: every one listed, in item order."""
    pose = _example("solve")
    on_target = {**pose, "pins": ["left_wrist"]}
    flat = {**pose, "pose": {j: [0.0, 1.0, 0.0] for j in pose["pose"]}}
    parent = BAD_CHARACTERS["character.joints[3].parent"]
    items = [_char(parent), pose, on_target, _example("solve_character"), flat]
    resp = client.post("/v1/solve/batch", json={"items": items})
    assert_problem(resp, 422, "items[0].character.joints[3].parent", "items[2].pins[0]")
    assert _locations(resp) == [
        "items[0].character.joints[3].parent", "items[2].pins[0]", "items[4].pose"
    ]  # fmt: skip


def test_a_bad_character_item_among_good_ones_is_told_alone(client: Any) -> None:
    """One bad character item among good pose and character items: its own error, as the
    single request words it (no count, no other item)."""
    good, pose = _example("solve_character"), _example("solve")
    bad = _char(BAD_CHARACTERS["joint_map.left_wrist"])
    resp = client.post("/v1/solve/batch", json={"items": [good, pose, bad, good, pose]})
    assert_problem(resp, 422)
    told = "items[2].joint_map.left_wrist: the skeleton has no joint 'Nope'"
    assert resp.json()["detail"] == told
    assert _locations(resp) == ["items[2].joint_map.left_wrist"]
    alone = client.post("/v1/solve", json=bad).json()
    assert alone["errors"][0]["message"] == resp.json()["errors"][0]["message"]


def test_bad_items_past_three_and_twenty_are_counted(client: Any) -> None:
    """The detail names the first three and counts the rest; the list holds the first 20,
    character and pose items alike."""
    on_target = {**_example("solve"), "pins": ["left_wrist"]}
    bad = _char(BAD_CHARACTERS["character.units"])
    resp = client.post("/v1/solve/batch", json={"items": [bad, on_target, bad, on_target, bad]})
    assert resp.json()["detail"].endswith("; and 2 more")
    assert _locations(resp) == [
        "items[0].character.units", "items[1].pins[0]", "items[2].character.units",
        "items[3].pins[0]", "items[4].character.units",
    ]  # fmt: skip
    resp = client.post("/v1/solve/batch", json={"items": [bad, on_target] * 12})
    assert len(resp.json()["errors"]) == 20 and resp.json()["detail"].endswith("; and 21 more")
    assert _locations(resp)[-2:] == ["items[18].character.units", "items[19].pins[0]"]
