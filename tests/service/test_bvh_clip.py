"""``POST /v1/bvh/solve/batch``: many frames of one file edited in one call. Each edit is
solved as ``/v1/bvh/solve`` solves its frame alone (the same report, bit for bit), the
file comes back as those edits applied one after another would leave it, and the clip is
bounded as a batch is: its edits counted before they are validated, priced by the file's
joints, every edit's own errors told in one 422, the deadline checked between edits."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.retarget import canonical_points
from core.skeleton import JOINT_INDEX
from service.bvh_models import BVHSolveRequest
from service.character_bvh import character_from_bvh, read_request_bvh
from service.routes import characters as routes
from tests.character_files import FILES
from tests.conftest import REPO_ROOT, make_client
from tests.service.test_api import assert_problem

#: (canonical joint, move in metres, reach, pins) of the edits, in turn
EDITS = [
    ("left_wrist", [0.10, 0.12, 0.05], "soft", []),
    ("right_wrist", [-0.08, 0.15, 0.0], "exact", ["left_ankle", "right_ankle"]),
    ("head", [0.0, 0.0, 0.0], "soft", []),  # (where it stands: the frame as sent)
    ("left_ankle", [0.05, 0.10, 0.05], "exact", ["right_ankle"]),
    ("pelvis", [0.0, -0.08, 0.0], "soft", []),
]


def clip_of(text: str, name: str, frames: list[int]) -> dict[str, Any]:
    """A clip body of ``text``: an edit of :data:`EDITS` on each of ``frames``, its target
    its joint's own point moved (in the file's units and axes)."""
    _, _, units, _ = FILES[name]
    read = {"units": units} if units is not None else {}
    bvh = read_request_bvh(text)
    edits = []
    for k, f in enumerate(frames):
        joint, move, reach, pins = EDITS[k % len(EDITS)]
        ask = BVHSolveRequest.model_validate(
            {"bvh": text, "frame": f, "targets": [{"joint": joint, "position": [0, 0, 0]}], **read}
        )
        ch = character_from_bvh(bvh, ask, f)
        at = canonical_points(ch.skel, ch.pose, ch.jmap)[JOINT_INDEX[joint]]
        goal = at + ch.from_service(np.asarray(move))  # (a move: no offset to take off)
        edits.append({"frame": f, "targets": [{"joint": joint, "position": goal.tolist()}],
                      "pins": pins, "options": {"reach": reach}})  # fmt: skip
    return {"bvh": text, **read, "edits": edits}


@pytest.mark.parametrize("name", ["bandai", "reactidle-6ch", "fair1-child-inches-zup"])
def test_a_clip_is_its_frames_edited_one_by_one(
    client: Any, bvh_files: dict[str, Path], name: str
) -> None:
    """Three studios' files (a walk, an idle whose root channels are read as sent, a child
    in inches and +Z up): the clip's file is the file each edit's ``/v1/bvh/solve`` leaves
    when run one after another, in any order; each edit's report is that route's, field for
    field; the clip twice is the same bytes."""
    text = bvh_files[name].read_text()
    n = read_request_bvh(text).num_frames
    frames = [n // 2, 3, n - 1, n // 2 + 1, 0, n // 3]  # (out of order, neighbours, ends)
    body = clip_of(text, name, frames)
    answers = [client.post("/v1/bvh/solve/batch", json=body) for _ in range(2)]
    assert all(r.status_code == 200 for r in answers), answers[0].text
    assert answers[0].content == answers[1].content
    clip = answers[0].json()
    assert [e["frame"] for e in clip["edits"]] == frames
    one_by_one = text
    head = {k: v for k, v in body.items() if k not in ("bvh", "edits")}
    for edit, got in zip(body["edits"], clip["edits"], strict=True):
        alone = client.post("/v1/bvh/solve", json={"bvh": text, **head, **edit}).json()
        assert got == {k: alone[k] for k in got}, edit["frame"]
        assert {k: clip[k] for k in clip if k not in ("bvh", "edits")} == {
            k: alone[k] for k in clip if k not in ("bvh", "edits")
        }
        after = client.post("/v1/bvh/solve", json={"bvh": one_by_one, **head, **edit})
        one_by_one = after.json()["bvh"]
    assert clip["bvh"] == one_by_one
    backwards = text
    for edit in reversed(body["edits"]):  # (in another order: the same file)
        after = client.post("/v1/bvh/solve", json={"bvh": backwards, **head, **edit})
        backwards = after.json()["bvh"]
    assert backwards == one_by_one
    assert sum(bool(e["changed_joints"]) for e in clip["edits"]) >= len(frames) - 1
    assert not clip["edits"][2]["changed_joints"]  # the head where it stands: as sent


def test_every_edit_s_own_errors_are_told_at_once(client: Any, bvh_files: dict[str, Path]) -> None:
    """A frame edited twice, a frame the file does not hold, a joint the file does not
    have, a pin on a target: one 422, each error at its edit's field."""
    text = bvh_files["bandai"].read_text()
    body = clip_of(text, "bandai", [10, 11, 12])
    edits = body["edits"]
    edits.append({**edits[0]})  # frame 10 again
    edits.append({**edits[1], "frame": 10**6})
    edits[1] = {**edits[1], "targets": [{"joint": "Tail", "position": [0, 0, 0]}]}
    edits[2] = {**edits[2], "pins": [edits[2]["targets"][0]["joint"]]}
    resp = client.post("/v1/bvh/solve/batch", json=body)
    problem = assert_problem(resp, 422, "edits[3].frame: frame 10 is edited by edits[0] too")
    where = [e["location"] for e in problem["errors"]]
    assert where == ["edits[1].targets[0].joint", "edits[2].pins[0]", "edits[3].frame",
                     "edits[4].frame"], problem  # fmt: skip
    assert problem["errors"][3]["message"].startswith("1000000 is out of range: the file has")


