"""From solved canonical points back to a character's own local rotations (numpy).

:func:`canonical_points` gives the 21 mapped points of a character's pose;
:func:`retarget` changes that pose so its mapped points go where a solve put them:

1. **Root**: the nearest joint at or above the pelvis's joint that carries its own
   translation (the root position, or a BVH joint with position channels) is moved so the
   pelvis point lands on the solved pelvis.
2. **Aim pass**, joints in skeleton order (parents first). A joint that carries canonical
   joints with canonical children (its *aim group*) turns so those children point from its
   origin to their solved positions. One child: the *swing* only, the minimal rotation
   taking the old bone direction to the new one, applied in the parent's frame, so the bone
   keeps its twist. Several children (pelvis, chest): the least-squares rotation over all
   of them (Kabsch), the one rotation a rigid bone can take.
3. **Exact reach** (optional): for each target, the chain of single-child aims above it is
   FABRIK-ed, in the character's own bone lengths, from its fixed top onto the target, and
   the aim pass re-run, so the target is met whenever that chain can reach it. A goal still
   out of its chain's reach after that moves the whole body towards it and the pass is
   repeated: a pin's always, a target's where nothing holds the body, a held target's
   (one the solve met) only where the answer misses it otherwise.
4. **Polish** (:func:`core.reach.polish`): what the targets and pins still miss is closed
   by damped least-squares turns of the joints above them, pins first.
5. **Hinges** (:func:`core.hinges.keep_hinges`): an elbow or knee the frame bends as a
   hinge bends about the same axis, the upper bone twisted to suit; no point moves.

Joints in no aim group (fingers, twist bones, props, spine joints between mapped ones)
keep their local rotation but where the polish turns them (and a hinge's children, step 5,
their world rotation); every joint keeps its offset,
so bone lengths are the character's own.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core import compiled_characters
from core.characters import F64, Pose, Skeleton, forward_kinematics, swing
from core.characters_maps import JointMap
from core.compiled_chain import chain_fabrik
from core.hinges import keep_hinges
from core.reach import polish
from core.skeleton import JOINT_INDEX, PARENTS

_PELVIS = JOINT_INDEX["pelvis"]
_HIPS = (JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"])
#: weight of a pinned child (or one above a pin) against the others where a joint aims
#: several: a chest under a pinned neck or head
HEAVY = 100.0
#: each canonical joint's first child (joints without children absent)
_FIRST_CHILD = {p: c for c, p in reversed(list(enumerate(PARENTS))) if p >= 0}


def canonical_points(skel: Skeleton, pose: Pose, jmap: JointMap) -> F64:
    """The 21 canonical points ``[21, 3]`` of a pose, in the character's units and axes."""
    g_rot, g_pos = forward_kinematics(skel, pose)
    return jmap.points(g_rot, g_pos)


@dataclass(frozen=True)
class _Plan:
    groups: dict[int, list[int]]  # aim joint -> canonical children it aims
    aim_of: dict[int, int]  # canonical joint -> aim joint of its bone to its parent
    #: the groups as arrays for the compiled pass: aim joints in skeleton order, and their
    #: children ``kids[kid_start[i]:kid_start[i + 1]]``
    aims: npt.NDArray[np.int64]
    kid_start: npt.NDArray[np.int64]
    kids: npt.NDArray[np.int64]
    #: the skeleton's parents and the anchors' joints ``[21]`` and offsets ``[21, 3]``, as
    #: the kernel takes them (contiguous), once per retarget rather than once per pass
    parents: npt.NDArray[np.int64]
    anchor_joints: npt.NDArray[np.int64]
    anchor_offsets: F64


def _plan(skel: Skeleton, jmap: JointMap) -> _Plan:
    groups: dict[int, list[int]] = {}
    aim_of: dict[int, int] = {}
    for c, p in enumerate(PARENTS):
        if p < 0:
            continue
        b = jmap.anchors[p].joint
        if not skel.rotatable[b]:
            continue
        groups.setdefault(b, []).append(c)
        aim_of[c] = b
    aims = sorted(groups)
    sizes = [len(groups[b]) for b in aims]
    return _Plan(
        groups,
        aim_of,
        np.array(aims, dtype=np.int64),
        np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
        np.array([c for b in aims for c in groups[b]], dtype=np.int64),
        np.require(skel.parent_array, np.int64, ["C", "W"]),
        np.require(jmap.joints, np.int64, ["C", "W"]),
        np.require(jmap.offsets.reshape(-1, 3), np.float64, ["C", "W"]),
    )


