"""Pose requests at the edges a review found (2026-12-04): each gets the problem that names
what was wrong, with the status and headers every other answer gets; never a 500 (the docs'
examples, changed one value at a time)."""

from __future__ import annotations

import copy
import gzip
import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_NAMES, bone_lengths
from tests.conftest import REPO_ROOT, make_client
from tests.service.test_api import assert_problem

EXAMPLES = REPO_ROOT / "docs" / "examples"
EVERY_ANSWER = ("x-request-id", "x-total-time", "x-content-type-options", "content-security-policy")


def _example(name: str) -> dict[str, Any]:
    body: dict[str, Any] = json.loads((EXAMPLES / f"{name}.json").read_text())
    return body


def _columns(n: int = 3) -> dict[str, Any]:
    """The docs' solve example as a columnar batch of ``n`` copies."""
    solve = _example("solve")
    row = [v for j in JOINT_NAMES for v in solve["pose"][j]]
    goals = [v for t in solve["targets"] for v in t["position"]]
    return {
        "poses": [row] * n,
        "targets": {"joints": [t["joint"] for t in solve["targets"]], "positions": [goals] * n},
    }


def _raw(client: Any, path: str, text: str, **headers: str) -> Any:
    return client.post(
        path, content=text.encode(), headers={"content-type": "application/json", **headers}
    )


def test_an_integer_beyond_any_float_is_a_422_in_every_form(client: Any) -> None:
    """A 400-digit JSON integer (valid JSON) where a number goes: a 500 in the columnar form
    before (numpy's OverflowError), 'Input should be a valid number' in the others."""
    huge = "9" * 400
    text = json.dumps(_columns())
    cols = re.sub(r'("poses": \[\[)[^,]+', lambda m: m.group(1) + huge, text, count=1)
    body = assert_problem(_raw(client, "/v1/solve/batch", cols), 422, "poses[0][0]")
    assert body["errors"][0]["location"] == "poses[0][0]"
    solve = json.dumps(_example("solve"))
    x = json.dumps(_example("solve")["targets"][0]["position"][0])
    body = assert_problem(
        _raw(client, "/v1/solve", solve.replace(x, huge, 1)), 422, "beyond any number"
    )
    assert "an integer of 400 digits" in body["detail"], body["detail"]


@pytest.mark.parametrize("field", ["joints", "pins"])
@pytest.mark.parametrize("depth", [800, 1000])
def test_a_joint_name_nested_a_thousand_deep_is_named_not_a_500(
    client: Any, field: str, depth: int
) -> None:
    """orjson reads lists up to 1,024 deep; quoting one in the message recursed past
    Python's stack (a 500 before). Now the value is shown three levels deep; past the
    depth the routes' strict decoder reads (~990), the body is their 400, as on the route
    (the hot path answered its own 422: an audit, 2026-12-06)."""
    deep = "[" * depth + "1.0" + "]" * depth
    cols = _columns(1)
    cols["targets"]["joints"] = ["left_wrist"]
    cols["targets"]["positions"] = [cols["targets"]["positions"][0][:3]]
    if field == "pins":
        cols["pins"] = ["__DEEP__"]
    else:
        cols["targets"]["joints"] = ["__DEEP__"]
    text = json.dumps(cols).replace('"__DEEP__"', deep)
    r = _raw(client, "/v1/solve/batch", text)
    if depth < 900:
        assert_problem(r, 422, "[[[[…]]]]")
    else:
        assert_problem(r, 400, "JSON nested too deeply")
    for name in EVERY_ANSWER[:2]:
        assert name in r.headers


