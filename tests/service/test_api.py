"""The REST API against the real models, through the ASGI app with its lifespan."""

from __future__ import annotations

import json
import logging
import math
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX, JOINT_NAMES, bone_lengths
from tests.conftest import REPO_ROOT, PosePairs, make_client

PROBLEM = "application/problem+json"


def as_array(pose: dict[str, list[float]]) -> np.ndarray:
    return np.array([pose[n] for n in JOINT_NAMES], dtype=np.float64)


def engine_pose(engine: Any, body: dict[str, Any]) -> np.ndarray:
    """What ``engine`` answers a pose-form solve body (its targets, default options)."""
    from service.problems import SolveProblem

    pose = as_array(body["pose"])
    idx = np.asarray([JOINT_INDEX[t["joint"]] for t in body["targets"]], dtype=np.intp)
    p = SolveProblem(
        pose=pose, target_idx=idx, target_pos=np.asarray([t["position"] for t in body["targets"]]),
        weights=np.ones(len(idx)), n_targets=len(idx),
    )  # fmt: skip
    (r,) = engine.solve([p])
    return np.asarray(r.pose)


def yaw_shift(yaw: float, shift: tuple[float, float, float], scale: float = 1.0) -> Any:
    c, s = math.cos(yaw), math.sin(yaw)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])

    def apply(p: np.ndarray) -> np.ndarray:
        return np.asarray((p * scale) @ rot.T + np.asarray(shift))

    return apply


def solve_body(
    pairs: PosePairs, k: int, joints: list[str], transform: Any = None, **options: Any
) -> dict[str, Any]:
    start, goal = int(pairs.starts[k]), int(pairs.goals[k])
    goal_pose = pairs.poses[goal] if transform is None else transform(pairs.poses[goal])
    return {
        "pose": pairs.pose_dict(start, transform),
        "targets": [
            {"joint": j, "position": [float(v) for v in goal_pose[JOINT_INDEX[j]]]} for j in joints
        ],
        "options": options,
    }


def assert_problem(resp: Any, status: int, *needles: str) -> dict[str, Any]:
    assert resp.status_code == status, resp.text
    assert resp.headers["content-type"].startswith(PROBLEM)
    body: dict[str, Any] = resp.json()
    assert body["status"] == status and body["title"] and body["detail"]
    for needle in needles:
        assert needle in body["detail"], body["detail"]
    return body


# -- solving ---------------------------------------------------------------------------
def test_solve_reaches_real_targets_with_input_bone_lengths(
    client: Any, real_poses: PosePairs
) -> None:
    reach, polished = [], 0
    for k in range(20):
        body = solve_body(real_poses, k, ["left_wrist", "right_wrist"])
        resp = client.post("/v1/solve", json=body)
        assert resp.status_code == 200, resp.text
        out = resp.json()
        assert set(out["pose"]) == set(JOINT_NAMES)
        assert out["solvers"][0] == "left_wrist+right_wrist"
        # a wrist the retry's pass left short, its collar turned only within the clavicle's
        # cone (core.ends.CLAVICLE_CONE): polished, in 1 of these 20
        assert out["solvers"][1:] in ([], ["fabrik-polish"])
        polished += len(out["solvers"]) - 1
        assert out["method"] == "neural"
        start_len = bone_lengths(as_array(body["pose"]))
        out_len = bone_lengths(as_array(out["pose"]))
        assert np.max(np.abs(out_len / start_len - 1)) <= 1e-5
        assert out["max_bone_length_error"] <= 1e-5
        reach += [t["error"] for t in out["targets"]]
    # soft reach on real edits: centimetres, not decimetres
    assert float(np.mean(reach)) < 0.06, np.mean(reach)
    assert polished <= 1


def test_exact_reach_and_pins(client: Any, synthetic_poses: PosePairs) -> None:
    for k in range(10):
        body = solve_body(synthetic_poses, k, ["left_wrist"], reach="exact", tolerance=0.001)
        body["pins"] = ["left_ankle", "right_ankle"]
        out = client.post("/v1/solve", json=body).json()
        assert out["targets"][0]["reached"], out["targets"]
        assert out["targets"][0]["error"] <= 0.001
        start, end = as_array(body["pose"]), as_array(out["pose"])
        for pin in ("left_ankle", "right_ankle"):
            assert np.linalg.norm(end[JOINT_INDEX[pin]] - start[JOINT_INDEX[pin]]) <= 0.001
        assert out["max_bone_length_error"] <= 1e-5