def test_a_file_s_own_error_is_told_once_in_the_single_route_s_words(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """Units the file does not make plain (the child in inches, none stated) are the
    file's, not each edit's: the clip's 422 is ``/v1/bvh/solve``'s, once."""
    text = bvh_files["fair1-child-inches-zup"].read_text()
    body = clip_of(text, "fair1-child-inches-zup", [5, 6, 7])
    del body["units"]
    clip = client.post("/v1/bvh/solve/batch", json=body)
    alone = client.post("/v1/bvh/solve", json={"bvh": text, **body["edits"][0]})
    problem = assert_problem(clip, 422, "units: not plain from the rest pose")
    assert problem["detail"] == assert_problem(alone, 422)["detail"]
    assert "edits[" not in problem["detail"]


def test_a_clip_is_bounded_as_a_batch_is(models_dir: Path, bvh_files: dict[str, Path]) -> None:
    """More edits than a batch may hold items: a 413 before any edit is validated (each of
    these would be a 422); within the count, past the batch's work limit (two exact edits
    of a 27-joint file cost more than four of the costliest pose items): a 413 naming the
    costliest edit and the price of one."""
    text = bvh_files["bandai"].read_text()
    with make_client(models_dir, max_batch_items=4) as c:
        many = {"bvh": text, "edits": [{"frame": -1, "targets": []}] * 5}
        assert_problem(
            c.post("/v1/bvh/solve/batch", json=many), 413, "edits: 5 edits exceed the limit of 4"
        )
        body = clip_of(text, "bandai", [1, 2])
        resp = c.post("/v1/bvh/solve/batch", json=body)
        said = "(edits[1], 27 joints: 437; one such is taken alone"
        assert_problem(resp, 413, "edits: the batch costs", said,
                       "an edit costs 280 + 3 per 5 joints, 140 more for exact reach")  # fmt: skip
        one = {**body, "edits": body["edits"][1:]}  # one edit alone is never refused for it
        assert c.post("/v1/bvh/solve/batch", json=one).status_code == 200


def test_the_deadline_is_checked_between_edits(
    models_dir: Path, bvh_files: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each edit is solved in its own stage: past the deadline the clip stops with a 504
    that counts the edits done, and solves no more."""
    solved: list[int] = []
    solve = routes.solve_prepared

    def slow(*args: Any) -> Any:
        solved.append(1)
        time.sleep(0.3)
        return solve(*args)

    text = bvh_files["bandai"].read_text()
    body = clip_of(text, "bandai", list(range(20, 30)))
    body["edits"] = [{**e, "pins": [], "options": {"reach": "soft"}} for e in body["edits"]]
    with make_client(models_dir, deadline_seconds=1.0) as c:
        monkeypatch.setattr(routes, "solve_prepared", slow)
        resp = c.post("/v1/bvh/solve/batch", content=json.dumps(body),
                      headers={"content-type": "application/json"})  # fmt: skip
        problem = assert_problem(resp, 504, "1 s deadline", "solving edits[")
    assert "of 10 edits done" in problem["detail"], problem
    assert 2 <= len(solved) < 10


def test_a_clip_over_the_body_limit_is_told_to_go_as_an_excerpt_of_its_frames(
    client: Any, models_dir: Path, bvh_files: dict[str, Path]
) -> None:
    """The 413 of a clip too big to send says how to cut it: the file through its
    'Frame Time:' line with 'Frames:' the frames edited, their lines alone, each edit's
    frame renumbered from 0. Cut so, it is answered as the whole file's frames are."""
    text = bvh_files["bandai"].read_text()
    frames = [40, 41, 42, 90]
    body = clip_of(text, "bandai", frames)
    head, _, motion = text.partition("Frame Time:")
    time_line, _, block = motion.partition("\n")
    rows = block.splitlines()
    n = len(rows)
    excerpt = re.sub(r"Frames:\s*\d+", f"Frames: {len(frames)}", head)
    excerpt += f"Frame Time:{time_line}\n"
    excerpt += "\n".join(rows[f] for f in frames) + "\n"
    cut = {**body, "bvh": excerpt,
           "edits": [{**e, "frame": k} for k, e in enumerate(body["edits"])]}  # fmt: skip
    with make_client(models_dir, max_body_bytes=len(json.dumps(cut)) + 512) as small:
        resp = small.post("/v1/bvh/solve/batch", json=body)
        assert_problem(resp, 413, "(the server's POSE_MAX_BODY_BYTES). Send a big file as an "
                       "excerpt: its text through the 'Frame Time:' line with 'Frames:' the "
                       "count of frames edited, then their lines alone")  # fmt: skip
        part = small.post("/v1/bvh/solve/batch", json=cut)
        assert part.status_code == 200, part.text
    whole = client.post("/v1/bvh/solve/batch", json=body).json()
    got = part.json()
    assert [e["targets"] for e in got["edits"]] == [e["targets"] for e in whole["edits"]]
    back = whole["bvh"].splitlines()
    assert [back[len(back) - n + f] for f in frames] == got["bvh"].splitlines()[-len(frames) :]


def test_a_frame_not_read_as_asked_is_told_per_edit_and_the_file_s_error_once(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """The Z-up child with only frame 40 turned upright along +Y, sent with ``"up": "+Y"``:
    the frames not turned are refused (the rest pose stands along +Z, they do not stand
    along +Y), each edit told with its frame at ``up``, in one 422; a clip of such frames
    alone is told once, in ``/v1/bvh/solve``'s words."""
    from tests.service.test_up_warning import turned_frame

    text = turned_frame(bvh_files["fair1-child-inches-zup"].read_text(), 40)
    head = {"joint": "Head", "position": [0.0, 0.0, 30.0]}
    edits = [{"frame": f, "targets": [head]} for f in (40, 41, 42)]
    body = {"bvh": text, "units": "in", "up": "+Y", "edits": edits}
    problem = assert_problem(client.post("/v1/bvh/solve/batch", json=body), 422)
    assert [e["location"] for e in problem["errors"]] == ["up", "up"], problem
    assert problem["errors"][0]["message"].startswith("edits[1] (frame 41): '+Y'"), problem
    assert problem["errors"][1]["message"].startswith("edits[2] (frame 42): '+Y'"), problem
    alone_body = {k: v for k, v in {**body, **edits[1]}.items() if k != "edits"}
    alone = client.post("/v1/bvh/solve", json=alone_body)
    said = assert_problem(alone, 422)["detail"]
    assert problem["detail"].startswith(f"edits[1] (frame 41): {said}")
    both = {**body, "edits": edits[1:]}
    assert assert_problem(client.post("/v1/bvh/solve/batch", json=both), 422)["detail"] == said


def test_a_clip_s_frames_standing_along_different_axes_ask_for_up(client: Any) -> None:
    """A rest pose that stands along neither axis (the docs' file, every OFFSET turned to
    lie along +X) leaves ``up`` to each frame: a clip whose frames stand along +Y and +Z is
    refused at ``up`` naming both (one file has one up axis), and answered once it is
    given."""
    example = json.loads((REPO_ROOT / "docs/examples/bvh_solve_batch.json").read_text())
    lines = example["bvh"].split("\n")
    for k, line in enumerate(lines):
        if line.strip().startswith("OFFSET"):
            x, y, z = (float(v) for v in line.split()[1:])
            lines[k] = line.split("OFFSET")[0] + f"OFFSET {y:.2f} {-x:.2f} {z:.2f}"
    first = next(k for k, line in enumerate(lines) if line.startswith("Frame Time")) + 1
    for f, turn in enumerate(([90, 0, 0], [0, 0, -90], [90, 0, 0])):  # Z X Y: +X to +Y, +Z
        row = lines[first + f].split()
        row[3:6] = [f"{a:.6f}" for a in turn]
        lines[first + f] = " ".join(row)
    edits = [{"frame": f, "targets": [{"joint": "Head", "position": [0.0, 0.0, 0.0]}]}
             for f in range(3)]  # fmt: skip
    body = {"bvh": "\n".join(lines), "units": "cm", "edits": edits}
    resp = client.post("/v1/bvh/solve/batch", json=body)
    said = "+Y (edits[0], frame 0), +Z (edits[1], frame 1)"
    problem = assert_problem(resp, 422, "up: not given, and the rest pose stands up along "
                             "neither +Y nor +Z", said)  # fmt: skip
    assert problem["errors"][0]["location"] == "up"
    answered = client.post("/v1/bvh/solve/batch", json={**body, "up": "+Y"})
    assert answered.status_code == 200, answered.text


def test_the_deadline_before_the_edits_are_read_is_a_504_counting_none(
    models_dir: Path, bvh_files: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The file read past the deadline: a 504 before the edits are read, counting none
    done (an audit, 2026-12-06: it was a 500, its counts missing ``done``)."""
    read = routes.read_request_bvh

    def slow(*args: Any) -> Any:
        time.sleep(0.6)
        return read(*args)

    body = clip_of(bvh_files["bandai"].read_text(), "bandai", [20, 21, 22])
    monkeypatch.setattr(routes, "read_request_bvh", slow)
    with make_client(models_dir, deadline_seconds=0.5) as c:
        resp = c.post("/v1/bvh/solve/batch", json=body)
        problem = assert_problem(resp, 504, "before reading the edits", "0 of 3 edits done")
    assert (problem["done"], problem["total"]) == (0, 3)


def test_every_edited_frame_s_bad_value_is_told_and_frames_before_the_price(
    models_dir: Path, bvh_files: dict[str, Path]
) -> None:
    """Two edited frames holding values past the bound of a channel's: both told,
    each at its line; and a clip past its work limit whose edits are refused for their
    frames (edited twice, not in the file) is told those (a 422), not to send smaller
    batches of edits that would be refused anyway (an audit, 2026-12-06)."""
    text = bvh_files["bandai"].read_text()
    lines = text.split("\n")
    first = next(k for k, line in enumerate(lines) if line.startswith("Frame Time")) + 1
    for f, word in ((30, "1e9"), (31, "-2e8")):
        row = lines[first + f].split()
        row[7] = word
        lines[first + f] = " ".join(row)
    body = clip_of(text, "bandai", [30, 31, 32])
    body["bvh"] = "\n".join(lines)
    problem = assert_problem(client_post(models_dir, body), 422, "frame 30", "frame 31")
    assert [e["location"] for e in problem["errors"]] == ["bvh", "bvh"]
    clip = clip_of(text, "bandai", [1, 2])
    clip["edits"] += [clip["edits"][0], {**clip["edits"][1], "frame": 10**6}]
    with make_client(models_dir, max_batch_items=4) as c:
        resp = c.post("/v1/bvh/solve/batch", json=clip)
        problem = assert_problem(resp, 422, "edits[2].frame: frame 1 is edited by edits[0]")
        assert [e["location"] for e in problem["errors"]] == ["edits[2].frame", "edits[3].frame"]


def client_post(models_dir: Path, body: dict[str, Any]) -> Any:
    with make_client(models_dir) as c:
        return c.post("/v1/bvh/solve/batch", json=body)