def test_a_500_carries_the_headers_of_every_answer(
    models_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The last-resort 500 was answered outside the timing and hardening layers."""
    with make_client(models_dir) as c:
        engine = c.app.state.pose.repository.engine

        def boom(*_: Any, **__: Any) -> None:
            raise RuntimeError("injected fault")

        monkeypatch.setattr(engine, "solve", boom)
        monkeypatch.setattr(engine, "solve_lone", boom)  # (a lone soft edit's)
        r = c.post("/v1/solve", json=_example("solve"), headers={"X-Request-ID": "r-500"})
        assert_problem(r, 500)
        assert r.headers["x-request-id"] == "r-500"
        for name in EVERY_ANSWER:
            assert name in r.headers, name


def test_cors_preflights_carry_the_headers_of_every_answer(models_dir: Path) -> None:
    """Preflights were answered outside the request id, timing and hardening layers: a
    refused one could not be matched to anything."""
    with make_client(models_dir, cors_origins=["http://editor.example"]) as c:
        for origin, status in (("http://editor.example", 200), ("http://evil.example", 400)):
            r = c.options(
                "/v1/solve", headers={"Origin": origin, "Access-Control-Request-Method": "POST"}
            )
            assert r.status_code == status, r.text
            for name in EVERY_ANSWER[:3]:
                assert name in r.headers, (origin, name)


@pytest.mark.parametrize(
    "path", ["/v1/solve", "/v1/solve/batch", "/v1/complete", "/v1/character/solve",
             "/v1/bvh/solve", "/v1/bvh/inspect"],
)  # fmt: skip
def test_an_empty_body_is_a_400_on_every_route_that_reads_one(client: Any, path: str) -> None:
    """422 'body: Field required' on four routes, 400 on the batch, before."""
    body = assert_problem(_raw(client, path, ""), 400, "no body")
    assert body["type"].endswith("malformed-body")


def test_an_empty_body_by_any_framing_is_a_400(client: Any) -> None:
    """The gate saw only Content-Length 0: a chunked empty body or ``Content-Length: 00``
    still reached FastAPI, which does not read an empty body (422 'Field required')."""
    chunked = client.post(
        "/v1/solve", content=iter([b""]), headers={"content-type": "application/json"}
    )
    assert_problem(chunked, 400, "no body")
    for path in ("/v1/solve", "/v1/solve/batch", "/v1/complete"):
        assert_problem(_raw(client, path, "  \n "), 400, "no body")


def test_an_empty_post_to_no_route_is_still_a_404(client: Any) -> None:
    assert _raw(client, "/v1/nothing-here", "").status_code == 404


def test_a_trailing_slash_is_a_404_that_names_the_route(client: Any) -> None:
    """An API audit (2026-12-05): ``POST /v1/solve/`` was a bare 307 (no problem, no
    body) whose Location repeated the client's Host header. Now a 404 problem that names
    the route; the editor's page alone still redirects, to a path."""
    body = _example("solve")
    for method, path in (("POST", "/v1/solve/"), ("GET", "/v1/skeleton/"), ("GET", "/metrics/")):
        r = client.request(method, path, json=body if method == "POST" else None,
                           headers={"host": "evil.example"}, follow_redirects=False)  # fmt: skip
        assert r.status_code == 404 and "location" not in r.headers, r.headers
        assert r.headers["content-type"] == "application/problem+json"
        assert r.json()["detail"] == (
            f"no route {path}: the route is {path[:-1]}, without the slash"
        )
    assert client.get("/nothing-here/").json()["detail"] == "Not Found"
    r = client.get("/editor/", headers={"host": "evil.example"}, follow_redirects=False)
    assert r.status_code == 307 and r.headers["location"] == "/editor"


def test_field_and_cross_field_errors_are_one_problem_shape(client: Any) -> None:
    """Type invalid-request had two titles, and cross-field errors no ``errors`` list."""
    bad = _example("bad")
    field = assert_problem(client.post("/v1/solve", json=bad), 422)
    twice = _example("solve")
    twice["targets"] = [twice["targets"][0], twice["targets"][0]]
    cross = assert_problem(client.post("/v1/solve", json=twice), 422, "duplicate target")
    assert field["type"] == cross["type"] and field["title"] == cross["title"]
    assert cross["errors"] == [
        {"location": "targets[1]", "message": cross["detail"].partition(": ")[2]}
    ]


@pytest.mark.parametrize(
    ("weights", "needle"), [([float("nan")], "finite"), ([1.0, 2.0], "must hold 1 number, got 2")]
)
def test_shared_columnar_weights_are_named_once_where_they_are(
    client: Any, weights: list[float], needle: str
) -> None:
    """A flat weight list shared by every item was named once per item, at places that do
    not exist in the body (``targets.weights[2][0]``)."""
    cols = _columns(3)
    cols["targets"]["joints"] = cols["targets"]["joints"][:1]
    cols["targets"]["positions"] = [row[:3] for row in cols["targets"]["positions"]]
    cols["targets"]["weights"] = weights
    body = assert_problem(_raw(client, "/v1/solve/batch", json.dumps(cols)), 422, needle)
    where = [e["location"] for e in body["errors"]]
    assert where == (["targets.weights[0]"] if needle == "finite" else ["targets.weights"])


def test_a_batch_over_its_item_limit_is_a_413_before_its_items_are_read(models_dir: Path) -> None:
    """The item list was validated whole before its length was checked: one bad item in
    1,025 gave a 422 there (a 413 in the columnar form), and 8 MiB of items cost a compute
    thread ~1-2 s before their 413."""
    with make_client(models_dir, max_batch_items=4) as c:
        items = [_example("solve")] * 5
        items[1] = {"pose": "not a pose"}
        assert_problem(c.post("/v1/solve/batch", json={"items": items}), 413, "5 items")
        assert c.post("/v1/solve/batch", json={"items": items[:1]}).status_code == 200


def test_a_characters_duplicate_is_named_as_the_client_named_it(client: Any) -> None:
    """'duplicate target for joint left_wrist' named a joint the client never sent."""
    body = _example("solve_character")
    hand = body["targets"][0]["joint"]
    body["targets"] = [body["targets"][0], copy.deepcopy(body["targets"][0])]
    detail = assert_problem(client.post("/v1/solve", json=body), 422)["detail"]
    assert f"'{hand}'" in detail and "mapped to 'left_wrist'" in detail, detail


@pytest.mark.parametrize("coding", ["gzip", "br"])
def test_a_compressed_body_is_a_415(client: Any, coding: str) -> None:
    """A gzip body was read as text (400 'not UTF-8'); a plain one labelled gzip was solved."""
    plain = json.dumps(_example("solve")).encode()
    for content in (gzip.compress(plain), plain):
        r = client.post(
            "/v1/solve", content=content,
            headers={"content-type": "application/json", "content-encoding": coding},
        )  # fmt: skip
        assert_problem(r, 415, coding)
    for listed in ("identity, identity", "identity, gzip"):  # a list of codings (RFC 9110)
        r = client.post(
            "/v1/solve", content=plain,
            headers={"content-type": "application/json", "content-encoding": listed},
        )  # fmt: skip
        if "gzip" in listed:
            assert_problem(r, 415, listed)
        else:  # (a 415 before: an API audit, 2026-12-08)
            assert r.status_code == 200, r.text


def test_a_charset_other_than_utf8_is_a_415(client: Any) -> None:
    """An API audit (2026-12-05): ``charset=latin-1`` was read as UTF-8 (a Latin-1 name
    then got a 400 'not UTF-8'). JSON is UTF-8 (RFC 8259): another charset is a 415 that
    says so; UTF-8 declared in any spelling is served."""
    plain = json.dumps(_example("solve")).encode()
    for ctype in ("application/json; charset=latin-1", 'application/json;charset="UTF-16"'):
        r = client.post("/v1/solve", content=plain, headers={"content-type": ctype})
        assert_problem(r, 415, "charset", "UTF-8")
    for ctype in ("application/json; charset=UTF-8", "application/json;charset=utf8"):
        assert client.post("/v1/solve", content=plain, headers={"content-type": ctype}).is_success


def test_a_mistyped_route_is_a_404_whatever_its_content_type(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """An audit (2026-12-06): ``curl -s .../v1/bvh/slove -d '{}'`` (curl's default form
    content type) was a 415 "content type must be application/json": the client fixed the
    header, then learnt the path was wrong. The route is checked first: no route is a 404
    (a method the route does not take a 405); a route's own body of the wrong type, a 415."""
    form = {"content-type": "application/x-www-form-urlencoded"}
    edit = json.dumps({"bvh": bvh_files["cmu-daz-salsa"].read_text(), "frame": 5})
    for content in ("{}", edit):
        r = client.post("/v1/bvh/slove", content=content, headers=form)
        assert_problem(r, 404)
        r = client.post("/v1/bvh/solve/", content=content, headers=form)
        assert_problem(r, 404, "/v1/bvh/solve")  # (the route without the slash)
        assert_problem(client.post("/v1/bvh/solve", content=content, headers=form), 415)
        assert_problem(client.post("/v2/health/live", content=content, headers=form), 405)
    r = client.post(
        "/v1/bvh/slove", content=gzip.compress(edit.encode()),
        headers={"content-type": "application/json", "content-encoding": "gzip"},
    )  # fmt: skip
    assert_problem(r, 404)
    for path in ("/v1/bvh/inspect", "/v1/bvh/solve/batch", "/v1/solve"):
        assert_problem(client.post(path, content="{}", headers=form), 415, "application/json")


def test_a_compressed_transfer_coding_is_a_415(client: Any) -> None:
    """``Transfer-Encoding: gzip, chunked`` was read as a plain body (and solved)."""
    plain = json.dumps(_example("solve")).encode()
    for coding in ("gzip, chunked", "deflate"):
        r = client.post(
            "/v1/solve", content=gzip.compress(plain),
            headers={"content-type": "application/json", "transfer-encoding": coding},
        )  # fmt: skip
        assert_problem(r, 415, "transfer coding", coding.split(",")[0])
    # the same as two header lines (the last, "chunked", was taken alone)
    r = client.post(
        "/v1/solve", content=gzip.compress(plain),
        headers=[("content-type", "application/json"), ("transfer-encoding", "gzip"),
                 ("transfer-encoding", "chunked")],
    )  # fmt: skip
    assert_problem(r, 415, "transfer coding", "gzip, chunked")
    r = client.post(
        "/v1/solve", content=plain,
        headers={"content-type": "application/json", "transfer-encoding": "chunked"},
    )  # fmt: skip
    assert r.status_code == 200, r.text


def test_completion_refuses_key_points_at_one_spot(client: Any) -> None:
    body = _example("complete")
    for k in body["keypoints"]:
        k["position"] = [1.0, 1.0, 1.0]
    assert_problem(client.post("/v1/complete", json=body), 422, "six base points", "1 cm")
    body = _example("complete")
    pelvis = next(k["position"] for k in body["keypoints"] if k["joint"] == "pelvis")
    for k in body["keypoints"]:
        if k["joint"] == "neck":
            k["position"] = pelvis
    assert_problem(client.post("/v1/complete", json=body), 422, "pelvis and the neck")


@pytest.mark.parametrize("floor", [-50.0, -9999.0])  # and one above the pelvis
def test_a_floor_far_from_the_key_points_gives_a_body_of_their_size(
    client: Any, floor: float
) -> None:
    """A floor 50 m below the key points made bones up to 7 m long (1.4 km at 10 km); 9 m
    above them, 1.25 m. Such floors now give the answer of the lowest floor a body of the
    training data stood on (``service.completion.FLOOR_REACH``), not above the lowest key
    point (no body stands under its ground: a floor at the pelvis read standing key points
    as a body lying there, 93-106 mm off, an API audit, 2026-12-07; no error either way)."""
    body = _example("complete")
    near = client.post("/v1/complete", json=body).json()
    far = client.post("/v1/complete", json={**body, "floor": floor})
    assert far.status_code == 200, far.text
    pose = np.array([far.json()["pose"][j] for j in JOINT_NAMES])
    lengths = bone_lengths(pose)
    ref = bone_lengths(np.array([near["pose"][j] for j in JOINT_NAMES]))
    assert lengths.max() < 0.6 and np.abs(lengths - ref).max() < 0.1, lengths
    points = {k["joint"]: np.array(k["position"]) for k in body["keypoints"]}
    pelvis = float(points["pelvis"][1])
    torso = float(np.linalg.norm(points["neck"] - points["pelvis"]))
    # the answer says which floor was used: the request's where it was taken as given
    assert near["floor"] == body.get("floor", 0.0)
    lowest = min(float(p[1]) for p in points.values())
    assert far.json()["floor"] == pytest.approx(min(pelvis - 4.0 * torso, lowest), abs=1e-12)
    above = client.post("/v1/complete", json={**body, "floor": pelvis + 9.0})
    at = client.post("/v1/complete", json={**body, "floor": pelvis})
    assert above.status_code == at.status_code == 200 and above.json() == at.json()
    assert at.json()["floor"] == lowest


@pytest.mark.parametrize(
    "path",
    ["/v2/health/live", "/v2/health/ready", "/v1/models", "/v1/skeleton", "/metrics", "/docs",
     "/editor", "/openapi.json"],
)  # fmt: skip
def test_every_get_route_answers_head_as_get(client: Any, path: str) -> None:
    """HEAD was a 405 on the health routes, which load balancers probe with, and then on
    every GET route but those (``service.middleware.head``)."""
    get, head = client.get(path), client.head(path)
    assert head.status_code == get.status_code == 200
    assert head.content == b"" and head.headers["content-type"] == get.headers["content-type"]


def test_a_405_allows_head_where_it_allows_get(client: Any) -> None:
    """Every GET route answers HEAD (``service.middleware.head``); a 405's ``Allow`` said
    only GET."""
    r = client.post("/v1/skeleton", json={})
    assert r.status_code == 405
    assert [m.strip() for m in r.headers["allow"].split(",")] == ["GET", "HEAD"]


def test_head_requests_are_counted_under_their_route(models_dir: Path) -> None:
    """A HEAD probe was counted as ``route="unmatched"``: the route the router found was
    written into the GET copy of the scope that the metrics outside never saw."""
    with make_client(models_dir) as c:
        for _ in range(3):
            assert c.head("/v1/skeleton").status_code == 200
        assert c.head("/v2/health/live").status_code == 200
        metrics = c.get("/metrics").text
    assert 'pose_requests_total{route="/v1/skeleton",status="200"} 3.0' in metrics
    assert 'pose_requests_total{route="/v2/health/live",status="200"} 1.0' in metrics
    assert 'route="unmatched"' not in metrics


@pytest.mark.parametrize("joint", ["neck", "spine2", "left_collar"])
def test_exact_reach_lifts_the_body_for_a_trunk_target_out_of_its_reach(
    client: Any, joint: str
) -> None:
    """A neck, chest or collar 3 cm above a standing body is out of reach of a pelvis held
    where it is, and FABRIK holds it when nothing else is targeted: exact reach missed by
    the whole 3 cm (with both ankles pinned the pelvis moved and it was reached). Now the
    body is lifted by what is left and polished again (``Engine._shifted_fallback``);
    plain FABRIK (``method: fabrik``) stays the textbook algorithm."""
    samples = json.loads((REPO_ROOT / "service" / "static" / "samples.json").read_text())
    pose = samples["samples"][0]["pose"]
    goal = [pose[joint][0], pose[joint][1] + 0.03, pose[joint][2]]
    body = {"pose": pose, "targets": [{"joint": joint, "position": goal}]}
    exact = client.post("/v1/solve", json={**body, "options": {"reach": "exact"}}).json()
    assert exact["targets"][0]["reached"] and exact["targets"][0]["error"] < 1e-3, exact
    assert exact["max_bone_length_error"] < 1e-5
    assert min(p[1] for p in exact["pose"].values()) >= min(p[1] for p in pose.values()) - 1e-9
    fabrik = client.post("/v1/solve", json={**body, "options": {"method": "fabrik"}}).json()
    assert fabrik["targets"][0]["error"] > 0.02  # its pelvis held: short by ~the 3 cm


def test_a_problem_location_is_never_read_out_of_a_clients_name() -> None:
    """``error_response`` names the field a cross-field detail starts with, but only a
    field as the messages write them: a client's joint named ``L: Forearm`` or ``Bip01 L
    Forearm`` is not one (the location was ``rotations.L`` for the first)."""
    from service.errors import InvalidRequest, error_response

    def location(detail: str) -> str:
        body = json.loads(bytes(error_response(InvalidRequest(detail)).body))
        where: str = body["errors"][0]["location"]
        return where

    assert location("items[2].targets[1]: duplicate target") == "items[2].targets[1]"
    assert location("rotations.L: Forearm: zero-length quaternion") == "body"
    assert location("rotations.Bip01 L Forearm: zero-length quaternion") == "body"
    assert location("degenerate pose: zero-length bones") == "body"


def test_a_bvh_file_with_a_byte_order_mark_is_read(client: Any) -> None:
    """Windows exporters write a UTF-8 BOM: 'expected HIERARCHY, got \\ufeffHIERARCHY'."""
    body = _example("bvh_solve")
    plain = client.post("/v1/bvh/inspect", json={"bvh": body["bvh"]})
    marked = client.post("/v1/bvh/inspect", json={"bvh": "\ufeff" + body["bvh"]})
    assert plain.status_code == marked.status_code == 200, marked.text
    assert marked.json()["joints"] == plain.json()["joints"]


def test_bad_units_get_one_message_without_pydantics_internals(client: Any) -> None:
    body = _example("solve_character")
    body["character"]["units"] = "CM"
    detail = assert_problem(client.post("/v1/solve", json=body), 422, "must be one of m, cm")[
        "detail"
    ]
    assert "literal[" not in detail and "constrained-float" not in detail, detail


def test_a_nan_channel_is_named_as_a_number_not_numpys_repr(client: Any) -> None:
    body = _example("bvh_solve")
    lines = body["bvh"].split("\n")
    row = next(i for i, ln in enumerate(lines) if ln.startswith("Frame Time")) + 1
    row += body["frame"]  # the frame edited (only that one is read)
    lines[row] = " ".join(["nan", *lines[row].split()[1:]])
    body["bvh"] = "\n".join(lines)
    detail = assert_problem(client.post("/v1/bvh/solve", json=body), 422)["detail"]
    assert "np.float64" not in detail, detail
    assert f"line {row + 1}" in detail and "nan" in detail, detail


@pytest.mark.parametrize("frame", [1, None])
def test_a_bad_value_after_blank_lines_is_named_at_its_own_line(frame: int | None) -> None:
    """A review's find: the line of a NaN was counted from the first frame line as if no
    blank line came before it (line 15 for line 17), in a whole read and one frame's."""
    from service.character_bvh import read_request_bvh
    from service.errors import InvalidRequest

    head = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 3 Xrotation Yrotation Zrotation\n"
    text = head + " End Site\n {\n OFFSET 0 1 0\n }\n}\nMOTION\nFrames: 3\nFrame Time: 0.1\n"
    text += "1 2 3\n\n\n4 nan 6\n7 8 9\n"
    assert text.split("\n")[16] == "4 nan 6"
    with pytest.raises(InvalidRequest, match=r"line 17: frame 1, channel Hips\.Yrotation"):
        read_request_bvh(text, frame)


def test_exact_reach_lifts_a_body_no_higher_than_onto_its_toes(client: Any) -> None:
    """A hand 3 m above a standing body: approached (the fallback lifts the body by at most
    ``service.engine.LIFT`` of its summed bone lengths, ~9 cm here, beyond what the
    networks lifted it), not reached by a body in the air."""
    from service.engine import LIFT

    samples = json.loads((REPO_ROOT / "service" / "static" / "samples.json").read_text())
    pose = samples["samples"][0]["pose"]
    goal = [pose["left_wrist"][0], pose["left_wrist"][1] + 3.0, pose["left_wrist"][2]]
    body = {"pose": pose, "targets": [{"joint": "left_wrist", "position": goal}],
            "options": {"reach": "exact"}}  # fmt: skip
    out = client.post("/v1/solve", json=body).json()
    assert not out["targets"][0]["reached"]
    start = np.array([pose[j] for j in JOINT_NAMES])
    end = np.array([out["pose"][j] for j in JOINT_NAMES])
    rise = end[:, 1].min() - start[:, 1].min()  # the networks' own lift, then the shift's
    assert 0.0 < rise < 2 * LIFT * bone_lengths(start).sum(), rise  # uncapped: ~2.3 m


def test_exact_reach_meets_a_characters_head(client: Any) -> None:
    """A character's head hangs from the neck alone, one bone from a neck point the chest's
    least-squares turn placed millimetres off: exact reach missed a head 2 cm down by
    3-7 mm on every file tried (4.6 mm here). The chest's turn now joins its chain
    (``core.retarget._widened``)."""
    ex = _example("solve_character")
    ex["pins"] = []
    first = client.post("/v1/solve", json={**ex, "targets": ex["targets"][:1]}).json()
    head = next(j["name"] for j in ex["character"]["joints"] if j["name"].lower() == "head")
    goal = [first["positions"][head][0], first["positions"][head][1] - 0.02,
            first["positions"][head][2]]  # fmt: skip
    body = {
        **ex,
        "rotations": first["rotations"],
        "root_position": first["root_position"],
        "targets": [{"joint": head, "position": goal}],
        "options": {"reach": "exact"},
    }
    out = client.post("/v1/solve", json=body).json()
    assert out["targets"][0]["reached"] and out["targets"][0]["error"] < 1e-3, out["targets"]


def test_a_characters_head_reach_leaves_a_pinned_neck_where_it_is(client: Any) -> None:
    """The chest's turn that meets a head (``core.retarget._widened``) is not made where it
    would move a pin or target on the head's own chain (a review found a pinned neck left
    37.5 mm off for a head 2 cm down): the pin holds."""
    ex = _example("solve_character")
    ex["pins"] = []
    first = client.post("/v1/solve", json={**ex, "targets": ex["targets"][:1]}).json()
    names = [j["name"] for j in ex["character"]["joints"]]
    head = next(n for n in names if n.lower() == "head")
    neck = next(n for n in names if n.lower() == "neck")
    at = first["positions"][head]
    body = {
        **ex,
        "rotations": first["rotations"],
        "root_position": first["root_position"],
        "targets": [{"joint": head, "position": [at[0], at[1] - 0.02, at[2]]}],
        "pins": [neck],
        "options": {"reach": "exact"},
    }
    out = client.post("/v1/solve", json=body).json()
    assert out["pins"][0]["reached"] and out["pins"][0]["error"] < 1e-3, out["pins"]


def test_exact_reach_moved_whole_never_loses_a_reached_target_or_sinks(client: Any) -> None:
    """The body moved whole (``Engine._shifted_fallback``) is kept only where no target it
    had reached is lost and no joint sinks below the floor: a review's random search found a
    reached spine2 lost for a nearer wrist, and a polish that took a foot 1.5 mm under the
    floor (rest pose, exact reach, no pins)."""
    from core.rest import rest_pose

    rest = rest_pose()
    pose = {j: [float(v) for v in rest[i]] for i, j in enumerate(JOINT_NAMES)}
    cases = [
        {"spine2": [-0.17111, 1.25736, 0.05017], "left_wrist": [0.71, 1.45, -0.01]},
        {"left_ankle": [0.10957, 0.07841, -0.02048], "left_knee": [0.15494, 0.41029, -0.00352]},
    ]
    for goals in cases:
        targets = [{"joint": j, "position": p} for j, p in goals.items()]
        out = client.post(
            "/v1/solve", json={"pose": pose, "targets": targets, "options": {"reach": "exact"}}
        ).json()
        assert min(p[1] for p in out["pose"].values()) >= -1e-9, out["pose"]
        if "spine2" in goals:
            assert out["targets"][0]["reached"], out["targets"]


@pytest.mark.parametrize("char", ["\x85", "\u2028", "\x0c"])
def test_a_joint_name_with_a_line_break_python_knows_is_read(client: Any, char: str) -> None:
    """The reader split the hierarchy with str.splitlines(), which also breaks at U+0085
    (Windows' '…' read as Latin-1, as the editor reads a file that is not UTF-8), U+2028 and
    form feeds: 'expected {, got x'. Lines end at \\n, \\r\\n or \\r only now."""
    body = _example("bvh_solve")
    text = body["bvh"].replace("JOINT Spine\n", f"JOINT Spine{char}x\n", 1)
    r = client.post("/v1/bvh/inspect", json={"bvh": text})
    assert r.status_code == 200, r.text


def test_a_health_routes_405_allows_get(client: Any) -> None:
    """With HEAD added as a route of its own, a 405 there listed only HEAD (Starlette
    names the first route that matched the path): the contract test's schemathesis run
    flagged it (its schema documents GET)."""
    r = client.post("/v2/health/live", content=b"{}", headers={"content-type": "application/json"})
    assert r.status_code == 405 and "GET" in r.headers["allow"], r.headers


def test_a_lone_surrogate_in_a_key_is_placed_at_the_key_as_one_in_a_value(client: Any) -> None:
    """An audit (2026-12-06): a lone surrogate (``"\\udfff"``: valid JSON, no UTF-8) in an
    object's key was reported at the object (``body`` for a top-level key) in pydantic's
    words ("unable to parse raw data as a unicode string"), naming no key. Now a key is
    placed at its path, the key as JSON escapes it, as a value is at its own."""
    solve = json.dumps(_example("solve"))
    batch = json.dumps({"items": [_example("solve")]})
    columns = json.dumps({**_columns(1), "options": {"reach": "soft"}})
    cases = [  # path, body, location, the string the message names
        ("/v1/solve", solve.replace('"options"', '"\\udfff"'), "\\udfff", "key '\\udfff'"),
        ("/v1/solve", solve.replace('"reach"', '"re\\udfffach"'), "options.re\\udfffach",
         "key 're\\udfffach'"),
        ("/v1/solve", solve.replace('"head"', '"he\\ud800ad"', 1), "pose.he\\ud800ad",
         "key 'he\\ud800ad'"),
        ("/v1/solve/batch", batch.replace('"reach"', '"\\udfff"'), "items[0].options.\\udfff",
         "key '\\udfff'"),
        ("/v1/solve/batch", columns.replace('"reach"', '"\\udfff"'), "options.\\udfff",
         "key '\\udfff'"),
        ("/v1/solve", solve.replace('"joint": "left_wrist"', '"joint": "left\\ud800"', 1),
         "targets[0].joint", "string 'left\\ud800'"),
    ]  # fmt: skip
    assert all(body.count("\\ud") == 1 for _, body, _, _ in cases)  # each replaced once
    for path, body, where, named in cases:
        r = client.post(path, content=body.encode(), headers={"content-type": "application/json"})
        got = assert_problem(r, 422, f"{where}: the {named} holds a lone surrogate")
        assert got["type"].endswith("/invalid-request"), got
        assert got["errors"][0]["location"] == where, got["errors"]
        assert "no UTF-8" in got["errors"][0]["message"], got["errors"]
        assert "unable to parse raw data" not in r.text, r.text


@pytest.mark.parametrize("path", ["/v1/solve", "/v1/solve/batch", "/v1/complete"])
def test_a_json_body_with_a_byte_order_mark_is_read(client: Any, path: str) -> None:
    """A UTF-8 BOM before the JSON (Windows tools write one; RFC 8259 section 8.1 lets a
    parser ignore it) was a 400 telling the client to "decode using utf-8-sig", Python's
    advice to itself. Now it is read as the body without it, small or big (the fast paths,
    the routes, the decoder in steps), and a malformed one still says where."""
    body = {
        "/v1/solve": _example("solve"),
        "/v1/solve/batch": _columns(3),
        "/v1/complete": _example("complete"),
    }[path]
    plain = _raw(client, path, json.dumps(body))
    assert plain.status_code == 200, plain.text
    for pad in ("", " " * 70_000):  # read on the event loop, and in a worker thread
        marked = _raw(client, path, "\ufeff" + json.dumps(body) + pad)
        assert marked.status_code == 200, marked.text
        assert marked.json() == plain.json()
    bad = _raw(client, path, "\ufeff" + json.dumps(body)[:-1])
    assert_problem(bad, 400, "malformed JSON at line 1")
    assert "utf-8-sig" not in bad.json()["detail"]


def test_every_degenerate_pose_of_a_batch_is_named(client: Any) -> None:
    """A pose with a zero-length bone named only the first such pose of a batch, in either
    form (as the repeats did): now every one, the first 20 listed, the rest counted."""
    solve = _example("solve")
    flat = {j: [0.0, 1.0, 0.0] for j in JOINT_NAMES}
    items = [solve, {**solve, "pose": flat}, solve, {**solve, "pose": flat}]
    resp = client.post("/v1/solve/batch", json={"items": items})
    assert_problem(resp, 422, "items[1].pose: degenerate pose", "items[3].pose: degenerate pose")
    assert [e["location"] for e in resp.json()["errors"]] == ["items[1].pose", "items[3].pose"]
    cols = _columns(30)
    for b in range(1, 30, 2):
        cols["poses"][b] = [0.0, 1.0, 0.0] * len(JOINT_NAMES)
    resp = client.post("/v1/solve/batch", json=cols)
    errors = resp.json()["errors"]
    assert [e["location"] for e in errors] == [f"poses[{b}]" for b in range(1, 30, 2)]
    assert errors[0]["message"].startswith("degenerate pose: zero-length bones ending at")
    resp = client.post("/v1/solve/batch", json={"items": [{**solve, "pose": flat}] * 25})
    assert len(resp.json()["errors"]) == 20 and resp.json()["detail"].endswith("; and 22 more")
