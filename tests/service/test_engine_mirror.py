"""Each neural pass also solving the edit's mirror image (``serving.solve_mirror``,
``options.mirror``), on real poses: the answer is then the same, mirrored, for an edit and
its mirror image (a left-wrist drag and the matching right-wrist drag), which the left and
right solvers alone are not; it stays bit-identical alone and in a batch whatever the
other items ask; a request can turn it either way; bad values are 422s naming the field."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import mirror_key, mirrored, mirrored_flat
from service import networks, runtime
from service.engine import Engine
from service.problems import SolveProblem
from tests.conftest import PosePairs, edit_problems, make_client
from tests.service.test_api import as_array, solve_body
from tests.service.test_passes_api import assert_bad_option

WRISTS = ("left_wrist", "right_wrist")


@pytest.fixture(scope="module")
def engines(models_dir: Path) -> tuple[Engine, Engine]:
    """The shipped models served with the mirror image off, and on."""
    return Engine(models_dir, serving={"solve_mirror": False}), Engine(
        models_dir, serving={"solve_mirror": True}
    )


def _mirror_problem(p: SolveProblem, names: tuple[str, ...]) -> SolveProblem:
    """``p`` mirrored in the world (x -> -x, left and right swapped): the same edit of the
    mirror-image body, its targets on the mirrored joints."""
    from core.skeleton import JOINT_INDEX

    goal_world = np.zeros((21, 3))
    goal_world[p.target_idx] = p.target_pos
    idx = np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)
    return dataclasses.replace(
        p, pose=mirrored(p.pose), target_idx=idx, target_pos=mirrored(goal_world)[idx]
    )


def test_mirror_helpers() -> None:
    rng = np.random.default_rng(0)
    poses = rng.normal(size=(4, 21, 3))
    np.testing.assert_array_equal(mirrored(mirrored(poses)), poses)
    assert not np.allclose(mirrored(poses), poses)
    assert mirror_key("left_elbow") == "right_elbow"
    assert mirror_key("left_wrist+right_wrist") == "left_wrist+right_wrist"
    assert mirror_key("head+left_ankle") == "head+right_ankle"
    flat = poses.reshape(4, -1)  # the flat form is the same permutation and sign
    np.testing.assert_array_equal(mirrored_flat(flat), mirrored(poses).reshape(4, -1))


def test_one_solver_fast_way_gives_the_general_ways_numbers(
    engines: tuple[Engine, Engine], real_poses: PosePairs
) -> None:
    """``networks.both_views`` (one solver: mirrored inputs from flat columns, one run
    where the set is its own mirror image) is bit for bit the mean of the solver's answer
    and its mirror solver's answer to the mirrored pose and targets, taken back, on the
    rows asked; the other rows are the solver's answer alone."""
    engine = engines[1]
    x = real_poses.poses[real_poses.starts[:6]].astype(np.float32)  # [6, 21, 3]
    canvas = np.ascontiguousarray(real_poses.poses[real_poses.goals[:6]], dtype=np.float32)
    views = np.asarray([True, False, True, True, False, True])
    assert set(engine.mirror_views) == set(engine.solvers)  # every shipped solver has one
    for key, view in engine.mirror_views.items():
        got = networks.both_views(engine, x.reshape(6, -1), canvas, view, views)
        want = networks.run_once(engine, x.reshape(6, -1), canvas, (key,))
        other = networks.run_once(
            engine, mirrored(x[views]).reshape(4, -1), mirrored(canvas[views]), (view.back,)
        )
        back = mirrored(other.reshape(4, 21, 3)).reshape(4, -1)
        want[views] = (want[views] + back) * np.float32(0.5)
        np.testing.assert_array_equal(got, want, err_msg=key)
        assert view.back == mirror_key(key)


