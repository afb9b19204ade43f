"""Request validation the schemas cannot express: cross-field checks."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from core.skeleton import BONES, JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, bone_lengths
from service.engine import SolveProblem
from service.errors import InvalidRequest

F64 = npt.NDArray[np.floating[Any]]
MAX_COORDINATE = 1.0e4  # metres; beyond this a coordinate is rejected as nonsense
MIN_BONE = 1.0e-4  # metres; shorter bones make a pose degenerate


def _finite_vec(value: Sequence[float], where: str) -> F64:
    if len(value) != 3:
        raise InvalidRequest(f"{where}: expected 3 numbers [x, y, z], got {len(value)}")
    rows = _finite_rows(np.asarray([value], dtype=np.float64), lambda _: where)
    return np.asarray(rows[0])


def _finite_rows(arr: F64, where: Callable[[int], str]) -> F64:
    """Check ``[N, 3]`` coordinates at once; on failure, name the first bad row."""
    if np.isfinite(arr).all() and np.abs(arr).max() <= MAX_COORDINATE:
        return arr
    ok = np.isfinite(arr).all(axis=1)
    if not ok.all():
        i = int(np.argmin(ok))
        raise InvalidRequest(
            f"{where(i)}: coordinates must be finite numbers, got {arr[i].tolist()}"
        )
    i = int(np.argmax((np.abs(arr) > MAX_COORDINATE).any(axis=1)))
    raise InvalidRequest(f"{where(i)}: coordinates beyond ±{MAX_COORDINATE:g} m")


def _known_joint(name: str, where: str) -> int:
    if name not in JOINT_INDEX:
        raise InvalidRequest(
            f"{where}: unknown joint {name!r}; joints are {', '.join(JOINT_NAMES)}"
        )
    return JOINT_INDEX[name]


def parse_pose(pose: dict[str, list[float]], where: str = "pose") -> F64:
    unknown = sorted(set(pose) - set(JOINT_NAMES))
    if unknown:
        raise InvalidRequest(
            f"{where}: unknown joints {unknown}; joints are {', '.join(JOINT_NAMES)}"
        )
    missing = [j for j in JOINT_NAMES if j not in pose]
    if missing:
        raise InvalidRequest(f"{where}: missing joints {missing} (all 21 are required)")
    try:
        arr = np.array([pose[j] for j in JOINT_NAMES], dtype=np.float64)
    except ValueError:  # ragged: some joint is not 3 numbers
        arr = np.empty((0, 3))
    if arr.shape != (NUM_JOINTS, 3):
        bad = next(j for j in JOINT_NAMES if len(pose[j]) != 3)
        raise InvalidRequest(f"{where}.{bad}: expected 3 numbers [x, y, z], got {len(pose[bad])}")
    _finite_rows(arr, lambda i: f"{where}.{JOINT_NAMES[i]}")
    lengths = bone_lengths(arr)
    if lengths.min() < MIN_BONE:
        short = [JOINT_NAMES[c] for (c, _), n in zip(BONES, lengths, strict=True) if n < MIN_BONE]
        raise InvalidRequest(
            f"{where}: degenerate pose: zero-length bones ending at {short} "
            f"(each joint must be at least {MIN_BONE * 1000:g} mm from its parent)"
        )
    return arr


def parse_poses(poses: Sequence[Sequence[Sequence[float]]], where: Sequence[str]) -> F64:
    """Validate many joint-ordered poses ``[B][21][3]`` at once (a batch); on any problem,
    the offending pose is parsed alone so the error names it and its joint."""
    try:
        arr = np.array(poses, dtype=np.float64)
        ok = arr.shape == (len(poses), NUM_JOINTS, 3)
    except ValueError:
        ok = False
    if ok:
        finite = np.isfinite(arr).all() and np.abs(arr).max() <= MAX_COORDINATE
        if finite and bone_lengths(arr).min() >= MIN_BONE:
            return arr
    for pose, name in zip(poses, where, strict=True):  # find and name the culprit
        parse_pose({j: list(v) for j, v in zip(JOINT_NAMES, pose, strict=True)}, name)
    raise AssertionError("a batch failed validation but no pose did")  # pragma: no cover


def parse_keypoints(keypoints: Sequence[tuple[str, Sequence[float]]]) -> dict[str, F64]:
    """Validate key points: known, distinct joints with finite coordinates."""
    points: dict[str, F64] = {}
    for i, (joint, position) in enumerate(keypoints):
        _known_joint(joint, f"keypoints[{i}].joint")
        if joint in points:
            raise InvalidRequest(f"keypoints[{i}]: duplicate key point {joint!r}")
        points[joint] = _finite_vec(position, f"keypoints[{i}].position")
    return points


def parse_solve(
    pose: F64,
    targets: Sequence[tuple[str, list[float], float]],
    pins: Sequence[str],
    *,
    method: str,
    preserve_bone_lengths: bool,
    reach: str,
    tolerance: float,
    where: str = "",
    floor: float = 0.0,
) -> SolveProblem:
    """Validate one solve request's targets and pins against its ``pose`` ``[21, 3]``
    (already validated by ``parse_pose`` or ``parse_poses``); raises ``InvalidRequest``
    with a precise detail."""
    prefix = f"{where}." if where else ""
    arr = pose
    idx: list[int] = []
    for i, (joint, position, _) in enumerate(targets):
        j = _known_joint(joint, f"{prefix}targets[{i}].joint")
        if j in idx:
            raise InvalidRequest(f"{prefix}targets[{i}]: duplicate target for joint {joint!r}")
        if len(position) != 3:
            raise InvalidRequest(
                f"{prefix}targets[{i}].position: expected 3 numbers [x, y, z], got {len(position)}"
            )
        idx.append(j)
    n_targets = len(idx)
    goal = _finite_rows(
        np.array([t[1] for t in targets], dtype=np.float64),
        lambda i: f"{prefix}targets[{i}].position",
    )
    for i, joint in enumerate(pins):
        j = _known_joint(joint, f"{prefix}pins[{i}]")
        if j in idx[:n_targets]:
            raise InvalidRequest(f"{prefix}pins[{i}]: joint {joint!r} is both pinned and targeted")
        if j in idx:
            raise InvalidRequest(f"{prefix}pins[{i}]: joint {joint!r} is pinned twice")
        idx.append(j)
    target_idx = np.asarray(idx, dtype=np.intp)
    weights = np.ones(len(idx))
    weights[:n_targets] = [t[2] for t in targets]
    return SolveProblem(
        pose=arr,
        target_idx=target_idx,
        target_pos=np.concatenate([goal, arr[target_idx[n_targets:]]]),
        weights=weights,
        n_targets=n_targets,
        method=method,
        preserve_bone_lengths=preserve_bone_lengths,
        reach=reach,
        tolerance=tolerance,
        floor=floor,
    )