def test_unreachable_target_is_approached_not_an_error(
    client: Any, synthetic_poses: PosePairs
) -> None:
    """2 m to the right of the shoulder, both feet pinned: beyond any arm, approached. Not
    pinned, exact reach moves the body across until it is reached, as soft reach moves
    its start (``serving.reach_travel``; ``Engine._shifted_fallback``)."""
    body = solve_body(synthetic_poses, 0, ["right_wrist"], reach="exact")
    pose = as_array(body["pose"])
    shoulder = pose[JOINT_INDEX["right_shoulder"]]
    far = shoulder + np.array([-2.0, 0.0, 0.0])  # 2 m to the right: beyond any arm
    body["targets"][0]["position"] = far.tolist()
    free = client.post("/v1/solve", json=body).json()
    assert free["targets"][0]["reached"] is True, free["targets"]
    body["pins"] = ["left_ankle", "right_ankle"]
    resp = client.post("/v1/solve", json=body)
    assert resp.status_code == 200
    out = resp.json()
    assert out["targets"][0]["reached"] is False
    end = as_array(out["pose"])
    assert np.all(np.isfinite(end))
    assert out["max_bone_length_error"] <= 1e-5
    # the wrist moved towards the target
    assert np.linalg.norm(end[JOINT_INDEX["right_wrist"]] - far) < np.linalg.norm(
        pose[JOINT_INDEX["right_wrist"]] - far
    )


@pytest.mark.parametrize("method", ["neural", "fabrik"])
def test_world_space_in_world_space_out(
    client: Any, synthetic_poses: PosePairs, method: str
) -> None:
    """A yawed, displaced copy of the problem gives the same answer, yawed and displaced."""
    move = yaw_shift(-math.pi / 2, (50.0, 0.0, -30.0))
    for k in range(3):
        a = client.post("/v1/solve", json=solve_body(synthetic_poses, k, ["head"], method=method))
        b = client.post(
            "/v1/solve",
            json=solve_body(synthetic_poses, k, ["head"], transform=move, method=method),
        )
        pa, pb = as_array(a.json()["pose"]), as_array(b.json()["pose"])
        assert np.abs(move(pa) - pb).max() < 1e-4


def test_characters_beyond_the_trained_sizes_are_solved_at_scale(
    client: Any, synthetic_poses: PosePairs
) -> None:
    """A 1.5x and a 1.7x character are both solved at the networks' body size: their
    answers are the same pose up to scale, by the same steps (the retry's threshold scales
    with the body too), with each character's own bone lengths."""
    joints = ["left_ankle", "right_ankle"]
    big, bigger = yaw_shift(0.0, (0, 0, 0), scale=1.5), yaw_shift(0.0, (0, 0, 0), scale=1.7)
    ja = client.post("/v1/solve", json=solve_body(synthetic_poses, 1, joints, transform=big))
    jb = client.post("/v1/solve", json=solve_body(synthetic_poses, 1, joints, transform=bigger))
    a, b = as_array(ja.json()["pose"]), as_array(jb.json()["pose"])
    # the networks see both at the same size; with the retry's threshold in metres (5 mm
    # for every body) the bigger one alone took one more pass and the polish; now both
    # take the same steps (here: both polished), and the polish's tolerance (1 mm, the
    # caller's, in metres) leaves them 0.69 mm apart; a scale wrong by the ratio would
    # put them centimetres apart
    assert ja.json()["solvers"] == jb.json()["solvers"]
    assert np.abs(a * (1.7 / 1.5) - b).max() < 1e-3
    start = as_array(solve_body(synthetic_poses, 1, joints, transform=bigger)["pose"])
    assert np.allclose(bone_lengths(b), bone_lengths(start), rtol=1e-5)
    tiny = yaw_shift(0.0, (0, 0, 0), scale=0.6)
    c = client.post("/v1/solve", json=solve_body(synthetic_poses, 1, joints, transform=tiny)).json()
    assert c["max_bone_length_error"] <= 1e-5
    assert max(t["error"] for t in c["targets"]) < 0.1


def test_same_request_same_bits(client: Any, synthetic_poses: PosePairs) -> None:
    body = solve_body(synthetic_poses, 2, ["left_wrist", "head", "right_ankle"], reach="exact")
    first = client.post("/v1/solve", json=body).content
    for k in range(30):  # other traffic in between must not change the answer
        client.post("/v1/solve", json=solve_body(synthetic_poses, k, ["right_wrist"]))
    assert client.post("/v1/solve", json=body).content == first