def _aim_pass(
    skel: Skeleton,
    pose: Pose,
    jmap: JointMap,
    plan: _Plan,
    goal: F64,
    skip: int | None,
    original: Pose,
    weigh: F64,
) -> set[int]:
    """Aim every group (parents first), in one compiled call
    (:func:`core.compiled_characters.aim_pass_into`). Each turn starts from the joint's
    *original* local rotation, so a joint aimed again (exact reach) still differs from the
    input by one swing, never by a twist. A group that aims two children or more (a
    chest, a pelvis) takes their least-squares turn, each child weighing its length times
    ``weigh [21]`` (:func:`_weights`: pins and held goals, and their parents, weigh
    :data:`HEAVY` times the others, so a chest turns a pinned neck, or a pinned head's
    neck, where the solve put it and lets the collars follow)."""
    rotations = np.require(pose.rotations, np.float64, ["C", "W"])
    pose.rotations = rotations
    translations = np.require(pose.translations, np.float64, ["C", "W"])
    first = np.require(original.rotations, np.float64, ["C", "W"])
    goal = np.require(goal, np.float64, ["C", "W"])
    g_rot, g_pos = np.empty((skel.size, 3, 3)), np.empty((skel.size, 3))
    changed = np.zeros(len(plan.aims), dtype=np.uint8)
    compiled_characters.aim_pass_into(
        plan.parents, rotations, translations, first, plan.aims, plan.kid_start, plan.kids,
        plan.anchor_joints, plan.anchor_offsets, goal, -1 if skip is None else skip,
        weigh, g_rot, g_pos, changed,
    )  # fmt: skip
    return {int(b) for b in plan.aims[changed.astype(bool)]}


def _weights(heavy: frozenset[int]) -> F64:
    """Each canonical joint's weight ``[21]`` in a least-squares aim: :data:`HEAVY` for
    those in ``heavy``, else 1."""
    out = np.ones(len(PARENTS))
    out[sorted(heavy)] = HEAVY
    return out


def _place_pelvis(
    skel: Skeleton, pose: Pose, jmap: JointMap, plan: _Plan, goal: F64
) -> tuple[int | None, int | None]:
    """Move and turn the pelvis's joint as one rigid body onto the solved pelvis, spine1 and
    hips (weighted Kabsch with translation; the hips weigh most, since the legs hang from
    them). Returns (the joint translated, the joint turned), None where none could be.

    An exact pelvis target once weighed the pelvis 100 times, so that the fit put it on the
    goal: the turn then fitted the solved hips and spine about the pelvis alone, and where
    the character's pelvis triangle is not the networks' (its hips nearly level with its
    pelvis), a lowered pelvis turned the character's 139-161 degrees over, its spine below
    its hips and its shoulders shrugged to 0.66-0.77 of their width (an API audit,
    2026-12-07, AnimatedDrawings' children). The exact reach that follows meets the pelvis
    target anyway (0.002-0.003 mm there)."""
    anchor = jmap.anchors[_PELVIS]
    t = anchor.joint
    while t >= 0 and not skel.translatable[t]:
        t = skel.parents[t]
    if t < 0:
        return None, None
    b = anchor.joint
    kids = plan.groups.get(b, [])
    members = [_PELVIS, *kids]
    weights = np.array([0.25] + [1.0 if c in _HIPS else 0.25 for c in kids])
    g_rot, g_pos = forward_kinematics(skel, pose)
    now = jmap.points(g_rot, g_pos)[members]
    want = goal[members]
    w = weights / weights.sum()
    c_now, c_want = w @ now, w @ want
    turn = np.eye(3)
    if kids and skel.rotatable[b]:
        turn = compiled_characters.best_rotation(now - c_now, want - c_want, w)
    origin = turn @ (g_pos[b] - c_now) + c_want
    delta = origin - g_pos[b]
    parent = skel.parents[t]
    pose.translations[t] = pose.translations[t] + (delta if parent < 0 else g_rot[parent].T @ delta)
    if not kids or not skel.rotatable[b]:
        return t, None
    new_global = turn @ g_rot[b]
    parent = skel.parents[b]
    if parent >= 0:
        g_rot, _ = forward_kinematics(skel, pose)
    pose.rotations[b] = new_global if parent < 0 else g_rot[parent].T @ new_global
    return t, b


