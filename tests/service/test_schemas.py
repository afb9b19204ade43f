"""The integer fields of the request bodies (``service.schemas.WHOLE``: ``frame`` of both
BVH routes, ``options.passes`` of every solve form), through the real routes, with each
number sent as a client writes it in the JSON text."""

from __future__ import annotations

import json
from typing import Any

import pytest

from service.errors import NOT_FINITE
from service.schemas import MAX_WHOLE_FLOAT
from tests.conftest import PosePairs
from tests.service.test_api import assert_problem
from tests.service.test_character_edges import _example
from tests.service.test_columnar import columns

HOLE = "__number__"  # a string in the body, replaced by the number's JSON text

#: (the number as JSON writes it, the message that refuses it)
PAST = "is not a whole number this API reads: a number written with a fraction or an "
BAD: list[tuple[str, str]] = [
    ("1e300", f"1e300 {PAST}exponent stands for one only within ±{MAX_WHOLE_FLOAT}"),
    ("-1e300", f"-1e300 {PAST}exponent stands for one only within ±{MAX_WHOLE_FLOAT}"),
    ("1e20", f"1e20 {PAST}exponent stands for one only within ±{MAX_WHOLE_FLOAT}"),
    ("9007199254740994.0", f"9007199254740994.0 {PAST}exponent stands for one only within"),
    ("3.5", "3.5 is not a whole number"),
    ("1.5e-3", "0.0015 is not a whole number"),
    ("1e400", NOT_FINITE),
    ("-Infinity", NOT_FINITE),
]


def _post(client: Any, path: str, body: dict[str, Any], number: str) -> Any:
    text = json.dumps(body).replace(f'"{HOLE}"', number)
    assert text.count(number) >= 1 and HOLE not in text
    return client.post(path, content=text, headers={"content-type": "application/json"})


def _bodies(real_poses: PosePairs) -> list[tuple[str, dict[str, Any], str]]:
    """(route, body with the number's place, the field's location) for every WHOLE field."""
    bvh = _example("bvh_solve")
    pose = _example("solve")
    col = columns(real_poses, 3)
    col["options"] = {"passes": HOLE}
    return [
        ("/v1/bvh/solve", {**bvh, "frame": HOLE}, "frame"),
        ("/v1/bvh/inspect", {"bvh": bvh["bvh"], "frame": HOLE}, "frame"),
        ("/v1/bvh/solve", {**bvh, "options": {"passes": HOLE}}, "options.passes"),
        ("/v1/solve", {**pose, "options": {"passes": HOLE}}, "options.passes"),
        (
            "/v1/solve/batch",
            {"items": [pose, {**pose, "options": {"passes": HOLE}}]},
            "items[1].options.passes",
        ),
        ("/v1/solve/batch", col, "options.passes"),
    ]


@pytest.mark.parametrize(("number", "message"), BAD, ids=[n for n, _ in BAD])
def test_an_integer_field_refuses_a_float_that_is_no_whole_number_quoting_it(
    client: Any, real_poses: PosePairs, number: str, message: str
) -> None:
    """``"frame": 1e300`` was read as the 301-digit integer the float rounds to (``int()``
    of it) and refused as ``frame: <an integer of 301 digits> is out of range``; ``1e20``
    as ``100000000000000000000``, ``3.5`` as "Input should be a valid integer", quoting
    nothing. Now each is a 422 naming the field and quoting the number as JSON writes it,
    in every field the rule covers."""
    for path, body, where in _bodies(real_poses):
        r = _post(client, path, body, number)
        assert_problem(r, 422)
        got = r.json()
        assert got["detail"].startswith(f"{where}: {message}"), (path, got["detail"])
        assert [e["location"] for e in got["errors"]] == [where], (path, got["errors"])
        assert "digits" not in got["detail"] and "0" * 20 not in got["detail"], got["detail"]
        assert len(got["detail"]) <= 250, got["detail"]


def test_an_integer_field_reads_a_whole_float_as_its_integer(
    client: Any, real_poses: PosePairs
) -> None:
    """A whole number written as a float (``2.0``, ``2e0``) within ±2**53 is the integer
    (as before): the same answer, byte for byte; past the file's frames it is named as the
    integer, as an integer frame is."""
    for path, body, _ in _bodies(real_poses):
        want = _post(client, path, body, "2")
        assert want.status_code == 200, (path, want.text[:300])
        for number in ("2.0", "2e0", "0.2e1"):
            assert _post(client, path, body, number).content == want.content, (path, number)
    bvh = _example("bvh_solve")
    r = _post(client, "/v1/bvh/inspect", {"bvh": bvh["bvh"], "frame": HOLE}, "1e5")
    assert_problem(r, 422)
    assert r.json()["detail"].startswith("frame: 100000 is out of range: the file has "), r.text