def test_composition_and_uncovered_joints(client: Any, real_poses: PosePairs) -> None:
    five = ["head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"]
    out = client.post("/v1/solve", json=solve_body(real_poses, 3, five)).json()
    key = "head+left_ankle+left_wrist+right_ankle+right_wrist"
    assert out["solvers"] == [key]  # a trained set: its own solver
    assert max(t["error"] for t in out["targets"]) < 0.15
    # a superset composes: the largest trained subset first, then what it leaves
    out = client.post("/v1/solve", json=solve_body(real_poses, 3, [*five, "left_knee"])).json()
    assert out["solvers"][:2] == [key, "left_knee"]  # (then the retry's polish, if it ran)
    assert set(out["solvers"][2:]) <= {"fabrik-polish"}
    assert max(t["error"] for t in out["targets"]) < 0.15
    out = client.post("/v1/solve", json=solve_body(real_poses, 3, five[:3])).json()
    assert sorted(out["solvers"]) == ["head", "left_wrist+right_wrist"]
    # spine2 has no trained solver: a FABRIK polish places it, holding the others
    out = client.post(
        "/v1/solve", json=solve_body(real_poses, 3, ["spine2", "left_wrist"], reach="soft")
    ).json()
    assert out["solvers"][-1] == "fabrik-polish"
    spine = next(t for t in out["targets"] if t["joint"] == "spine2")
    assert spine["error"] < 0.01
    # out of the spine's reach: the pass's polish, the retry's pass and polish, whose
    # fallback from the start answered; the path names the last of them only
    body = solve_body(real_poses, 3, ["spine2"], reach="soft")
    body["targets"][0]["position"][1] += 0.3
    out = client.post("/v1/solve", json=body).json()
    assert out["targets"][0]["error"] > 0.02 and not out["targets"][0]["reached"]
    assert out["solvers"] == ["fabrik-fallback"]  # the retry's, from the start: named once


def test_weights_order_the_solver_sequence(client: Any, synthetic_poses: PosePairs) -> None:
    body = solve_body(synthetic_poses, 4, ["head", "left_knee"])
    body["targets"][0]["weight"] = 5.0
    assert client.post("/v1/solve", json=body).json()["solvers"] == ["left_knee", "head"]
    body["targets"][0]["weight"] = 0.2
    assert client.post("/v1/solve", json=body).json()["solvers"] == ["head", "left_knee"]


def test_fabrik_method(client: Any, synthetic_poses: PosePairs) -> None:
    body = solve_body(synthetic_poses, 5, ["left_wrist", "right_ankle"], method="fabrik")
    out = client.post("/v1/solve", json=body).json()
    assert out["method"] == "fabrik" and out["solvers"] == ["fabrik"]
    assert out["iterations"] >= 1
    assert out["max_bone_length_error"] <= 1e-5


def test_batch_matches_single_solves(client: Any, synthetic_poses: PosePairs) -> None:
    sets = [["left_wrist"], ["left_ankle", "right_ankle"], ["head", "right_wrist"], ["pelvis"]]
    items = [solve_body(synthetic_poses, k, sets[k % 4]) for k in range(12)]
    items.append(solve_body(synthetic_poses, 12, ["left_knee"], method="fabrik"))
    resp = client.post("/v1/solve/batch", json={"items": items})
    assert resp.status_code == 200, resp.text
    got = resp.json()["items"]
    assert len(got) == len(items)
    for item, out in zip(items, got, strict=True):
        single = client.post("/v1/solve", json=item).json()
        assert single["solvers"] == out["solvers"]
        assert np.abs(as_array(single["pose"]) - as_array(out["pose"])).max() < 1e-5


def test_batch_limit_is_a_413(models_dir: Path, synthetic_poses: PosePairs) -> None:
    with make_client(models_dir, max_batch_items=3) as small:
        items = [solve_body(synthetic_poses, k, ["head"]) for k in range(4)]
        assert_problem(small.post("/v1/solve/batch", json={"items": items}), 413, "limit of 3")
        assert small.post("/v1/solve/batch", json={"items": items[:3]}).status_code == 200


def test_batch_error_names_the_item(client: Any, synthetic_poses: PosePairs) -> None:
    items = [solve_body(synthetic_poses, k, ["head"]) for k in range(3)]
    items[2]["targets"][0]["joint"] = "tail"
    assert_problem(client.post("/v1/solve/batch", json={"items": items}), 422, "items[2]", "tail")


# -- completion ----------------------------------------------------------------------------
BASE = ["pelvis", "neck", "left_wrist", "right_wrist", "left_ankle", "right_ankle"]