def _chain(plan: _Plan, jmap: JointMap, target: int) -> list[int]:
    """Canonical joints [top, ..., target] whose aims each carry that one child; the top's
    own aim joint is fixed by the joints above. Empty when no aim is free to move."""
    chain = [target]
    c = target
    while True:
        b = plan.aim_of.get(c)
        if b is None or plan.groups[b] != [c]:
            break
        p = PARENTS[c]
        chain.insert(0, p)
        c = p
    if len(chain) < 2:
        return []
    # every point inside the chain must be the origin of the next aim joint (no End Site
    # or part-way point), so that each aim turns the chain about that point
    if any(np.any(jmap.anchors[c].offset != 0) for c in chain[1:-1]):
        return []
    return chain


_ROUNDS = 8


def _nearer(
    skel: Skeleton, pose: Pose, jmap: JointMap, exact: Sequence[tuple[int, F64]], old: F64
) -> bool:
    """Whether ``pose`` meets its exact targets (pins included) nearer than it did with the
    local rotations ``old``: its farthest miss smaller, by more than rounding."""
    joints = [j for j, _ in exact]
    goals = np.asarray([g for _, g in exact], dtype=np.float64)

    def worst(rotations: F64) -> float:
        g_rot, g_pos = forward_kinematics(skel, Pose(rotations, pose.translations))
        return float(np.linalg.norm(jmap.points(g_rot, g_pos)[joints] - goals, axis=1).max())

    return worst(pose.rotations) < worst(old) - 1e-12


def _widened(
    skel: Skeleton, pose: Pose, jmap: JointMap, plan: _Plan, goal: F64, chain: list[int],
    target: F64, exact: Sequence[tuple[int, F64]], tolerance: float, bend: F64 | None,
    turned: int | None,
) -> F64 | None:  # fmt: skip
    """A target its chain left short, where the chain's top hangs from a joint that aims
    several (a chest: the neck and both collars): that joint's turn joins the chain. The
    head's chain is the neck alone, one bone from a neck point the chest's least-squares
    turn placed millimetres off, so exact reach missed a head by 3-7 mm on every file
    tried. The chain with the joint's origin in front is FABRIK-ed onto the target, and
    the goals of all its aimed children are turned rigidly about that origin by the
    swing that carries the chain's top where FABRIK put it (the chest turns as one, arms
    with it), so its least-squares turn lands the top there exactly. Not where another
    exact target or pin lies on the chain or hangs from one of the joint's other children
    (the chest's turn would move it), nor for the pelvis (placed, not aimed); the caller
    keeps the result only where it meets the exact targets nearer (:func:`_nearer`).
    Returns the widened goals (a copy of ``goal``), or None where it does not apply."""
    joint, aim = chain[-1], plan.aim_of.get(chain[0])
    goal_t = np.asarray(target, dtype=np.float64)
    if aim is None or aim == turned or len(plan.groups[aim]) < 2:
        return None  # (the pelvis, ``turned``, is placed by _place_pelvis, not aimed)
    others = [c for c in plan.groups[aim] if c != chain[0]]
    for j, _ in exact:
        if j != joint and j in chain:  # a pin or target on the chain itself (a neck)
            return None
        while j >= 0 and j not in others and j != joint:
            j = PARENTS[j]
        if j in others:
            return None
    g_rot, g_pos = forward_kinematics(skel, pose)
    pts = jmap.points(g_rot, g_pos)
    if float(np.linalg.norm(pts[joint] - goal_t)) <= tolerance:
        return None
    origin, top = g_pos[aim], g_pos[jmap.anchors[chain[0]].joint]
    line = np.concatenate([origin[None], top[None], pts[chain[1:]]])
    done = chain_fabrik(line, goal_t, tolerance * 0.01, bend=bend)
    turn = swing(top - origin, done[1] - origin)
    wider = goal.copy()
    for c in plan.groups[aim]:
        wider[c] = origin + turn @ (pts[c] - origin)
    wider[chain[1:]] = done[2:]
    return wider


