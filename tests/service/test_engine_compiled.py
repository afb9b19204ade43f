"""The engine's compiled solve on real edits: bit-identical run to run, single vs batch
and array API vs problems; the same answers as the numpy reference path."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from core import kinematics
from core.skeleton import JOINT_INDEX, bone_lengths
from service import fabrik_set
from service.engine import Engine
from service.problems import SolveProblem
from tests.conftest import REPO_ROOT, PosePairs

FIVE = ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")


def _problems(real: PosePairs, names: tuple[str, ...], **kw: object) -> list[SolveProblem]:
    idx = np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)
    return [
        SolveProblem(
            pose=real.poses[s] + np.array([1.5, 0.2, -3.0]),
            target_idx=idx,
            target_pos=real.poses[g][idx] + np.array([1.5, 0.2, -3.0]),
            weights=np.ones(len(idx)),
            n_targets=len(idx),
            floor=0.2,
            **kw,  # type: ignore[arg-type]
        )
        for s, g in zip(real.starts[:40], real.goals[:40], strict=True)
    ]


def test_bit_identical_run_to_run_and_single_vs_batch(
    engine: Engine, real_poses: PosePairs
) -> None:
    mixed = (
        _problems(real_poses, ("left_wrist", "right_wrist"))
        + _problems(real_poses, FIVE, reach="exact")
        + _problems(real_poses, ("left_wrist",), method="fabrik")
        + _problems(real_poses, ("left_elbow", "spine2"))
    )
    batch = engine.solve(mixed)
    again = engine.solve(mixed)
    for p, a, b in zip(mixed, batch, again, strict=True):
        (one,) = engine.solve([p])
        assert np.array_equal(a.pose, b.pose) and np.array_equal(a.pose, one.pose)
        assert a.solvers == one.solvers and a.iterations == one.iterations
        assert np.array_equal(a.errors, one.errors)


def test_array_api_is_the_problems_api(engine: Engine, real_poses: PosePairs) -> None:
    probs = _problems(real_poses, ("left_wrist", "right_wrist"))
    results = engine.solve(probs)
    ans = engine.solve_arrays(
        np.stack([p.pose for p in probs]), np.stack([p.target_idx for p in probs]),
        np.stack([p.target_pos for p in probs]), floor=0.2,
    )  # fmt: skip
    assert np.array_equal(ans.pose, np.stack([r.pose for r in results]))
    assert ans.paths[int(ans.path_of[0])] == tuple(results[0].solvers)


def test_fabrik_method_is_the_numpy_fabrik(engine: Engine, real_poses: PosePairs) -> None:
    """``method: "fabrik"`` is numpy's textbook FABRIK, or where that folds the hips (nearer
    than ``FOLDED`` of the start's), its ``rigid_hips`` run where that reaches as well
    (``service.fabrik_set``): both arise among these 5-target edits."""
    probs = _problems(real_poses, FIVE, method="fabrik")
    hips = [JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]]
    retried = kept = 0
    for p, r in zip(probs, engine.solve(probs), strict=True):
        start = p.pose - np.array([1.5, 0.2, -3.0])  # canonical already: yaw 0 here
        ref = kinematics.fabrik(
            start, bone_lengths(start), p.target_idx, p.target_pos - np.array([1.5, 0.2, -3.0]),
            tolerance=p.tolerance, max_iterations=engine.fabrik_max_iterations,
        )  # fmt: skip
        width = [np.linalg.norm(np.subtract(*q[hips])) for q in (start, ref.positions)]
        if width[1] < fabrik_set.FOLDED * width[0]:
            retried += 1
            rigid = kinematics.fabrik(
                start, bone_lengths(start), p.target_idx,
                p.target_pos - np.array([1.5, 0.2, -3.0]), tolerance=p.tolerance,
                max_iterations=engine.fabrik_max_iterations, rigid_hips=True,
            )  # fmt: skip
            if r.iterations != ref.iterations:
                kept += 1
                ref = dataclasses.replace(rigid, iterations=ref.iterations + rigid.iterations)
        assert r.iterations == ref.iterations
        assert np.abs(r.pose - np.array([1.5, 0.2, -3.0]) - ref.positions).max() < 1e-9
    assert retried >= kept > 0


def test_the_warm_up_compiles_the_signatures_solves_use(models_dir: Path) -> None:
    """The container's numba seed holds what ``compiled.warm`` and ``compiled_fabrik.warm``
    compile; a kernel a solve then calls with another signature (an argument omitted in the
    warm-up, given by the engine) is compiled at the first solve: in the image that took
    the start to ready from 2.1 to 10 s and the ready RSS from 282 to 414 MiB (this stop's
    smoke runs). In a fresh interpreter, after the warm-ups, soft, exact, pinned and FABRIK
    solves compile nothing more."""
    code = f"""
import json, numpy as np
from pathlib import Path
from numba.core.registry import CPUDispatcher
from core import compiled, compiled_fabrik, compiled_limbs, rigid
from core.skeleton import JOINT_INDEX as J, JOINT_NAMES
from service.engine import Engine
from service.schemas import SolveOptions
from service.validation import problem_of
compiled.warm(); compiled_fabrik.warm()
kernels = [k for m in (compiled, compiled_fabrik, compiled_limbs, rigid) for k in vars(m).values()
           if isinstance(k, CPUDispatcher)]
before = [len(k.signatures) for k in kernels]
engine = Engine(Path({str(models_dir)!r}))
body = json.loads(Path("docs/examples/solve.json").read_text())
pose = np.asarray([body["pose"][n] for n in JOINT_NAMES])
goal = (pose[0] + [0.1, -0.05, 0.0])[None]
for reach in ("soft", "exact"):
    for pins in ([], [J["left_ankle"], J["right_ankle"]]):
        for method in ("neural", "fabrik"):
            opts = SolveOptions(reach=reach, method=method)
            engine.solve([problem_of(pose, [0], goal, [1.0], pins, opts)])
after = [len(k.signatures) for k in kernels]
print(json.dumps([k.__name__ for k, b, a in zip(kernels, before, after) if a != b]))
"""
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True,
                          text=True, check=False, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
