"""The checks the request schemas cannot express (the schemas do every field check:
joint names, finite numbers, bounds, vector lengths): repeated joints, a pin on a
targeted joint, degenerate poses. Each failure is an ``InvalidRequest`` (422) naming the
field."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from core.skeleton import BONES, JOINT_INDEX, JOINT_NAMES, bone_lengths
from service.engine import SolveProblem
from service.errors import InvalidRequest
from service.schemas import CompleteRequest, SolveRequest

F64 = npt.NDArray[np.floating[Any]]
MIN_BONE = 1.0e-4  # metres; shorter bones make a pose degenerate


def poses(requests: Sequence[SolveRequest], where: Sequence[str]) -> F64:
    """The start poses ``[B, 21, 3]`` (joint order) of validated requests; a pose with a
    zero-length bone is refused, naming the pose and the joints."""
    arr = np.array(
        [[getattr(r.pose, j) for j in JOINT_NAMES] for r in requests], dtype=np.float64
    ).reshape(len(requests), len(JOINT_NAMES), 3)
    lengths = bone_lengths(arr)
    if lengths.size and lengths.min() < MIN_BONE:
        b = int(np.argmax(lengths.min(axis=-1) < MIN_BONE))
        short = [
            JOINT_NAMES[c] for (c, _), n in zip(BONES, lengths[b], strict=True) if n < MIN_BONE
        ]
        raise InvalidRequest(
            f"{where[b]}: degenerate pose: zero-length bones ending at {short} "
            f"(each joint must be at least {MIN_BONE * 1000:g} mm from its parent)"
        )
    return arr


def solve_problem(req: SolveRequest, pose: F64, where: str = "") -> SolveProblem:
    """One solve's targets and pins against its ``pose`` ``[21, 3]``."""
    prefix = f"{where}." if where else ""
    idx: list[int] = []
    for i, t in enumerate(req.targets):
        j = JOINT_INDEX[t.joint]
        if j in idx:
            raise InvalidRequest(f"{prefix}targets[{i}]: duplicate target for joint {t.joint!r}")
        idx.append(j)
    n_targets = len(idx)
    for i, joint in enumerate(req.pins):
        j = JOINT_INDEX[joint]
        if j in idx[:n_targets]:
            raise InvalidRequest(f"{prefix}pins[{i}]: joint {joint!r} is both pinned and targeted")
        if j in idx:
            raise InvalidRequest(f"{prefix}pins[{i}]: joint {joint!r} is pinned twice")
        idx.append(j)
    target_idx = np.asarray(idx, dtype=np.intp)
    weights = np.ones(len(idx))
    weights[:n_targets] = [t.weight for t in req.targets]
    goal = np.array([t.position for t in req.targets], dtype=np.float64)
    o = req.options
    return SolveProblem(
        pose=pose,
        target_idx=target_idx,
        target_pos=np.concatenate([goal, pose[target_idx[n_targets:]]]),
        weights=weights,
        n_targets=n_targets,
        method=o.method,
        preserve_bone_lengths=o.preserve_bone_lengths,
        reach=o.reach,
        tolerance=o.tolerance,
        floor=o.floor,
    )


def keypoints(req: CompleteRequest) -> dict[str, F64]:
    """Key points by joint, each joint at most once."""
    points: dict[str, F64] = {}
    for i, kp in enumerate(req.keypoints):
        if kp.joint in points:
            raise InvalidRequest(f"keypoints[{i}]: duplicate key point {kp.joint!r}")
        points[kp.joint] = np.asarray(kp.position, dtype=np.float64)
    return points