def test_mirror_graphs_answer_as_the_fused_graphs_and_numpy(
    engines: tuple[Engine, Engine], real_poses: PosePairs
) -> None:
    """Where every row asks for the mirror image, ``networks.both_views`` runs the set's
    shipped mirror graph (``trainer.mirror``) and nothing else: with the fused graphs
    taken away it still answers, and bit for bit as the numpy way around the fused graphs
    (the engine without mirror graphs), for every set, on 1 row and on 7, and on more rows
    than a run's block (the sets that are their own mirror run half-blocks)."""
    engine = engines[1]
    numpy_way = copy.copy(engine)
    numpy_way.mirror_graphs = {}
    no_fused = copy.copy(engine)
    no_fused.fused = {}
    assert set(engine.mirror_graphs) == set(engine.solvers)  # the shipped models have all
    rows = runtime.ROW_BLOCK + 3
    x = real_poses.poses[real_poses.starts[np.arange(rows) % 40]].astype(np.float32)
    canvas = np.ascontiguousarray(
        real_poses.poses[real_poses.goals[np.arange(rows) % 40]], dtype=np.float32
    )
    for key, view in engine.mirror_views.items():
        for n in (1, 7, rows):
            flat, views = x[:n].reshape(n, -1), np.ones(n, dtype=np.bool_)
            got = networks.both_views(no_fused, flat, canvas[:n], view, views)
            want = networks.both_views(numpy_way, flat, canvas[:n], view, views)
            np.testing.assert_array_equal(got, want, err_msg=f"{key}, {n} rows")
        block = engine.mirror_graphs[key].block
        assert block == (runtime.ROW_BLOCK // 2 if view.back == key else runtime.ROW_BLOCK)


@pytest.mark.parametrize(
    "sequence",
    [("left_ankle+right_ankle", "left_wrist"), ("left_wrist", "right_knee", "head"),
     ("left_elbow", "right_knee")],
)  # fmt: skip
def test_composed_views_step_together_as_they_run_apart(
    engines: tuple[Engine, Engine], real_poses: PosePairs, sequence: tuple[str, ...]
) -> None:
    """``networks.delta_views`` (a composed edit's two views step by step, a step whose set
    is its own mirror image as one run of both) answers each view as :func:`networks.delta`
    alone, bit for bit, with fewer mirrored rows than own rows too, and ``answer`` is their
    mean on the rows that ask."""
    engine = engines[1]
    back = networks.mirror_of(engine, sequence)
    assert back is not None and back != sequence
    x = real_poses.poses[real_poses.starts[:7]].astype(np.float32).reshape(7, -1)
    canvas = np.ascontiguousarray(real_poses.poses[real_poses.goals[:7]], dtype=np.float32)
    rows = np.asarray([0, 2, 3, 6])
    x_m = mirrored_flat(x[rows])
    c_m = mirrored(canvas[rows])
    own, other = networks.delta_views(engine, x, canvas, x_m, c_m, sequence, back)
    np.testing.assert_array_equal(own, networks.delta(engine, x, canvas, sequence))
    np.testing.assert_array_equal(other, networks.delta(engine, x_m, c_m, back))
    views = np.isin(np.arange(7), rows)
    want = own.copy()
    want[rows] = (own[rows] + mirrored_flat(other)) * np.float32(0.5)
    np.testing.assert_array_equal(networks.answer(engine, x, canvas, sequence, views), want)


@pytest.mark.parametrize(
    "names",
    [("left_wrist",), ("left_elbow",), WRISTS, ("pelvis", "right_knee"), ("head", "left_elbow"),
     ("left_wrist", "right_knee", "spine2")],
)  # fmt: skip
def test_an_edit_and_its_mirror_image_answer_alike(
    engines: tuple[Engine, Engine], real_poses: PosePairs, names: tuple[str, ...]
) -> None:
    """Solved with the mirror image, a drag and the same drag on the mirror-image body
    (the other side's joint) give mirror-image answers, to float rounding; the left and
    right solvers alone answer them differently (millimetres and more). Composed edits too:
    their solvers run in mirror-image order (was: by name, ``pelvis`` before ``right_knee``
    but ``left_knee`` before ``pelvis``, mirror images 28 cm apart; an audit, 2026-12-07)."""
    from core.skeleton import JOINT_NAMES, MIRROR

    other = tuple(sorted(JOINT_NAMES[MIRROR[JOINT_NAMES.index(n)]] for n in names))
    starts = real_poses.poses[real_poses.starts[:12]]
    goals = real_poses.poses[real_poses.goals[:12]]
    probs = [dataclasses.replace(p, turn_search=False) for p in edit_problems(starts, goals, names)]
    flipped = [_mirror_problem(p, other) for p in probs]
    gap = {}
    for on, engine in zip((False, True), engines, strict=True):
        a = np.stack([r.pose for r in engine.solve(probs)])
        b = np.stack([r.pose for r in engine.solve(flipped)])
        gap[on] = float(np.abs(mirrored(b) - a).max())
    assert gap[True] < 1e-4, gap
    if names != WRISTS:  # one solver per side: they differ
        assert gap[False] > 1e-3, gap
    assert gap[False] > 10 * gap[True], gap


def test_bit_identical_alone_and_in_a_mixed_batch(
    engines: tuple[Engine, Engine], real_poses: PosePairs
) -> None:
    """Items that ask for the mirror image and items that do not, in one batch with
    exact reach and several target sets: each answer equals the item solved alone, and
    equals the engine whose default is what the item asked for."""
    off, on = engines
    starts = real_poses.poses[real_poses.starts[:8]]
    goals = real_poses.poses[real_poses.goals[:8]]
    probs = edit_problems(starts[:4], goals[:4], ("left_elbow",)) + edit_problems(
        starts[4:], goals[4:], WRISTS
    )
    probs = [
        dataclasses.replace(p, mirror=bool(i % 2), reach="exact" if i % 3 == 0 else "soft")
        for i, p in enumerate(probs)
    ]
    together = off.solve(probs)
    for p, r in zip(probs, together, strict=True):
        (alone,) = off.solve([p])
        (default,) = (on if p.mirror else off).solve([dataclasses.replace(p, mirror=None)])
        for other in (alone, default):
            assert np.array_equal(r.pose, other.pose) and np.array_equal(r.errors, other.errors)
            assert r.solvers == other.solvers
        assert r.max_bone_error <= 1e-5
    plain = off.solve([dataclasses.replace(p, mirror=False) for p in probs])
    changed = [not np.array_equal(a.pose, b.pose) for a, b in zip(together, plain, strict=True)]
    assert changed == [bool(p.mirror) for p in probs]


def test_options_mirror_over_http(client: Any, real_poses: PosePairs) -> None:
    body = solve_body(real_poses, 0, ["left_wrist"])
    poses = {}
    for value in (None, False, True):
        req = body if value is None else {**body, "options": {"mirror": value}}
        resp = client.post("/v1/solve", json=req)
        assert resp.status_code == 200, resp.text
        poses[value] = as_array(resp.json()["pose"])
    default = client.get("/v1/models").json()["solve_mirror"]
    assert np.array_equal(poses[None], poses[default])
    assert not np.array_equal(poses[False], poses[True])


def test_the_deployment_can_turn_the_default_off(
    models_dir: Path, client: Any, real_poses: PosePairs
) -> None:
    """``POSE_SOLVE_MIRROR=false``: the default answer is the one ``mirror: false`` gets
    from the shipped default, and a request can still ask for the mirror image."""
    body = solve_body(real_poses, 0, ["left_wrist"])
    shipped_off = client.post("/v1/solve", json={**body, "options": {"mirror": False}})
    shipped_on = client.post("/v1/solve", json={**body, "options": {"mirror": True}})
    with make_client(models_dir, solve_mirror=False) as fast:
        assert fast.get("/v1/models").json()["solve_mirror"] is False
        plain = fast.post("/v1/solve", json=body)
        asked = fast.post("/v1/solve", json={**body, "options": {"mirror": True}})
    assert as_array(plain.json()["pose"]).tolist() == as_array(shipped_off.json()["pose"]).tolist()
    assert as_array(asked.json()["pose"]).tolist() == as_array(shipped_on.json()["pose"]).tolist()


@pytest.mark.parametrize("value", ["yes", 1, [True]])
def test_bad_mirror_is_422_naming_the_field(
    client: Any, real_poses: PosePairs, value: object
) -> None:
    assert_bad_option(client, real_poses, "mirror", value)
