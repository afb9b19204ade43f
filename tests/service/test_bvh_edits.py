"""``/v1/bvh/solve`` gives the user's file back with the edit and nothing else: a file whose
frames are wrapped over lines keeps every other byte (line ends, byte order mark, the
hierarchy's text, the other frames), an edit that moves nothing leaves the file as it was,
and the errors reported are those of the file as written (an independent reader checks)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from core.bvh import parse_bvh
from tests.character_files import RefBVH
from tests.conftest import REPO_ROOT, make_client
from tests.core.test_bvh_write import raw, relaid
from tests.service.test_api import assert_problem


def one_a_line(text: str, n_channels: int) -> str:
    """``text`` (its byte order mark dropped) with one frame a line, LF: what the
    independent reader reads."""
    text = text.removeprefix("\ufeff").replace("\r\n", "\n")
    head, _, body = text.partition("Frame Time:")
    time_line, _, values = body.partition("\n")
    words = values.split()
    rows = [" ".join(words[i : i + n_channels]) for i in range(0, len(words), n_channels)]
    return f"{head}Frame Time:{time_line}\n" + "\n".join(rows) + "\n"


def changed_words(old: str, new: str, bvh: Any, frame: int) -> set[str]:
    """The joints one of whose values of ``frame`` the answer writes anew (by the words
    of the frame's span: everything else is compared byte for byte by the caller)."""
    start, end = bvh.frame_span(frame)
    grow = len(new) - len(old)
    assert new[:start] == old[:start] and new[end + grow :] == old[end:]
    a, b = old[start:end].split(), new[start : end + grow].split()
    return {
        j.name for j in bvh.joints
        for c in range(j.channel_start, j.channel_start + len(j.channels)) if a[c] != b[c]
    }  # fmt: skip


def test_a_wrapped_crlf_file_with_a_bom_keeps_every_other_byte(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """An audit (2026-12-06, D4): such a file came back with LF ends, no byte order mark,
    tabs and every number of the file rewritten. Now the edited frame's changed values
    alone differ; the answer is the same bytes run to run, and its reported target error
    is the independent reader's measure of the file as written."""
    source = raw(bvh_files["cmu-daz-salsa"])
    n = parse_bvh(source).num_channels
    text = relaid(source, 11, "\r\n", bom=True)
    frame = 300
    ref = RefBVH(one_a_line(text, n))
    wrist = ref.positions(frame)["lHand"]
    goal = (wrist + np.array([8.0, 6.0, -4.0])).tolist()  # cm
    body = {"bvh": text, "frame": frame, "targets": [{"joint": "lHand", "position": goal}],
            "options": {"reach": "exact"}}  # fmt: skip
    answers = [client.post("/v1/bvh/solve", json=body) for _ in range(2)]
    assert all(r.status_code == 200 for r in answers), answers[0].text
    out = answers[0].json()
    assert answers[1].json()["bvh"] == out["bvh"] and out["units"] == "cm"
    new = out["bvh"]
    assert new.startswith("\ufeff") and new.count("\r\n") == text.count("\r\n")
    assert new.count("\n") == text.count("\n")
    rewritten = changed_words(text, new, parse_bvh(text, "in", frames=[frame]), frame)
    assert rewritten and set(out["changed_joints"]) == rewritten
    after = RefBVH(one_a_line(new, n)).positions(frame)["lHand"]
    error_m = float(np.linalg.norm(after - goal)) * 0.01
    assert abs(out["targets"][0]["error"] - error_m) < 1e-7
    assert out["targets"][0]["reached"] is True


def test_an_edit_that_moves_nothing_leaves_the_file_as_it_was(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """An audit (2026-12-06, D6): a target placed where the joint stands rewrote 46 values
    on 16 joints (the neural path's noise, up to 2.5e-5 degrees a joint) and FABRIK's 6
    values near zero (``-9.35e-15`` -> ``-0.000000``). Now the file comes back as it was,
    ``changed_joints`` empty, the error that of the frame as it stands; an edit that brings
    the target nearer is still written."""
    text = raw(bvh_files["cmu-daz-salsa"])
    frame = 5
    pts = client.post("/v1/bvh/inspect", json={"bvh": text, "frame": frame}).json()["points"]
    here = pts["left_wrist"]
    for method in ("neural", "fabrik"):
        body = {"bvh": text, "frame": frame, "options": {"method": method},
                "targets": [{"joint": "left_wrist", "position": here}]}  # fmt: skip
        r = client.post("/v1/bvh/solve", json=body)
        assert r.status_code == 200, r.text
        out = r.json()
        assert out["bvh"] == text, method
        assert out["changed_joints"] == [], method
        assert out["targets"][0]["error"] < 1e-9 and out["targets"][0]["reached"], method
        moved = {
            **body,
            "targets": [{"joint": "left_wrist", "position": [here[0] + 0.5, *here[1:]]}],
        }
        out = client.post("/v1/bvh/solve", json=moved).json()  # 5 mm (cm units)
        assert out["bvh"] != text and "lForeArm" in out["changed_joints"], method
        assert out["targets"][0]["error"] < 0.005 - 1e-6, method  # nearer than it stood


def test_a_value_beyond_any_body_in_a_wrapped_frame_names_its_own_line(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """The frame is read alone now, so the 422 names the line of the value itself (it
    named the MOTION block's first line for a file whose frames are wrapped)."""
    text = relaid(raw(bvh_files["bandai"]), 11, "\r\n", bom=True)
    bvh = parse_bvh(text, "in", frames=[40])
    span = bvh.frame_span(40)
    assert span is not None
    words = [m for m in re.finditer(r"\S+", text[span[0] : span[1]])]
    at = span[0] + words[30].start()
    bad = text[:at] + "1e9" + text[at + len(words[30].group()) :]
    r = client.post("/v1/bvh/solve", json={"bvh": bad, "frame": 40, "targets": [
        {"joint": "left_wrist", "position": [0, 1, 0]}]})  # fmt: skip
    line = text[:at].count("\n") + 1
    assert r.status_code == 422 and f"bvh: line {line}: frame 40, channel " in r.text, r.text


def test_a_file_cut_short_edits_its_frames_before_the_cut_and_says_where_it_ends(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """An audit (2026-12-06): a file cut inside its last line was answered without a word
    (the editor alone warned), one cut at a line's end (`Frames:` one above its lines) was
    refused whatever frame was asked. Now both edit the frames before the cut, inspect and
    solve say where the file ends (`cut_short`), the answer keeps the rest as sent (the
    cut line too), and the frame at the cut is refused naming its line."""
    from tests.core.test_bvh_cut import _cuts

    text = raw(bvh_files["bandai"])
    here = client.post("/v1/bvh/inspect", json={"bvh": text, "frame": 40}).json()
    assert here["cut_short"] is None
    goal = [v + d for v, d in zip(here["points"]["left_wrist"], (5.0, 5.0, -5.0), strict=True)]
    body = {"frame": 40, "targets": [{"joint": "left_wrist", "position": goal}]}
    whole = client.post("/v1/bvh/solve", json={**body, "bvh": text}).json()
    assert whole["cut_short"] is None
    start, end = parse_bvh(text, "walk", frames=[40]).frame_span(40) or (0, 0)
    line = whole["bvh"][start : whole["bvh"].index("\n", start)]
    for case, (cut_text, cut) in _cuts(text).items():
        told = {"frame": cut.frame, "values": cut.values, "line": cut.line, "frames": 195}
        seen = client.post("/v1/bvh/inspect", json={"bvh": cut_text, "frame": 40}).json()
        assert {k: seen["cut_short"][k] for k in told} == told, case
        assert seen["points"] == here["points"], case
        r = client.post("/v1/bvh/solve", json={**body, "bvh": cut_text})
        assert r.status_code == 200, r.text
        out = r.json()
        assert out["cut_short"] == seen["cut_short"], case
        detail = out["cut_short"]["detail"]
        assert detail.startswith(f"the file is cut short: it ends on line {cut.line}, "), detail
        assert out["bvh"] == cut_text[:start] + line + cut_text[end:], case
        assert out["changed_joints"] == whole["changed_joints"], case
        r = client.post("/v1/bvh/solve", json={**body, "bvh": cut_text, "frame": cut.frame})
        assert r.status_code == 422, r.text
        assert r.json()["detail"].startswith(f"bvh: line {cut.line}: "), r.text


def test_a_file_whose_lines_end_in_cr_alone_comes_back_with_its_own_line_ends(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """An audit (2026-12-06): a classic Mac OS file (CR alone) was read as LF and came back
    with LF ends, every line end of it changed. Now it comes back with CR ends, the answer
    that of the same file with LF ends but for them."""
    lf = raw(bvh_files["bandai"])
    assert "\r" not in lf
    pts = client.post("/v1/bvh/inspect", json={"bvh": lf, "frame": 30}).json()["points"]
    goal = [v + d for v, d in zip(pts["left_wrist"], (6.0, 4.0, -3.0), strict=True)]
    body = {"frame": 30, "targets": [{"joint": "left_wrist", "position": goal}]}
    answers = [
        client.post("/v1/bvh/solve", json={**body, "bvh": text}).json()
        for text in (lf, lf.replace("\n", "\r"))
    ]
    assert answers[0]["changed_joints"] and answers[0]["bvh"] != lf
    assert "\n" not in answers[1]["bvh"]
    assert answers[1]["bvh"] == answers[0]["bvh"].replace("\n", "\r")
    assert answers[1]["targets"] == answers[0]["targets"]


def test_a_joint_with_an_axis_twice_among_its_positions_moves_nothing(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """An audit (2026-12-06): Bandai's `Hips` listing `Xposition Yposition Yposition` (no
    Z) was taken to move the pelvis, and a pelvis target 10 cm along Z was missed by 10 cm
    (its move had no channel to go into: the file came back as sent), and where `Hips`
    turned, its first `Yposition` was written with the second's value. Now the pelvis
    moves through the joint above it with all three (`joint_Root`), and `Hips` keeps its
    position values."""
    text = raw(bvh_files["bandai"]).replace(
        "OFFSET 0 93.9241 -3\n    CHANNELS 6 Xposition Yposition Zposition",
        "OFFSET 0 93.9241 -3\n    CHANNELS 6 Xposition Yposition Yposition",
    )
    pts = client.post("/v1/bvh/inspect", json={"bvh": text, "frame": 30}).json()["points"]
    goal = [pts["pelvis"][0], pts["pelvis"][1], pts["pelvis"][2] + 10.0]
    body = {"bvh": text, "frame": 30, "targets": [{"joint": "pelvis", "position": goal}],
            "options": {"reach": "exact"}}  # fmt: skip
    r = client.post("/v1/bvh/solve", json=body)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["targets"][0]["reached"] and out["targets"][0]["error"] < 1e-6, out["targets"]
    old, new = (parse_bvh(t, "walk", frames=[30]) for t in (text, out["bvh"]))
    hips = old.joints[old.index("Hips")].channel_start
    assert (new.row(30)[hips : hips + 3] == old.row(30)[hips : hips + 3]).all()
    assert "joint_Root" in out["changed_joints"]


def test_a_file_over_the_body_limit_is_told_to_go_as_an_excerpt(
    client: Any, models_dir: Path
) -> None:
    """A body over the limit was answered "body of N bytes exceeds the M-byte limit",
    nothing said of what to do (a new-user audit). The 413 names the server's setting and,
    on the BVH routes, the excerpt the editor sends: made as it says, it is within the
    limit and its frame is answered as the whole file's (only that frame is read)."""
    example = json.loads((REPO_ROOT / "docs/examples/bvh_solve.json").read_text())
    head, _, motion = example["bvh"].partition("Frame Time:")
    time_line, _, frames = motion.partition("\n")
    rows = frames.splitlines()
    big = head.replace("Frames: 3", "Frames: 30") + f"Frame Time:{time_line}\n"
    big += "\n".join(rows * 10) + "\n"
    excerpt = f"{head.replace('Frames: 3', 'Frames: 1')}Frame Time:{time_line}\n{rows[1]}\n"
    whole = {**example, "bvh": big, "frame": 1}
    with make_client(models_dir, max_body_bytes=8192) as small:
        for route in ("/v1/bvh/solve", "/v1/bvh/inspect"):
            r = small.post(route, json=whole)
            detail = assert_problem(r, 413, "-byte limit (the server's POSE_MAX_BODY_BYTES). "
                                    "Send a big file as an excerpt: its text through the "
                                    "'Frame Time:' line with 'Frames: 1', then the line of "
                                    "the frame wanted alone, as frame 0")["detail"]  # fmt: skip
            assert ("goes back in its place" in detail) == route.endswith("solve"), detail
            assert r.json()["type"].endswith("/payload-too-large")
        r = small.post("/v1/bvh/solve", json={**example, "bvh": excerpt, "frame": 0})
        assert r.status_code == 200, r.text
        cut = r.json()
    full = client.post("/v1/bvh/solve", json=whole).json()
    assert full["bvh"].splitlines()[-29] == cut["bvh"].splitlines()[-1]  # frame 1 of 30
    assert full["targets"] == cut["targets"] and full["changed_joints"] == cut["changed_joints"]
    with make_client(models_dir, max_body_bytes=1024) as small:
        body = json.dumps({"items": [example] * 4}).encode()
        for route, said in [
            ("/v1/solve", "send a smaller body"),
            ("/v1/solve/batch", "send a smaller body (a batch's items in several requests)"),
        ]:
            r = small.post(route, content=body, headers={"content-type": "application/json"})
            assert_problem(r, 413, f"body of {len(body)} bytes exceeds the 1024-byte limit "
                           f"(the server's POSE_MAX_BODY_BYTES): {said}")  # fmt: skip
        chunked = small.post("/v1/solve", content=iter([body[:600], body[600:]]),
                             headers={"content-type": "application/json"})  # fmt: skip
        assert_problem(chunked, 413, "body exceeds the 1024-byte limit (the server's "
                       "POSE_MAX_BODY_BYTES): send a smaller body")  # fmt: skip
