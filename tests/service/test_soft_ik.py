"""``options.soft_ik`` (kept limbs ease into full stretch: ``core.ends.soft_reach``), for
cleaning clips: a wrist dragged across the arm's reach no longer swings its elbow between
two nearly equal edits; absent or 0 changes nothing; the item list, the columnar form and
single solves answer alike; FABRIK ignores it; a bad value is a 422 naming the field."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX
from service.engine import Engine
from service.problems import SolveProblem
from tests.conftest import PosePairs
from tests.service.test_api import solve_body
from tests.service.test_columnar import assert_same, columns, items
from tests.service.test_passes_api import assert_bad_option


def across_the_reach(pairs: PosePairs, k: int, side: str) -> list[SolveProblem]:
    """A real start's wrist dragged out along its arm's line, 1 mm a step, from 4 cm
    inside the arm's reach to 2 cm past it."""
    pose = pairs.poses[pairs.starts[k]]
    top, mid, end = (JOINT_INDEX[f"{side}_{n}"] for n in ("shoulder", "elbow", "wrist"))
    reach = np.linalg.norm(pose[mid] - pose[top]) + np.linalg.norm(pose[end] - pose[mid])
    u = (pose[end] - pose[top]) / np.linalg.norm(pose[end] - pose[top])
    return [
        SolveProblem(pose=pose, target_idx=np.asarray([end]), target_pos=(pose[top] + d * u)[None],
                     weights=np.ones(1), n_targets=1)
        for d in reach + np.arange(-0.04, 0.02, 0.001)
    ]  # fmt: skip


def elbow_step(engine: Engine, problems: list[SolveProblem], side: str) -> float:
    """The elbow's largest move (m) between two neighbouring edits."""
    elbow = np.stack([r.pose[JOINT_INDEX[f"{side}_elbow"]] for r in engine.solve(problems)])
    return float(np.linalg.norm(np.diff(elbow, axis=0), axis=-1).max())


def test_a_wrist_crossing_the_reach_moves_its_elbow_smoothly(
    engine: Engine, real_poses: PosePairs
) -> None:
    """Without it, the elbow jumps about a centimetre in one millimetre of the target
    where the arm straightens (its distance off the line grows as the square root of how
    far inside the reach the wrist is); eased over 1 cm, in exact reach (the editor's and a
    clip's: the target still reached), the step stays a few millimetres."""
    for k, side in ((0, "left"), (1, "right"), (2, "left")):
        edits = [
            dataclasses.replace(p, reach="exact") for p in across_the_reach(real_poses, k, side)
        ]
        eased = [dataclasses.replace(p, soft_ik=0.01) for p in edits]
        plain, smooth = elbow_step(engine, edits, side), elbow_step(engine, eased, side)
        assert plain > 0.006 and smooth < 0.5 * plain, (k, plain, smooth)
        assert all(r.errors.max() <= 1e-3 for r in engine.solve(eased))  # still reached


def test_zero_is_absent_and_the_forms_agree(client: Any, real_poses: PosePairs) -> None:
    body = solve_body(real_poses, 3, ["left_wrist", "right_ankle"])
    plain = client.post("/v1/solve", json=body).json()
    assert client.post("/v1/solve", json={**body, "options": {"soft_ik": 0}}).json() == plain
    bodies = [solve_body(real_poses, k, ["left_wrist"], soft_ik=0.01 * (k % 3)) for k in range(9)]
    bodies[4]["options"]["reach"] = "exact"
    batch = client.post("/v1/solve/batch", json={"items": bodies})
    assert batch.status_code == 200, batch.text
    for b, got in zip(bodies, batch.json()["items"], strict=True):
        assert got == client.post("/v1/solve", json=b).json()
    col = columns(real_poses, 30, soft_ik=0.02)
    answer = client.post("/v1/solve/batch", json=col)
    assert answer.status_code == 200, answer.text
    one_by_one = [client.post("/v1/solve", json=b).json() for b in items(col)]
    assert_same(answer.json(), one_by_one)


def test_fabrik_ignores_it(engine: Engine, real_poses: PosePairs) -> None:
    edits = [
        dataclasses.replace(p, method="fabrik") for p in across_the_reach(real_poses, 0, "left")
    ]
    eased = [dataclasses.replace(p, soft_ik=0.05) for p in edits]
    for a, b in zip(engine.solve(edits), engine.solve(eased), strict=True):
        assert np.array_equal(a.pose, b.pose)


@pytest.mark.parametrize("value", [-0.01, 0.11, "0.01", True, [0.01]])
def test_bad_soft_ik_is_422_naming_the_field(
    client: Any, real_poses: PosePairs, value: object
) -> None:
    assert_bad_option(client, real_poses, "soft_ik", value)