def _attempt(
    skel: Skeleton,
    pose: Pose,
    jmap: JointMap,
    plan: _Plan,
    goal: F64,
    exact: Sequence[tuple[int, F64]],
    tolerance: float,
    shifts: Sequence[bool],
    weigh: F64,
) -> tuple[Pose, set[int], F64 | None, int | None]:
    """One retarget onto ``goal``; the shift of the pelvis that would bring the exact
    targets out of reach of their chains within reach (None if none is needed), and the
    joint whose translation places the pelvis (None if none)."""
    new = pose.copy()
    goal = goal.copy()
    changed: set[int] = set()
    root, turned = _place_pelvis(skel, new, jmap, plan, goal)
    if turned is not None:
        changed.add(turned)
    changed |= _aim_pass(skel, new, jmap, plan, goal, turned, pose, weigh)
    moves = []
    for (joint, target), may_shift in zip(exact, shifts, strict=True):
        chain = _chain(plan, jmap, joint)
        if not chain:
            continue
        g_rot, g_pos = forward_kinematics(skel, new)
        pts = jmap.points(g_rot, g_pos)
        top = jmap.anchors[chain[0]].joint
        line = np.concatenate([g_pos[top][None], pts[chain[1:]]])
        reach = float(np.linalg.norm(np.diff(line, axis=0), axis=1).sum())
        gap = np.asarray(target, dtype=np.float64) - g_pos[top]
        far = float(np.linalg.norm(gap)) - reach * (1.0 - 1e-6)
        if far > tolerance * 0.1 and may_shift:
            moves.append(gap / np.linalg.norm(gap) * (far + tolerance * 0.5))
        kid = _FIRST_CHILD.get(joint)  # e.g. the foot of an ankle: where a knee bends to
        bend = None if kid is None else pts[kid] - pts[joint]
        done = chain_fabrik(line, np.asarray(target, dtype=np.float64), tolerance * 0.01, bend=bend)
        goal[chain[1:]] = done[1:]
        changed |= _aim_pass(skel, new, jmap, plan, goal, turned, pose, weigh)
        wider = _widened(skel, new, jmap, plan, goal, chain, target, exact, tolerance, bend, turned)
        if wider is not None:
            rotations, aimed = new.rotations.copy(), set(changed)
            aimed |= _aim_pass(skel, new, jmap, plan, wider, turned, pose, weigh)
            if _nearer(skel, new, jmap, exact, rotations):  # only ever a better answer
                goal, changed = wider, aimed
            else:
                new.rotations = rotations
    if root is not None and not np.array_equal(new.translations[root], pose.translations[root]):
        changed.add(root)
    shift = np.mean(moves, axis=0) if moves else None
    return new, changed, shift, root


@dataclass(frozen=True)
class Retargeted:
    pose: Pose
    points: F64  # [21, 3] canonical points of the new pose (character units and axes)
    changed: frozenset[int]  # joints whose local rotation or translation changed