def test_complete_from_six_points(client: Any, real_poses: PosePairs) -> None:
    errors = []
    move = yaw_shift(2.0, (3.0, 0.0, -1.0))
    for k in range(10):
        true = move(real_poses.poses[real_poses.goals[k]])
        body = {
            "keypoints": [{"joint": j, "position": true[JOINT_INDEX[j]].tolist()} for j in BASE]
        }
        resp = client.post("/v1/complete", json=body)
        assert resp.status_code == 200, resp.text
        out = resp.json()
        assert out["levels"] == [1]
        pose = as_array(out["pose"])
        errors.append(np.linalg.norm(pose - true, axis=-1).mean())
        assert all(kp["error"] < 0.02 for kp in out["keypoints"])
    assert float(np.mean(errors)) < 0.10, np.mean(errors)


def test_complete_uses_larger_schemes_and_bone_lengths(
    client: Any, synthetic_poses: PosePairs
) -> None:
    true = synthetic_poses.poses[synthetic_poses.goals[0]]
    joints = [*BASE, "head", "left_elbow"]
    lengths = {"left_elbow": 0.3, "left_wrist": 0.25}
    body = {
        "keypoints": [{"joint": j, "position": true[JOINT_INDEX[j]].tolist()} for j in joints],
        "bone_lengths": lengths,
    }
    out = client.post("/v1/complete", json=body).json()
    assert out["levels"] == [1, 2]
    pose = as_array(out["pose"])
    got = bone_lengths(pose)
    from core.skeleton import BONES

    for child, value in lengths.items():
        b = next(i for i, (c, _) in enumerate(BONES) if c == JOINT_INDEX[child])
        assert abs(got[b] - value) < 1e-6


def test_complete_keeps_the_bones_its_key_points_fix(
    client: Any, real_poses: PosePairs, models_dir: Path
) -> None:
    """A bone whose two ends are key points (neck-head, elbow-wrist, knee-ankle ...) has the
    length they fix, and all 21 key points give the pose back (a completion audit: the
    network's estimate of those bones missed 16 and 19 of 20 11- and 16-point requests'
    key points by up to 11 mm, and the 21 points came back 2.9 mm off). A key point whose
    chain to the next has no key point in it (pelvis to neck) may still be out of reach of
    the estimated bones: 2 and 9 of 40 test poses at 11 and 16 points (27 and 38 before,
    `/tmp` count of the TEST split, seed 0)."""
    from core.manifest import load_manifest
    from core.skeleton import BONES

    levels = [list(e.joints) for e in load_manifest(models_dir).completion_levels()]
    assert [len(j) for j in levels] == [6, 11, 16]
    missed = 0
    for k in range(8):
        true = real_poses.poses[real_poses.goals[k]]
        for joints in (levels[1], levels[2], list(JOINT_NAMES)):
            kp = [{"joint": j, "position": true[JOINT_INDEX[j]].tolist()} for j in joints]
            out = client.post("/v1/complete", json={"keypoints": kp}).json()
            missed += not all(p["reached"] for p in out["keypoints"])
            pose = as_array(out["pose"])
            for c, p in BONES:
                if JOINT_NAMES[c] in joints and JOINT_NAMES[p] in joints:
                    want = np.linalg.norm(true[c] - true[p])
                    assert abs(np.linalg.norm(pose[c] - pose[p]) - want) < 1e-9
            if len(joints) == len(JOINT_NAMES):
                assert np.abs(pose - true).max() < 1e-6
    assert missed <= 3, missed  # of 16 requests at 11 and 16 points
    # two key points on one spot fix no bone (a review: a head bone of length 0 came back,
    # a pose /v1/solve then refused as degenerate): the estimate stands
    true = real_poses.poses[real_poses.goals[0]]
    kp = {j: true[JOINT_INDEX[j]].tolist() for j in levels[1]}
    kp["head"] = kp["neck"]
    out = client.post("/v1/complete", json={"keypoints": [
        {"joint": j, "position": p} for j, p in kp.items()]}).json()  # fmt: skip
    pose = as_array(out["pose"])
    assert np.linalg.norm(pose[JOINT_INDEX["head"]] - pose[JOINT_INDEX["neck"]]) > 1e-3
    names = {n: pose[i].tolist() for i, n in enumerate(JOINT_NAMES)}
    again = {"pose": names, "targets": [{"joint": "left_wrist", "position": names["left_wrist"]}]}
    assert client.post("/v1/solve", json=again).status_code == 200


def test_complete_names_missing_base_points(client: Any) -> None:
    body = {
        "keypoints": [
            {"joint": "pelvis", "position": [0, 1, 0]},
            {"joint": "neck", "position": [0, 1.5, 0]},
        ]
    }
    out = assert_problem(client.post("/v1/complete", json=body), 422, "left_wrist", "right_ankle")
    assert out["missing"] == ["left_wrist", "right_wrist", "left_ankle", "right_ankle"]