def test_the_engine_refuses_it_out_of_range_alone_as_in_a_batch(
    engine: Engine, real_poses: PosePairs
) -> None:
    """A lone edit (the lean path) was solved with ``soft_ik`` 0.5, NaN or -0.01, where
    the same edit in a batch of two was refused (a review)."""
    edit = across_the_reach(real_poses, 0, "left")[0]
    for bad in (0.5, float("nan"), -0.01):
        wrong = dataclasses.replace(edit, soft_ik=bad)
        for batch in ([wrong], [wrong, edit]):
            with pytest.raises(ValueError, match="soft_ik"):
                engine.solve(batch)


def test_a_doll_asked_the_largest_ease_keeps_its_arm(engine: Engine, real_poses: PosePairs) -> None:
    """A body a tenth of the size (an arm of about 5 cm) asked to ease over 10 cm: the
    easing was larger than the arm's reach, the eased distance went below zero, and the
    answer was all NaN (equal bones) or the arm folded onto its shoulder; now the easing
    is at most a quarter of the limb's reach (``core.ends.SOFT_IK_LIMB``)."""
    edits = across_the_reach(real_poses, 1, "right")
    doll = [
        dataclasses.replace(p, pose=0.1 * p.pose, target_pos=0.1 * p.target_pos, soft_ik=0.1,
                            reach=reach)
        for p in edits[::10] for reach in ("soft", "exact")
    ]  # fmt: skip
    top, end = JOINT_INDEX["right_shoulder"], JOINT_INDEX["right_wrist"]
    for p, r in zip(doll, engine.solve(doll), strict=True):
        assert np.all(np.isfinite(r.pose)) and r.max_bone_error <= 1e-5
        reach = np.linalg.norm(np.diff(p.pose[[top, JOINT_INDEX["right_elbow"], end]], axis=0),
                               axis=-1).sum()  # fmt: skip
        assert np.linalg.norm(r.pose[end] - r.pose[top]) > 0.7 * reach  # not folded


def test_the_retry_and_polish_still_serve_an_eased_edit_beyond_its_ease(
    engine: Engine, real_poses: PosePairs
) -> None:
    """A soft edit asked to ease is retried and polished as any other once it is short by
    more than the retry's reach plus the ease it asked for (``soft_ik`` / e): an edit
    with ``soft_ik`` 1e-9, which eases nothing, was left 15 cm short where 0 reached
    within millimetres (the polish was skipped for any ``soft_ik`` > 0: a review)."""
    rng = np.random.default_rng(7)
    wrists = np.asarray([JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]])
    edits = []
    for k in range(24):
        pose = real_poses.poses[real_poses.starts[k]]
        away = rng.normal(size=(2, 3))
        goal = pose[wrists] + 0.3 * away / np.linalg.norm(away, axis=-1, keepdims=True)
        edits.append(SolveProblem(pose=pose, target_idx=wrists, target_pos=goal,
                                  weights=np.ones(2), n_targets=2))  # fmt: skip
    reach = engine.serving.retry_reach
    for soft in (1e-9, 0.01):
        plain = engine.solve(edits)
        eased = engine.solve([dataclasses.replace(p, soft_ik=soft) for p in edits])
        for a, b in zip(plain, eased, strict=True):
            # at most the ease asked for more than without it (a target out of reach: both
            # as near as the arm goes)
            assert b.errors.max() <= max(a.errors.max(), reach) + soft / np.e + 1e-6, soft


def test_the_editors_bounds_are_the_services() -> None:
    """The editor checks Tolerance and Soft IK in the page against bounds of its own
    (``service/static/editor/solve.js``, ``BOUNDS``); they must be the request schema's,
    Soft IK in centimetres."""
    import re

    from service.schemas import SolveOptions
    from tests.conftest import REPO_ROOT

    js = (REPO_ROOT / "service" / "static" / "editor" / "solve.js").read_text()

    def page(field: str) -> tuple[float, float]:
        m = re.search(rf"'?{field}'?: {{[^}}]*min: ([0-9.e-]+), max: ([0-9.e-]+)", js)
        assert m, field
        return float(m.group(1)), float(m.group(2))

    def schema(name: str) -> tuple[float, float]:
        meta = SolveOptions.model_fields[name].metadata
        lo = next(x.ge for x in meta if hasattr(x, "ge"))
        hi = next(x.le for x in meta if hasattr(x, "le"))
        return float(lo), float(hi)

    assert page("tolerance") == schema("tolerance")
    assert page("soft-ik") == tuple(100.0 * v for v in schema("soft_ik"))
