"""Targeted limb ends kept through the bone pass in the engine (``serving.keep_ends``):
only the targeted limb's elbow (knee) and end move, bone lengths hold, and on bodies the
models never saw the soft answer reaches nearer its targets and the real pose."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from core.skeleton import JOINT_INDEX, bone_lengths
from service.engine import Engine
from service.problems import SolveProblem, SolveResult
from tests.conftest import PosePairs, edit_problems, on_random_bodies

J = JOINT_INDEX


@pytest.fixture(scope="module")
def engines(models_dir: Path) -> tuple[Engine, Engine]:
    # one pass, no retry, no collar turn (its own test below): the kept ends alone
    kw = {"passes": 1, "retry_reach": 0.0, "keep_collar": False}
    return Engine(models_dir, serving={"keep_ends": False, **kw}), Engine(models_dir, serving=kw)


@pytest.fixture(scope="module")
def pairs(real_poses: PosePairs) -> tuple[np.ndarray, np.ndarray]:
    """Real (start, goal) pairs rebuilt on random asymmetric bodies, one per pair."""
    return on_random_bodies(real_poses, 11)


def test_shipped_models_keep_ends(engines: tuple[Engine, Engine], client: Any) -> None:
    assert engines[1].serving.keep_ends and engines[1].manifest.serving.keep_ends
    assert not engines[0].serving.keep_ends
    assert client.get("/v1/models").json()["keep_ends"] is True
    # and the lone elbows (serving.keep_elbows, set without retraining: the losses saw the
    # ends only)
    assert engines[1].serving.keep_elbows and client.get("/v1/models").json()["keep_elbows"] is True
    assert not engines[1].manifest.provenance.config["solver"].get("elbows_loss", False)
    # and wrists out of reach turn the collar (serving.keep_collar, set without retraining)
    assert engines[1].manifest.serving.keep_collar
    assert client.get("/v1/models").json()["keep_collar"] is True
    # and limbs drawn too straight bend to their side (serving.bend_side, docs item 52)
    assert engines[1].serving.bend_side == engines[1].manifest.serving.bend_side == 0.5
    assert client.get("/v1/models").json()["bend_side"] == 0.5


def test_only_the_targeted_limb_moves_and_reaches_nearer(
    engines: tuple[Engine, Engine], pairs: tuple[np.ndarray, np.ndarray]
) -> None:
    start, goal = pairs
    limbs = {
        ("left_wrist",): ("left_elbow", "left_wrist"),
        ("right_ankle",): ("right_knee", "right_ankle", "right_foot"),
    }
    for names, moved in limbs.items():
        probs = edit_problems(start, goal, names)
        a, b = ([r for r in e.solve(probs)] for e in engines)
        pa, pb = np.stack([r.pose for r in a]), np.stack([r.pose for r in b])
        others = np.setdiff1d(np.arange(21), [J[n] for n in moved])
        assert np.array_equal(pa[:, others], pb[:, others])
        assert np.abs(bone_lengths(pb) / bone_lengths(start) - 1).max() < 1e-9
        assert max(r.max_bone_error for r in b) <= 1e-5
        reach_a = np.asarray([r.errors[0] for r in a])
        reach_b = np.asarray([r.errors[0] for r in b])
        assert reach_b.mean() < 0.8 * reach_a.mean()
        # and the whole pose ends nearer the real one
        mpjpe = [np.linalg.norm(p - goal, axis=-1).mean() for p in (pa, pb)]
        assert mpjpe[1] < mpjpe[0]
    # batch and single agree bit for bit
    probs = edit_problems(start[:8], goal[:8], ("left_wrist", "right_ankle"))
    batch = engines[1].solve(probs)
    for p, r in zip(probs, batch, strict=True):
        assert np.array_equal(engines[1].solve([p])[0].pose, r.pose)


def test_kept_elbows_move_only_the_arm_and_reach_nearer(
    models_dir: Path, pairs: tuple[np.ndarray, np.ndarray], client: Any
) -> None:
    """``serving.keep_elbows``: a lone targeted elbow goes back where the networks put it;
    only its shoulder, the elbow and the hand below move; lengths hold; batch = single."""
    kw = {"passes": 1, "retry_reach": 0.0}
    off, on = (Engine(models_dir, serving={"keep_elbows": k, **kw}) for k in (False, True))
    assert on.chain_mask.sum() == 6 and off.chain_mask.sum() == (4 if off.serving.keep_ends else 0)
    assert client.get("/v1/models").json()["keep_elbows"] is on.manifest.serving.keep_elbows
    start, goal = pairs
    probs = edit_problems(start, goal, ("left_elbow",))
    a, b = off.solve(probs), on.solve(probs)
    pa, pb = np.stack([r.pose for r in a]), np.stack([r.pose for r in b])
    moved = [J[n] for n in ("left_shoulder", "left_elbow", "left_wrist")]
    others = np.setdiff1d(np.arange(21), moved)
    assert np.array_equal(pa[:, others], pb[:, others]) and not np.array_equal(pa, pb)
    assert max(r.max_bone_error for r in b) <= 1e-5
    reach_a, reach_b = (np.asarray([r.errors[0] for r in rs]) for rs in (a, b))
    assert reach_b.mean() < 0.5 * reach_a.mean()
    probs = edit_problems(start[:8], goal[:8], ("left_elbow", "right_elbow", "left_ankle"))
    for p, r in zip(probs, on.solve(probs), strict=True):
        assert np.array_equal(on.solve([p])[0].pose, r.pose)


def _off_on(
    off: Engine, on: Engine, pairs: tuple[np.ndarray, np.ndarray], target: str, moved: list[str]
) -> tuple[list[SolveResult], list[SolveResult], npt.NDArray[np.bool_], list[SolveProblem]]:
    """One-target edits of ``pairs`` solved by ``off`` and ``on``: some answers differ, in
    the joints ``moved`` only; ``on`` keeps lengths and answers a batch as it answers each
    item alone. The answers, which of them changed, and the problems."""
    start, goal = pairs
    probs = edit_problems(start, goal, (target,))
    a, b = off.solve(probs), on.solve(probs)
    pa, pb = np.stack([r.pose for r in a]), np.stack([r.pose for r in b])
    changed = np.any(pa != pb, axis=(1, 2))
    assert changed.any() and not changed.all()
    rest = np.setdiff1d(np.arange(21), [J[n] for n in moved])
    assert np.array_equal(pa[:, rest], pb[:, rest])
    assert max(r.max_bone_error for r in b) <= 1e-5
    for p, r in zip(probs[:8], on.solve(probs[:8]), strict=True):
        assert np.array_equal(on.solve([p])[0].pose, r.pose)
    return a, b, changed, probs


def test_eased_ends_differ_only_where_the_bone_pass_left_them_near(
    models_dir: Path, pairs: tuple[np.ndarray, np.ndarray], client: Any
) -> None:
    """``serving.keep_ease``: kept ends the bone pass left within ``keep_ease`` of the
    networks' go back only in proportion, so some answers change (the limb only), others
    not at all; lengths hold; batch = single; ``GET /v1/models`` reports the shipped value."""
    kw = {"passes": 1, "retry_reach": 0.0}
    plain, eased = (Engine(models_dir, serving={"keep_ease": e, **kw}) for e in (0.0, 0.01))
    assert client.get("/v1/models").json()["keep_ease"] == plain.manifest.serving.keep_ease
    _off_on(plain, eased, pairs, "right_ankle", ["right_knee", "right_ankle", "right_foot"])


def test_out_of_reach_wrists_turn_the_collar_in_soft_answers_only(
    models_dir: Path, pairs: tuple[np.ndarray, np.ndarray], client: Any
) -> None:
    """``serving.keep_collar``: a soft answer's kept wrist beyond the arm's reach turns its
    shoulder about the collar (only the shoulder, the elbow and the wrist move, reach
    improves on the whole and for most); exact answers are unchanged; lengths hold; batch =
    single."""
    kw = {"passes": 1, "retry_reach": 0.0}
    off, on = (Engine(models_dir, serving={"keep_collar": k, **kw}) for k in (False, True))
    assert client.get("/v1/models").json()["keep_collar"] is on.manifest.serving.keep_collar
    arm = ["left_shoulder", "left_elbow", "left_wrist"]
    a, b, changed, probs = _off_on(off, on, pairs, "left_wrist", arm)
    reach_a, reach_b = (np.asarray([r.errors[0] for r in rs]) for rs in (a, b))
    # the turn aims the shoulder at the wrist the networks kept, not at the target: with the
    # models of mx1-3ca9545e56de it brought every such answer nearer the target; with those of
    # docs/generalisation-3.md item 50, 12 of 14 (the others 0.9 and 4.4 mm farther)
    nearer = reach_b[changed] < reach_a[changed]
    assert nearer.mean() >= 0.75 and reach_b[changed].mean() < reach_a[changed].mean()
    exact = [dataclasses.replace(p, reach="exact") for p in probs[:16]]
    for x, y in zip(off.solve(exact), on.solve(exact), strict=True):
        assert np.array_equal(x.pose, y.pose)
    # nor in the soft passes an exact answer runs first (alone, the lean path; in a batch)
    two = [Engine(models_dir, serving={"passes": 2, "keep_collar": k}) for k in (False, True)]
    for x, y in zip(two[0].solve(exact), two[1].solve(exact + probs[:4])[:16], strict=True):
        assert np.array_equal(x.pose, y.pose)


def test_a_nearly_straight_arm_keeps_its_side_from_frame_to_frame(
    models_dir: Path, bvh_files: dict[str, Path]
) -> None:
    """``serving.bend_side`` on a real walk (a batch audit's clip): the left wrist dragged
    along a smooth path, both feet pinned. Where the networks draw the arm nearly straight
    but the character's longer arm must bend, the side they drew it bent to, a few
    millimetres of their answer, turned round between frames 138 and 139 (the elbow 314
    mm away, FABRIK's 56) and over a 9 mm move of the target from one start (370 mm)."""
    from bench.clips import clip_points

    points = clip_points(bvh_files["bandai"], None, "replace", 200)
    lw, la, ra, le = (J[n] for n in ("left_wrist", "left_ankle", "right_ankle", "left_elbow"))
    t = np.arange(len(points)) / 30.0
    path = 0.3 * np.stack([0.15 * np.sin(2 * np.pi * t / 3), 0.35 * np.sin(np.pi * t / t[-1]) ** 2,
                           0.15 * (1 - np.cos(2 * np.pi * t / 3))], axis=1)  # fmt: skip
    idx = np.asarray([[lw, la, ra]] * 2)
    shipped, plain = Engine(models_dir), Engine(models_dir, serving={"bend_side": 0.0})
    assert shipped.serving.bend_side == 0.5
    frames = points[[138, 139]]
    goals = np.stack([frames[:, lw] + path[[138, 139]], frames[:, la], frames[:, ra]], axis=1)

    def elbow_step(engine: Engine, **options: Any) -> float:
        pose = np.asarray(engine.solve_arrays(frames, idx, goals, n_targets=1, **options).pose)
        return float(np.linalg.norm(pose[1, le] - pose[0, le]))

    fabrik = elbow_step(shipped, fabrik=True, exact=True)
    assert 0.04 < fabrik < 0.08
    assert elbow_step(plain) > 0.25 and elbow_step(plain, exact=True) > 0.25
    assert elbow_step(shipped) < 1.2 * fabrik and elbow_step(shipped, exact=True) < 1.2 * fabrik
    # one start (frame 83), its wrist target (the path at full size) moved 9.4 mm in 20 steps
    g0 = points[83, lw] + path[83] / 0.3
    g1 = g0 + 0.1 * (points[84, lw] + path[84] / 0.3 - g0)
    goal = g0 + np.linspace(0.0, 1.0, 21)[:, None] * (g1 - g0)
    starts = np.repeat(points[83][None], 21, axis=0)
    travel = [
        np.linalg.norm(np.diff(np.asarray(e.solve_arrays(starts, np.full((21, 1), lw),
                                                         goal[:, None]).pose)[:, le], axis=0),
                       axis=-1).sum()
        for e in (plain, shipped)
    ]  # fmt: skip
    assert travel[0] > 0.2 and travel[1] < 0.02, travel  # the elbow's path: 370 mm, then 14