def test_complete_below_the_floor_names_the_sets_it_takes_and_the_nearests_lack(
    client: Any,
) -> None:
    """Key points below the six base points: the 422 names the key point sets a completion
    takes (6, 11, 16 points: each level's), which of the nearest set are missing, and what
    was given (it said only "the six base points are required; missing [...]", naming
    neither the six nor the larger sets)."""
    six = ["pelvis", "neck", "left_wrist", "right_wrist", "left_ankle", "right_ankle"]
    eleven = [*six, "head", "left_elbow", "right_elbow", "left_knee", "right_knee"]
    given = ["pelvis", "neck", "left_wrist", "head", "left_elbow", "spine1"]  # six, not those
    body = {
        "keypoints": [{"joint": j, "position": [0, 1 + i / 10, 0]} for i, j in enumerate(given)]
    }
    out = assert_problem(client.post("/v1/complete", json=body), 422)
    assert out["missing"] == ["right_wrist", "left_ankle", "right_ankle"]
    assert [len(s) for s in out["key_point_sets"]] == [6, 11, 16]
    assert out["key_point_sets"][:2] == [six, eleven]
    detail = out["detail"]
    assert detail.startswith(
        "keypoints: the nearest key point set a completion takes, the 6 base points, lacks "
        "right_wrist, left_ankle, right_ankle (given: pelvis, neck, left_wrist, head, "
        "left_elbow, spine1); it takes 6 points (pelvis, neck, left_wrist, right_wrist, "
        "left_ankle, right_ankle), 11 (the 6 and head, left_elbow, right_elbow, left_knee, "
        "right_knee) or 16 (the 11 and "
    ), detail
    assert detail.endswith("; any other joints besides"), detail
    assert out["errors"] == [
        {"location": "keypoints", "message": detail.removeprefix("keypoints: ")}
    ]


# -- bad input: always a precise problem+json, never a 500 ----------------------------------
@pytest.mark.parametrize(
    ("mutate", "needle"),
    [
        (lambda b: b["pose"].update(tail=[0, 0, 0]), "pose.tail: unknown joint 'tail': the pose"),
        (lambda b: b["pose"].pop("left_knee"), "pose.left_knee: Field required"),
        (lambda b: b["pose"].update(head=[0.0, 1.0]), "pose.head"),
        (lambda b: b["targets"].append(dict(b["targets"][0])), "duplicate target"),
        (lambda b: b["targets"][0].update(joint="nose"), "unknown joint 'nose'"),
        (lambda b: b.update(pins=["left_wrist"]), "both pinned and targeted"),
        (lambda b: b.update(pins=["elbow"]), "unknown joint 'elbow'"),
        (
            lambda b: b.update(pins=[1]),
            "pins[0]: a joint's name (a string) is needed, not a number",
        ),
        (lambda b: b["targets"][0].update(joint=None), "is needed, not null"),
        (
            lambda b: b.update(pins=[{"joint": "left_ankle", "position": [0, 0, 0]}]),
            "a pin holds a joint where it is: a joint to move is a target",
        ),
        (lambda b: b["targets"][0].update(position=[1, 2, 3, 4]), "targets[0].position"),
        (lambda b: b["pose"].update(left_knee=b["pose"]["left_hip"]), "zero-length bones"),
        (lambda b: b["options"].update(method="magic"), "options.method"),
        (lambda b: b.update(targets=[]), "targets"),
        (lambda b: b["targets"][0].update(position=[1e30, 0, 0]), "beyond"),
    ],
)
def test_bad_requests_are_precise_problems(
    client: Any, synthetic_poses: PosePairs, mutate: Any, needle: str
) -> None:
    body = solve_body(synthetic_poses, 0, ["left_wrist"])
    mutate(body)
    assert_problem(client.post("/v1/solve", json=body), 422, needle)


def test_nan_and_malformed_json(client: Any, synthetic_poses: PosePairs) -> None:
    body = solve_body(synthetic_poses, 0, ["left_wrist"])
    text = json.dumps(body).replace(json.dumps(body["targets"][0]["position"][0]), "NaN", 1)
    resp = client.post("/v1/solve", content=text, headers={"content-type": "application/json"})
    assert_problem(resp, 422, "finite")
    resp = client.post("/v1/solve", content=b"{", headers={"content-type": "application/json"})
    assert_problem(resp, 400, "line 1 column 2")


def test_content_type_and_body_size(models_dir: Path, synthetic_poses: PosePairs) -> None:
    with make_client(models_dir, max_body_bytes=4096) as c:
        body = json.dumps(solve_body(synthetic_poses, 0, ["head"])).encode()
        assert_problem(
            c.post("/v1/solve", content=body, headers={"content-type": "text/plain"}),
            415,
            "application/json",
        )
        huge = body + b" " * 5000
        resp = c.post("/v1/solve", content=huge, headers={"content-type": "application/json"})
        assert_problem(resp, 413, "4096")
        # the connection closes: the body is not worth taking (it stayed open, the client
        # sending the rest; a batch audit)
        assert resp.headers["connection"] == "close"


