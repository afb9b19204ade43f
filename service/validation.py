"""The checks the request schemas cannot express (the schemas do every field check:
joint names, finite numbers, bounds, vector lengths): repeated joints, a pin on a
targeted joint, degenerate poses. Each failure is an ``InvalidRequest`` (422) naming the
field."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from operator import attrgetter
from typing import Any

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ValidatorFunctionWrapHandler

from core import compiled
from core.skeleton import BONES, JOINT_INDEX, JOINT_NAMES, bone_lengths
from core.text import quoted
from service.errors import MAX_ERRORS, InvalidRequest, every_item
from service.problems import SolveProblem
from service.schemas import CompleteRequest, SolveOptions, SolveRequest

F64 = npt.NDArray[np.floating[Any]]
MIN_BONE = 1.0e-4  # metres; shorter bones make a pose degenerate
_JOINTS = attrgetter(*JOINT_NAMES)  # a Pose's 21 [x, y, z], in joint order


def poses(requests: Sequence[SolveRequest], where: Sequence[str]) -> F64:
    """The start poses ``[B, 21, 3]`` (joint order) of validated requests; a pose with a
    zero-length bone is refused, naming the pose and the joints."""
    arr = start_poses(requests)
    check_bones(arr, where.__getitem__)
    return arr


def start_poses(requests: Sequence[SolveRequest]) -> F64:
    """The start poses ``[B, 21, 3]`` (joint order) of validated requests, unchecked."""
    flat = itertools.chain.from_iterable
    return np.fromiter(
        flat(flat(_JOINTS(r.pose) for r in requests)),
        np.float64,
        3 * len(JOINT_NAMES) * len(requests),
    ).reshape(len(requests), len(JOINT_NAMES), 3)


def check_bones(arr: F64, where: Callable[[int], str]) -> None:
    """Refuse poses ``[B, 21, 3]`` with a zero-length bone, naming every such pose
    (``where(b)``) and its joints, the first ``MAX_ERRORS`` listed (``every_item``: the
    first alone was, and a batch client fixed one pose a round trip)."""
    bad, found = degenerate(arr, where)
    if bad:
        raise every_item(found, len(bad))


def degenerate(arr: F64, where: Callable[[int], str]) -> tuple[list[int], list[InvalidRequest]]:
    """The poses ``[B, 21, 3]`` with a zero-length bone (every one's index) and the errors
    of the first ``MAX_ERRORS`` of them (``where(b)`` names pose ``b``, and its joints)."""
    shortest = compiled.shortest_bones(compiled.as_f64(arr))
    if not (shortest.size and shortest.min() < MIN_BONE):
        return [], []
    bad: list[int] = np.flatnonzero(shortest < MIN_BONE).tolist()
    found = []
    for b in bad[:MAX_ERRORS]:
        short = [
            JOINT_NAMES[c]
            for (c, _), n in zip(BONES, bone_lengths(arr[b]), strict=True)
            if n < MIN_BONE
        ]
        found.append(
            InvalidRequest(
                f"{where(b)}: degenerate pose: zero-length bones ending at {', '.join(short)} "
                f"(each joint must be at least {MIN_BONE * 1000:g} mm from its parent)"
            )
        )
    return bad, found


def solve_problem(req: SolveRequest, pose: F64, where: str = "") -> SolveProblem:
    """One solve's targets and pins against its ``pose`` ``[21, 3]``."""
    return problem_of(
        pose,
        [JOINT_INDEX[t.joint] for t in req.targets],
        np.array([t.position for t in req.targets], dtype=np.float64),
        [t.weight for t in req.targets],
        [JOINT_INDEX[p] for p in req.pins],
        req.options,
        where,
    )


def check_options(options: SolveOptions, pinned: bool, where: str = "") -> None:
    """Refuse ``options.preserve_bone_lengths: false`` (the networks' raw answer, bones not
    kept) beside what keeps the bone lengths by construction: ``method: "fabrik"``,
    ``reach: "exact"`` and pins (each was silently ignored). Every request form checks its
    options here: the pose, character and BVH forms and the batch's items through
    :func:`problem_of`, the columnar batch through ``service.columnar.parse``."""
    if options.preserve_bone_lengths:
        return
    against = [
        name
        for name, on in (
            ('options.method "fabrik"', options.method == "fabrik"),
            ('options.reach "exact"', options.reach == "exact"),
            ("pins", pinned),
        )
        if on
    ]
    if against:
        prefix = f"{where}." if where else ""
        keep = "keep" if len(against) > 1 or against == ["pins"] else "keeps"
        raise InvalidRequest(
            f"{prefix}options.preserve_bone_lengths: false (the networks' raw answer, bones "
            f"not kept) conflicts with {' and '.join(against)}, which {keep} the bone lengths "
            "by construction; leave preserve_bone_lengths out (or true), or ask for the raw "
            'answer with method "neural", reach "soft" and no pins'
        )


def pin_weights(weights: npt.NDArray[np.float64], pins: int) -> npt.NDArray[np.float64]:
    """The weights of a problem's targets ``[..., K]`` followed by its ``pins``' ``[..., K +
    pins]``: each pin weighs as the heaviest target, so only the targets' weights relative
    to each other count, pins or not (a pin weighed 1 whatever the targets did: all weights
    2 instead of 1 put the pins' solver first and moved joints 6 cm, all 0.001 in exact reach
    29.6 cm; an API audit, 2026-12-08). The rule of every form: the pose and character forms
    (:func:`problem_of`) and the columnar batch (``service.columnar``)."""
    if weights.shape[-1] == 0:  # (no target: a pin weighs 1)
        heaviest = np.ones((*weights.shape[:-1], 1))
    else:
        heaviest = weights.max(axis=-1, keepdims=True)
    return np.concatenate([weights, np.repeat(heaviest, pins, axis=-1)], axis=-1)


def problem_of(
    pose: F64,
    targets: Sequence[int],
    goals: F64,
    weights: Sequence[float],
    pins: Sequence[int],
    options: SolveOptions,
    where: str = "",
    given: tuple[Sequence[str], Sequence[str]] | None = None,
) -> SolveProblem:
    """The engine problem of canonical joint indices ``targets`` (at ``goals`` ``[K, 3]``)
    and ``pins`` (held where ``pose`` has them); refuses a joint targeted twice, pinned
    twice, or both, and options that conflict (:func:`check_options`). Shared by
    ``/v1/solve`` and the character routes; ``given``: the names
    the client sent for the targets and the pins (a character's own), for the messages."""
    check_options(options, bool(len(pins)), where)
    prefix = f"{where}." if where else ""

    def named(j: int, k: int, pin: bool) -> str:
        sent = None if given is None else given[pin][k]
        canon = JOINT_NAMES[j]
        return repr(canon) if sent in (None, canon) else f"{quoted(sent)} (mapped to {canon!r})"

    def again(j: int, sent: str | None) -> str:
        """The entry that named joint ``j`` before, where the client named it otherwise
        (a character's own name and the canonical one: it said only the second)."""
        k = idx.index(j)
        pin, at = k >= n_targets, k - n_targets if k >= n_targets else k
        first = None if given is None else given[pin][at]
        if first is None or sent is None or first == sent:
            return ""
        return f": {'pins' if pin else 'targets'}[{at}], {quoted(first)}, is the same joint"

    idx: list[int] = []
    n_targets = len(targets)
    for i, j in enumerate(targets):
        if j in idx:
            sent = None if given is None else given[0][i]
            raise InvalidRequest(
                f"{prefix}targets[{i}]: duplicate target for joint {named(j, i, False)}"
                f"{again(j, sent)}"
            )
        idx.append(j)
    for i, j in enumerate(pins):
        name, sent = named(j, i, True), None if given is None else given[1][i]
        if j in idx[:n_targets]:
            raise InvalidRequest(
                f"{prefix}pins[{i}]: joint {name} is both pinned and targeted{again(j, sent)}"
            )
        if j in idx:
            raise InvalidRequest(f"{prefix}pins[{i}]: joint {name} is pinned twice{again(j, sent)}")
        idx.append(j)
    target_idx = np.array(idx, dtype=np.intp)
    goals = np.reshape(goals, (-1, 3))
    o = options
    return SolveProblem(
        pose=pose,
        target_idx=target_idx,
        target_pos=np.concatenate([goals, pose[pins]]) if len(pins) else goals.copy(),
        weights=pin_weights(np.array(weights, dtype=np.float64), len(pins)),
        n_targets=n_targets,
        method=o.method,
        preserve_bone_lengths=o.preserve_bone_lengths,
        reach=o.reach,
        tolerance=o.tolerance,
        floor=o.floor,
        passes=o.passes,
        carry=o.carry,
        turn_search=o.turn_search,
        mirror=o.mirror,
        soft_ik=o.soft_ik,
        names=None if given is None else (*given[0], *given[1]),
    )


def keypoints(req: CompleteRequest) -> dict[str, F64]:
    """Key points by joint, each joint at most once."""
    points: dict[str, F64] = {}
    for i, kp in enumerate(req.keypoints):
        if kp.joint in points:
            raise InvalidRequest(f"keypoints[{i}]: duplicate key point {kp.joint!r}")
        points[kp.joint] = np.asarray(kp.position, dtype=np.float64)
    return points


def validate_as(
    data: Any,
    handler: ValidatorFunctionWrapHandler,
    form: Callable[[Any], type[BaseModel]],
    context: Any = None,
) -> Any:
    """A union body's wrap validator: validate ``data`` as the one form ``form(data)`` names,
    within the validation's ``context`` (``service.bounded``), so that its errors are
    located as in that form (without the union's tag), and hand ``handler`` the instance
    (which it takes as it is). A body is validated once: a failing one was validated
    through the union, then again as its form."""
    if isinstance(data, BaseModel):  # validated already (FastAPI hands the body back)
        return handler(data)
    return handler(form(data).model_validate(data, context=context))