def retarget(
    skel: Skeleton,
    pose: Pose,
    jmap: JointMap,
    solved: F64,
    *,
    exact: Sequence[tuple[int, F64]] = (),
    pins: Sequence[tuple[int, F64]] = (),
    held: Sequence[tuple[int, F64]] = (),
    soft: Sequence[tuple[int, F64]] = (),
    tolerance: float = 0.0,
) -> Retargeted:
    """A copy of ``pose`` whose canonical points follow ``solved`` ``[21, 3]`` (character
    units and axes); ``exact`` lists (canonical joint, goal) pairs to meet within
    ``tolerance`` where the character's own chain can, ``pins`` pairs to hold first,
    ``held`` pairs held as pins are (targets a solve met), ``soft`` pairs to come near as
    the rest of the body allows (see the module docstring). The whole body is moved
    towards a pin out of its chain's reach, towards an exact goal only where nothing holds
    it (no pin, no pelvis target: the shift would break them), and towards a held goal only
    where the answer misses it otherwise: a chain's top the character cannot put where the
    solve did (a rigid chest under a collar the solve swung) is no reason to carry the
    body across, the polish turns the joints above it first."""
    plan = _plan(skel, jmap)
    # pins shift the body; targets only where nothing holds it (no pin, no pelvis target)
    free = not pins and not held and all(j != _PELVIS for j, _ in exact)
    lead = [free] * len(exact) + [True] * len(pins)
    steady = _fit(skel, pose, jmap, plan, solved, exact, pins, held, soft, tolerance,
                  [*lead, *[False] * len(held)])  # fmt: skip
    if held and _worst(steady.points, [*pins, *held]) > tolerance:  # shift for them too
        moved = _fit(skel, pose, jmap, plan, solved, exact, pins, held, soft, tolerance,
                     [*lead, *[True] * len(held)])  # fmt: skip
        # kept where it holds the pins no worse and meets the held goals nearer by more than
        # half the tolerance (a gain of micrometres is not worth carrying the body across)
        pinned = _worst(moved.points, pins) <= max(_worst(steady.points, pins), tolerance) * (
            1.0 + 1e-9
        )
        if pinned and _worst(moved.points, held) < _worst(steady.points, held) - tolerance / 2:
            return moved
    return steady


def _worst(points: F64, pairs: Sequence[tuple[int, F64]]) -> float:
    """The farthest of ``points`` from its goal in ``pairs`` (0 for none)."""
    if not pairs:
        return 0.0
    goals = np.asarray([g for _, g in pairs], dtype=np.float64)
    return float(np.linalg.norm(points[[j for j, _ in pairs]] - goals, axis=1).max())


def _fit(
    skel: Skeleton,
    pose: Pose,
    jmap: JointMap,
    plan: _Plan,
    solved: F64,
    exact: Sequence[tuple[int, F64]],
    pins: Sequence[tuple[int, F64]],
    held: Sequence[tuple[int, F64]],
    soft: Sequence[tuple[int, F64]],
    tolerance: float,
    shifts: Sequence[bool],
) -> Retargeted:
    """:func:`retarget` with ``shifts`` saying which of ``[*exact, *pins, *held]`` may move
    the whole body towards them when out of their chain's reach. The polish holds the held
    goals as pins where the caller pinned nothing, and as targets below the pins where it
    did (a pinned neck is not left off to keep a wrist the answer met)."""
    goal = np.array(solved, dtype=np.float64)
    body = [_PELVIS, *plan.groups.get(jmap.anchors[_PELVIS].joint, [])]
    kept = [*pins, *held]  # held as pins are while the body is laid out
    # the pins and held goals and their parents (a pinned head: its neck, a chest's child)
    weigh = _weights(frozenset({j for j, _ in kept} | {PARENTS[j] for j, _ in kept}))
    for _ in range(_ROUNDS):
        new, changed, shift, root = _attempt(
            skel, pose, jmap, plan, goal, [*exact, *kept], tolerance, shifts, weigh
        )
        if shift is None:
            break
        goal[body] += shift  # out of reach from the pelvis: move the whole body towards it
    # (soft reach: the targets come near, no phase for them alone)
    if pins and held:
        changed |= polish(skel, new, jmap, [*exact, *held], pins, tolerance, root)
    else:
        changed |= polish(skel, new, jmap, soft or exact, kept, tolerance, root, finish=not soft)
    changed |= keep_hinges(skel, pose, new, jmap, changed)  # the points stay where they are
    g_rot, g_pos = forward_kinematics(skel, new)
    return Retargeted(new, jmap.points(g_rot, g_pos), frozenset(changed))