# -- operations ------------------------------------------------------------------------------
def test_request_id_and_timing_headers(client: Any, synthetic_poses: PosePairs) -> None:
    resp = client.post(
        "/v1/solve",
        json=solve_body(synthetic_poses, 0, ["head"]),
        headers={"X-Request-ID": "abc-123"},
    )
    assert resp.headers["x-request-id"] == "abc-123"
    total = float(resp.headers["x-total-time"].removesuffix("ms"))
    compute = float(resp.headers["x-compute-time"].removesuffix("ms"))
    assert 0 < compute <= total
    generated = client.get("/v2/health/live").headers["x-request-id"]
    assert len(generated) == 32
    ids = {client.get("/v2/health/live").headers["x-request-id"] for _ in range(300)}
    assert len(ids) == 300 and all(len(i) == 32 and int(i, 16) >= 0 for i in ids)  # hex


def test_health_metrics_skeleton_models(
    client: Any, synthetic_poses: PosePairs, models_dir: Path
) -> None:
    assert client.get("/v2/health/live").json()["status"] == "live"
    assert client.get("/v2/health/ready").status_code == 200
    client.post("/v1/solve", json=solve_body(synthetic_poses, 0, ["left_wrist", "right_wrist"]))
    metrics = client.get("/metrics").text
    assert 'pose_solves_total{method="neural",solvers="left_wrist+right_wrist"}' in metrics
    assert "pose_request_seconds_bucket" in metrics
    sk = client.get("/v1/skeleton").json()
    assert sk["joints"] == list(JOINT_NAMES) and sk["parents"]["left_elbow"] == "left_shoulder"
    assert sk["frame"]["up"] == "+Y"
    models = client.get("/v1/models").json()
    manifest = json.loads((models_dir / "manifest.json").read_text())
    assert models["version"] == manifest["version"]
    assert "left_wrist+right_wrist" in models["solver_sets"]


def test_corrupt_model_is_not_ready_with_a_reason(
    models_dir: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture, synthetic_poses: PosePairs
) -> None:
    broken = tmp_path / "models"
    shutil.copytree(models_dir, broken)
    (broken / "decoder.onnx").write_bytes(b"garbage")
    with caplog.at_level(logging.ERROR, logger="service"), make_client(broken) as c:
        resp = c.get("/v2/health/ready")
        assert resp.status_code == 503
        assert "decoder.onnx" in resp.json()["detail"]
        assert c.get("/v2/health/live").status_code == 200
        assert_problem(c.post("/v1/skeleton"), 405)
        # the skeleton comes from the manifest alone, so it is served while not ready
        assert c.get("/v1/skeleton").json()["joints"] == list(JOINT_NAMES)
        out = c.post("/v1/solve", json=solve_body(synthetic_poses, 0, ["head"]))
        assert_problem(out, 503, "decoder.onnx")
        # a columnar batch is read as when ready (its errors were pydantic's words while
        # the models loaded: "List should have at least 63 items"), then the 503
        pose = solve_body(synthetic_poses, 0, ["head"])["pose"]
        row = [x for name in JOINT_NAMES for x in pose[name]]
        columns = {"poses": [row[:62]], "targets": {"joints": ["head"], "positions": [[0, 1, 0]]}}
        out = c.post("/v1/solve/batch", json=columns)
        assert_problem(out, 422, "poses[0]: must hold 63 numbers, got 62")
        out = c.post("/v1/solve/batch", json={**columns, "poses": [row]})
        assert_problem(out, 503, "decoder.onnx")
        # reading a file needs no models: inspect answers (its contract's 503 is shutdown's)
        example = json.loads((REPO_ROOT / "docs/examples/bvh_solve.json").read_text())
        inspect = {"bvh": example["bvh"], "frame": example["frame"]}
        assert c.post("/v1/bvh/inspect", json=inspect).status_code == 200
    assert any("decoder.onnx" in r.getMessage() for r in caplog.records)


