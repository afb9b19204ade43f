"""The lean path (:mod:`service.lean`): batches whose items all ask for the same neural
soft solve skip the general path's bookkeeping, and answer bit for bit as it does."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX
from service import lean
from service.engine import Engine
from service.lean import lean_sequence, solve_lean
from service.problems import SolveProblem, _Items, stacked
from tests.conftest import PosePairs

WRISTS = ("left_wrist", "right_wrist")
OFFSET = np.array([2.0, 0.3, -1.0])  # a world position away from the origin


def _problems(real: PosePairs, names: tuple[str, ...], **kw: object) -> list[SolveProblem]:
    idx = np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)
    turn = np.array([[0.6, 0.0, 0.8], [0.0, 1.0, 0.0], [-0.8, 0.0, 0.6]])  # a yaw
    return [
        SolveProblem(
            pose=real.poses[s] @ turn.T + OFFSET,
            target_idx=idx,
            target_pos=real.poses[g][idx] @ turn.T + OFFSET,
            weights=np.ones(len(idx)),
            n_targets=len(idx),
            floor=0.3,
            **kw,  # type: ignore[arg-type]
        )
        for s, g in zip(real.starts[:30], real.goals[:30], strict=True)
    ]


def _fabrik_item(real: PosePairs) -> SolveProblem:
    return _problems(real, ("left_ankle",), method="fabrik")[0]


@pytest.mark.parametrize("reach", ["soft", "exact"])
@pytest.mark.parametrize("passes", [1, 2, 3])
@pytest.mark.parametrize(
    ("names", "pins"),
    [(WRISTS, 0), (("left_knee",), 0), (("head", "left_wrist", "right_ankle"), 0),
     (("left_wrist", "right_wrist", "left_ankle", "right_ankle"), 2), (("head", "pelvis"), 1)],
)  # fmt: skip
def test_lean_answers_are_the_general_paths(
    engine: Engine, real_poses: PosePairs, passes: int, names: tuple[str, ...], pins: int,
    reach: str,
) -> None:  # fmt: skip
    """Alone (lean, from the problem), as a one-set batch (lean, from arrays) and inside a
    batch with a FABRIK item (the general path): the same bits, solvers, iterations and
    errors, pins (the last ``pins`` joints) included. Exact reach ends with the FABRIK
    polish and reaches; so do pins, soft or exact, where they were."""
    probs = [
        dataclasses.replace(p, passes=passes, reach=reach, n_targets=len(names) - pins)
        for p in _problems(real_poses, names)
    ]
    if pins:  # a pin holds its joint where the start has it
        probs = [
            dataclasses.replace(p, target_pos=np.concatenate(
                [p.target_pos[: p.n_targets], p.pose[p.target_idx[p.n_targets :]]]))
            for p in probs
        ]  # fmt: skip
    together = engine.solve(probs)
    general = engine.solve([*probs, _fabrik_item(real_poses)])[:-1]
    polished = 0
    for p, a, g in zip(probs, together, general, strict=True):
        (one,) = engine.solve([p])
        for r in (a, one):
            assert np.array_equal(r.pose, g.pose)
            assert np.array_equal(r.errors, g.errors) and np.array_equal(r.reached, g.reached)
            assert r.max_bone_error == g.max_bone_error
            assert r.solvers == g.solvers and r.iterations == g.iterations
            assert np.array_equal(r.pin_errors, g.pin_errors)
        assert one.max_bone_error < 1e-5
        assert len(one.pin_errors) == pins and bool((one.pin_errors <= 1e-3).all())
        if reach == "exact":  # the polish, or where it misses (a pinned pelvis), plain FABRIK
            assert one.solvers[-1] in ("fabrik-polish", "fabrik-fallback")
            assert one.reached.all() or pins  # a pin may hold a target out of reach
        elif pins:  # the pins' polish, or the retry's (or its fallback from the start)
            assert one.solvers[-1] in ("fabrik-polish", "fabrik-fallback")
        elif one.iterations:  # a soft answer the retry's pass left short: polished
            assert one.solvers[-1] in ("fabrik-polish", "fabrik-fallback")
            polished += 1
        else:
            assert "fabrik-polish" not in one.solvers
    # (a wrist's collar turned only within its cone, core.ends: 1 in 30 at most here)
    assert polished <= 1


@pytest.mark.parametrize("passes", [1, 2])
@pytest.mark.parametrize("pins", [0, 2])
def test_exact_reach_out_of_reach_falls_back_as_the_general_path(
    engine: Engine, real_poses: PosePairs, passes: int, pins: int
) -> None:
    """Where the polish cannot reach a target, the lean path also tries plain FABRIK from
    the caller's start and keeps the closer, as the general path does (bit for bit, the
    solver paths too: ``fabrik-fallback`` where FABRIK's was kept, here with pins held);
    a reachable target keeps the polish. Mixed in one batch, each item its own."""
    names = ("left_wrist", "left_ankle", "right_ankle")[: 1 + pins]
    probs = [
        dataclasses.replace(p, reach="exact", passes=passes, n_targets=1, target_pos=np.concatenate(
            [p.target_pos[:1] + np.array([0.0, 3.0 * (i % 2), 0.0]), p.pose[p.target_idx[1:]]]))
        for i, p in enumerate(_problems(real_poses, names)[:8])
    ]  # fmt: skip
    arrays, _ = _items(probs, engine)
    fell = solve_lean(engine, arrays, passes, lean_sequence(engine, *_items(probs, engine)) or (),
                      exact=True)[4]  # fmt: skip
    assert not fell[::2].any()  # the reachable ones kept the polish
    together = engine.solve(probs)
    general = engine.solve([*probs, _fabrik_item(real_poses)])[:-1]
    for i, (p, a, g) in enumerate(zip(probs, together, general, strict=True)):
        (one,) = engine.solve([p])
        for r in (a, one):
            assert np.array_equal(r.pose, g.pose) and r.solvers == g.solvers, i
            assert r.iterations == g.iterations and np.array_equal(r.errors, g.errors), i
        assert one.reached.all() == (i % 2 == 0), i  # the far ones (odd) are out of reach
        assert one.solvers[-1] == ("fabrik-fallback" if fell[i] else "fabrik-polish"), i


@pytest.mark.parametrize("pins", [0, 2])
@pytest.mark.parametrize("names", [WRISTS, ("head", "left_wrist", "right_ankle", "left_knee")])
def test_fabrik_answers_are_the_general_paths(
    engine: Engine, real_poses: PosePairs, names: tuple[str, ...], pins: int
) -> None:
    """FABRIK alone, as a one-set batch and inside a batch with a neural item (the
    general path): the same bits, iterations and errors, pins included."""
    probs = [
        dataclasses.replace(p, n_targets=len(names) - pins, weights=np.arange(1.0, len(names) + 1))
        for p in _problems(real_poses, names, method="fabrik")
    ]
    neural = _problems(real_poses, WRISTS)[0]
    together = engine.solve(probs)
    general = engine.solve([*probs, neural])[:-1]
    for p, a, g in zip(probs, together, general, strict=True):
        (one,) = engine.solve([p])
        for r in (a, one):
            assert np.array_equal(r.pose, g.pose) and r.iterations == g.iterations
            assert np.array_equal(r.errors, g.errors) and np.array_equal(r.pin_errors, g.pin_errors)
            assert r.max_bone_error == g.max_bone_error and r.solvers == g.solvers == ["fabrik"]
        assert len(one.pin_errors) == pins and one.iterations > 0


def _items(probs: list[SolveProblem], engine: Engine) -> tuple[_Items, np.ndarray]:
    items = _Items.of_arrays(
        **stacked(probs),
        carry=np.asarray([engine.carry_of(p) for p in probs]),
        mirror=np.asarray([engine.mirror_of(p) for p in probs]),
    )
    passes = np.asarray([engine.passes_of(p) for p in probs], np.int64)
    return items, passes


def test_which_batches_take_the_lean_path(engine: Engine, real_poses: PosePairs) -> None:
    wrists = _problems(real_poses, WRISTS)[:4]
    assert lean_sequence(engine, *_items(wrists, engine)) == ("left_wrist+right_wrist",)
    exact = [dataclasses.replace(p, reach="exact") for p in wrists]
    assert lean_sequence(engine, *_items(exact, engine)) == ("left_wrist+right_wrist",)
    pinned = [dataclasses.replace(p, n_targets=1) for p in wrists]  # right wrist: a pin
    assert lean_sequence(engine, *_items(pinned, engine)) == ("left_wrist+right_wrist",)
    others = {
        "a FABRIK item": [*wrists, _fabrik_item(real_poses)],
        "exact and soft reach": [dataclasses.replace(wrists[0], reach="exact"), *wrists[1:]],
        "free bone lengths": [dataclasses.replace(wrists[0], preserve_bone_lengths=False)],
        "pins and none": [*pinned[:2], *wrists[2:]],
        "two target sets": [*wrists, *_problems(real_poses, ("left_knee",))[:1]],
        "other weights": [dataclasses.replace(wrists[0], weights=np.array([1.0, 2.0])), wrists[1]],
        "other passes": [dataclasses.replace(wrists[0], passes=1), wrists[1]],
        "a target no solver covers": _problems(real_poses, ("left_elbow", "spine2"))[:2],
    }
    for why, probs in others.items():
        assert lean_sequence(engine, *_items(probs, engine)) is None, why


def test_one_problem_as_items_equals_its_stacked_arrays(
    engine: Engine, real_poses: PosePairs
) -> None:
    """``_Items.of_problem`` (the lean single path) builds what ``_Items.of_arrays`` builds
    from ``stacked([p])`` (the general path), field by field, dtype and all, every array
    writable (a read-only one would be another type to the compiled kernels)."""
    pose = real_poses.poses[real_poses.starts[0]]
    idx = np.asarray([JOINT_INDEX["left_wrist"], JOINT_INDEX["right_ankle"]], dtype=np.intp)
    base = SolveProblem(pose=pose, target_idx=idx, target_pos=pose[idx] + 0.1,
                        weights=np.array([1.0, 2.0]), n_targets=1)  # fmt: skip
    for p in (
        base, dataclasses.replace(base, n_targets=2, reach="exact", tolerance=1e-4, floor=0.2),
        dataclasses.replace(base, method="fabrik", preserve_bone_lengths=False),
        dataclasses.replace(base, turn_search=False, mirror=False, carry=0.2, passes=3),
    ):  # fmt: skip
        carry, mirror = engine.carry_of(p), engine.mirror_of(p)
        one = _Items.of_problem(p, carry, mirror)
        given = stacked([p])
        other = _Items.of_arrays(**given, carry=[carry], mirror=[mirror])
        for f in dataclasses.fields(one):
            a, b = getattr(one, f.name), getattr(other, f.name)
            assert a.dtype == b.dtype and np.array_equal(a, b), f.name
            assert a.flags.writeable and a.flags.c_contiguous, f.name
            assert b.flags.writeable and b.flags.c_contiguous, f.name
        # per-item options are the engine's own copies, never the caller's arrays
        for name in ("w", "fab", "keep", "ex", "tols", "floors", "turn", "cnt", "n_t"):
            assert not any(np.shares_memory(getattr(other, name), g) for g in given.values()), name


@pytest.mark.parametrize("mirror", [True, False])
@pytest.mark.parametrize("passes", [1, 2, 3])
@pytest.mark.parametrize("names", [WRISTS, ("left_knee",), ("head", "left_wrist")])
def test_one_edit_in_place_is_the_per_pass_way(
    engine: Engine, real_poses: PosePairs, monkeypatch: pytest.MonkeyPatch, names: tuple[str, ...],
    passes: int, mirror: bool,
) -> None:  # fmt: skip
    """A lone soft edit's passes in place (``lean.solve_one``: the kernels write into
    onnxruntime's bound buffers) give the per-pass way's bits (``solve_lean`` with it off),
    options and floors included; a composed set (head and a wrist) has no one run."""
    probs = [
        dataclasses.replace(p, passes=passes, mirror=mirror, carry=(0.0, 1.0, None)[i % 3],
                            soft_ik=0.02 * (i % 2))
        for i, p in enumerate(_problems(real_poses, names)[:12])
    ]  # fmt: skip
    items, _ = _items(probs[:1], engine)
    seq = lean_sequence(engine, items, np.array([passes]))
    assert seq is not None
    one = lean.solve_one(engine, items, passes, seq, engine.collar_items(items),
                         engine.pelvis_holds(items))  # fmt: skip
    assert (one is None) == (len(seq) > 1)
    fast = [engine.solve([p])[0] for p in probs]
    monkeypatch.setattr(lean, "solve_one", lambda *args: None)
    for p, a in zip(probs, fast, strict=True):
        (b,) = engine.solve([p])
        assert np.array_equal(a.pose, b.pose) and np.array_equal(a.errors, b.errors)
        assert a.max_bone_error == b.max_bone_error and a.solvers == b.solvers
        assert a.iterations == b.iterations
