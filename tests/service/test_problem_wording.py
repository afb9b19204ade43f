"""Problem details worded as what the client sent (an API audit, 2026-12-07): a count of
one is singular ("2 rows for 1 pose", it said "1 poses"); a batch body with ``items`` and a
columnar key says that a batch takes one form, not both (it said "poses: Extra inputs are
not permitted", as if the columnar form's own key were unknown); a 405 names the methods
the path takes, as its ``Allow`` header does (it said "Method Not Allowed" alone)."""

from __future__ import annotations

import json
from typing import Any

import pytest

from core.skeleton import JOINT_NAMES
from tests.conftest import REPO_ROOT

EXAMPLE = json.loads((REPO_ROOT / "docs/examples/solve.json").read_text())
ROW = [v for n in JOINT_NAMES for v in EXAMPLE["pose"][n]]
GOAL = EXAMPLE["targets"][0]["position"]


def test_a_count_of_one_is_singular(client: Any) -> None:
    cases = [
        ({"joints": ["left_wrist"], "positions": [GOAL, GOAL]}, [ROW], "2 rows for 1 pose: "),
        ({"joints": ["left_wrist"], "positions": [GOAL]}, [ROW, ROW], "1 row for 2 poses: "),
        ({"joints": [["left_wrist"]] * 2, "positions": [GOAL]}, [ROW], "2 rows for 1 pose: "),
        ({"joints": ["left_wrist"], "positions": GOAL}, [ROW, ROW], "a list of 2 rows (one per "
         "pose), not one row of 3 numbers"),
    ]  # fmt: skip
    for targets, poses, said in cases:
        out = client.post("/v1/solve/batch", json={"poses": poses, "targets": targets})
        assert out.status_code == 422, out.text
        assert said in out.json()["detail"], out.json()["detail"]
        assert " 1 poses" not in out.json()["detail"] and " 1 rows" not in out.json()["detail"]


@pytest.mark.parametrize("key", ["poses", "targets", "pins", "options"])
def test_a_batch_in_both_forms_is_told_it_takes_one(client: Any, key: str) -> None:
    item = {"pose": EXAMPLE["pose"], "targets": EXAMPLE["targets"]}
    extra: dict[str, Any] = {
        "poses": [ROW], "targets": {"joints": ["left_wrist"], "positions": [GOAL]},
        "pins": ["left_ankle"], "options": {"reach": "exact"},
    }  # fmt: skip
    out = client.post("/v1/solve/batch", json={"items": [item], key: extra[key]})
    assert out.status_code == 422, out.text
    (error,) = out.json()["errors"]
    assert error["location"] == key, error
    assert error["message"].startswith("a batch takes one form, not both: the item list "), error
    assert "Extra inputs" not in out.json()["detail"], out.json()["detail"]
    # the item list alone, and the columnar form alone, as before
    assert client.post("/v1/solve/batch", json={"items": [item]}).status_code == 200
    columns = {"poses": [ROW], "targets": {"joints": ["left_wrist"], "positions": [GOAL]}}
    assert client.post("/v1/solve/batch", json=columns).status_code == 200


def test_a_405_names_the_methods_the_path_takes(client: Any) -> None:
    for method, path, takes in (
        ("GET", "/v1/solve", "POST"),
        ("DELETE", "/v1/models", "GET and HEAD"),
        ("POST", "/v1/skeleton", "GET and HEAD"),
        ("PUT", "/v1/solve/batch", "POST"),
    ):
        out = client.request(method, path)
        assert out.status_code == 405, out.text
        assert out.json()["title"] == "Method Not Allowed"
        assert out.json()["detail"] == f"{method} is not allowed on {path}: it takes {takes}"
        allow = out.headers["allow"].split(", ")
        assert " and ".join([", ".join(allow[:-1]), allow[-1]] if len(allow) > 1 else allow) == (
            takes
        )