def test_composition_settings_the_models_ignore_are_named_at_load(
    models_dir: Path, client: Any, caplog: pytest.LogCaptureFixture, synthetic_poses: PosePairs
) -> None:
    """The shipped models answer in deltas, where the latent chain's passes and projections
    change nothing: a deployment that sets them is told so in the log at load, and its
    answers are the default's, byte for byte (a composed set: head, both elbows)."""
    body = solve_body(synthetic_poses, 0, ["head", "left_elbow", "right_elbow"])
    with (
        caplog.at_level(logging.WARNING, logger="service"),
        make_client(models_dir, composition_passes=2, composition_projections=0) as c,
    ):
        assert (
            c.post("/v1/solve", json=body).json()["pose"]
            == client.post("/v1/solve", json=body).json()["pose"]
        )
    (line,) = [
        json.loads(r.getMessage()) for r in caplog.records if "settings_ignored" in r.getMessage()
    ]
    assert line["settings"] == ["POSE_COMPOSITION_PASSES", "POSE_COMPOSITION_PROJECTIONS"]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="service"), make_client(models_dir) as c:
        assert c.get("/v2/health/ready").status_code == 200
    assert not [r for r in caplog.records if "settings_ignored" in r.getMessage()]


def test_api_key_guards_v1_only(models_dir: Path, synthetic_poses: PosePairs) -> None:
    with make_client(models_dir, api_key="s3cret") as c:
        body = solve_body(synthetic_poses, 0, ["head"])
        assert_problem(c.post("/v1/solve", json=body), 401)
        assert c.post("/v1/solve", json=body, headers={"X-API-Key": "s3cret"}).status_code == 200
        assert c.get("/v2/health/ready").status_code == 200
        assert c.get("/metrics").status_code == 200


def test_cors_allow_list(models_dir: Path) -> None:
    with make_client(models_dir, cors_origins=["http://editor.example"]) as c:
        ok = c.options(
            "/v1/solve",
            headers={"Origin": "http://editor.example", "Access-Control-Request-Method": "POST"},
        )
        assert ok.headers.get("access-control-allow-origin") == "http://editor.example"
        other = c.get("/v2/health/live", headers={"Origin": "http://evil.example"})
        assert "access-control-allow-origin" not in other.headers


def test_batch_pose_error_names_the_item_and_joint(client: Any, synthetic_poses: PosePairs) -> None:
    items = [solve_body(synthetic_poses, k, ["head"]) for k in range(3)]
    items[1]["pose"]["left_knee"] = items[1]["pose"]["left_hip"]
    assert_problem(
        client.post("/v1/solve/batch", json={"items": items}), 422, "items[1].pose", "left_knee"
    )


def test_floor_option_makes_raised_characters_solve_alike(
    client: Any, synthetic_poses: PosePairs
) -> None:
    lift = yaw_shift(0.0, (0.0, 1.0, 0.0))
    ground = client.post("/v1/solve", json=solve_body(synthetic_poses, 6, ["left_wrist"])).json()
    body = solve_body(synthetic_poses, 6, ["left_wrist"], transform=lift)
    body["options"]["floor"] = 1.0
    raised = client.post("/v1/solve", json=body).json()
    assert np.abs(lift(as_array(ground["pose"])) - as_array(raised["pose"])).max() < 1e-6
    true = synthetic_poses.poses[synthetic_poses.goals[0]]
    points = [{"joint": j, "position": lift(true)[JOINT_INDEX[j]].tolist()} for j in BASE]
    done = client.post("/v1/complete", json={"keypoints": points, "floor": 1.0}).json()
    flat = [{"joint": j, "position": true[JOINT_INDEX[j]].tolist()} for j in BASE]
    base = client.post("/v1/complete", json={"keypoints": flat}).json()
    assert np.abs(lift(as_array(base["pose"])) - as_array(done["pose"])).max() < 1e-6


def test_chunked_body_over_the_limit_is_a_413(models_dir: Path, synthetic_poses: PosePairs) -> None:
    body = json.dumps(solve_body(synthetic_poses, 0, ["head"])).encode() + b" " * 6000
    chunks = [body[i : i + 1000] for i in range(0, len(body), 1000)]
    with make_client(models_dir, max_body_bytes=4096) as c:
        resp = c.post(
            "/v1/solve", content=iter(chunks), headers={"content-type": "application/json"}
        )
        assert_problem(resp, 413, "4096")
        assert resp.headers["connection"] == "close"  # the rest of the body is not read
        small = json.dumps(solve_body(synthetic_poses, 0, ["head"])).encode()
        ok = c.post(
            "/v1/solve",
            content=iter([small[:500], small[500:]]),
            headers={"content-type": "application/json"},
        )
        assert ok.status_code == 200, ok.text


def test_gate_rejections_carry_cors_and_keys_are_strict(
    models_dir: Path, synthetic_poses: PosePairs
) -> None:
    origin = {"Origin": "http://editor.example"}
    with make_client(models_dir, api_key="s3cret", cors_origins=["http://editor.example"]) as c:
        body = solve_body(synthetic_poses, 0, ["head"])
        resp = c.post("/v1/solve", json=body, headers=origin)
        assert_problem(resp, 401)
        assert resp.headers["access-control-allow-origin"] == "http://editor.example"
        assert (
            c.post("/v1/solve", json=body, headers={"Authorization": "s3cret"}).status_code == 401
        )
        bearer = {"Authorization": "Bearer s3cret"}
        assert c.post("/v1/solve", json=body, headers=bearer).status_code == 200
    from pydantic import ValidationError

    from service.settings import Settings

    # an empty key meant no key: /v1 open to anyone while the operator believed it guarded
    for blank in ("", "  "):
        with pytest.raises(ValidationError, match="empty or only blanks"):
            Settings(models_dir=models_dir, api_key=blank)
    for padded in ("s3cret\n", " s3cret", "s3cret\t"):  # (a Secret made from a file)
        with pytest.raises(ValidationError, match="blanks or a newline before or after"):
            Settings(models_dir=models_dir, api_key=padded)
    assert Settings(models_dir=models_dir, api_key="s3 cret").api_key is not None
    assert Settings(models_dir=models_dir).api_key is None  # unset: no key, as documented


def test_unexpected_errors_keep_the_request_id(
    models_dir: Path, synthetic_poses: PosePairs, monkeypatch: pytest.MonkeyPatch
) -> None:
    with make_client(models_dir) as c:
        engine = c.app.state.pose.repository.engine

        def boom(*_: Any) -> None:
            raise RuntimeError("injected fault")

        monkeypatch.setattr(engine, "solve", boom)
        monkeypatch.setattr(engine, "solve_lone", boom)  # (a lone soft edit's)
        resp = c.post(
            "/v1/solve",
            json=solve_body(synthetic_poses, 0, ["head"]),
            headers={"X-Request-ID": "r-1"},
        )
        assert_problem(resp, 500)
        assert resp.headers["x-request-id"] == "r-1"
        assert "injected" not in resp.text  # no internals leak to the client


def test_degenerate_completion_inputs_are_rejected(client: Any, synthetic_poses: PosePairs) -> None:
    true = synthetic_poses.poses[synthetic_poses.goals[0]]
    points = [{"joint": j, "position": true[JOINT_INDEX[j]].tolist()} for j in BASE]
    resp = client.post(
        "/v1/complete", json={"keypoints": points, "bone_lengths": {"left_knee": 1e-200}}
    )
    assert_problem(resp, 422, "bone_lengths")
    body = solve_body(synthetic_poses, 0, ["head"], reach="exact", tolerance=1e-300)
    assert_problem(client.post("/v1/solve", json=body), 422, "tolerance")


def test_a_manifest_edited_by_hand_is_named_at_load(
    models_dir: Path,
    tmp_path: Path,
    caplog: pytest.LogCaptureFixture,
    synthetic_poses: PosePairs,
) -> None:
    """A serving block edited by hand (``passes`` 2 -> 3: other answers under the same
    ``model``; an audit, 2026-12-07) is named in a ``manifest_edited`` warning and served,
    in ``/v1/models`` and in answers, under the version of its content; the shipped folder,
    and one set with ``pose-trainer serving`` (``write_manifest``: a version and content
    sha256 of its own), are not."""
    from core.manifest import load_manifest, write_manifest

    edited = tmp_path / "models"
    shutil.copytree(models_dir, edited)
    manifest = json.loads((edited / "manifest.json").read_text())
    manifest["serving"]["passes"] = 3
    (edited / "manifest.json").write_text(json.dumps(manifest))
    as_set = load_manifest(edited, verify=False)
    assert as_set.version != manifest["version"]
    body = solve_body(synthetic_poses, 0, ["left_wrist"])
    with caplog.at_level(logging.WARNING, logger="service"), make_client(edited) as c:
        assert c.get("/v1/models").json()["version"] == as_set.version
        assert c.post("/v1/solve", json=body).json()["model"] == as_set.version
    (line,) = [
        json.loads(r.getMessage()) for r in caplog.records if "manifest_edited" in r.getMessage()
    ]
    assert line["version"] == line["content_version"] == as_set.version
    assert line["written_version"] == manifest["version"]
    write_manifest(edited, as_set)  # as pose-trainer serving writes it (a version of its own)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="service"), make_client(edited) as c:
        assert c.get("/v2/health/ready").status_code == 200
    with caplog.at_level(logging.WARNING, logger="service"), make_client(models_dir) as c:
        assert c.get("/v2/health/ready").status_code == 200
        assert c.get("/v1/models").json()["version"] == manifest["version"]
    assert not [r for r in caplog.records if "manifest_edited" in r.getMessage()]
