"""Exact reach on a character's own skeleton: a damped least-squares polish (its steps
compiled: :mod:`core.compiled_reach`).

:func:`core.retarget.retarget` lays a character's joints onto a solved canonical pose group
by group, and meets each exact target through the short chain of single-child aims above
it. That left misses the canonical solve had not made, where no such chain exists or the
character's joints do not fall where the canonical ones did: on five studios' files, a neck
moved forward with both ankles pinned ended 14-60 mm short (a spine of other joints than
the canonical one), a pin was broken by up to 11 mm (the chest's turn for a head), a
pelvis placed by a weighted fit was 0.4-1.5 mm off, and in soft reach a lowered pelvis
ended 3-6 cm from where the canonical answer had put it.

:func:`polish` closes what is left on the character itself: every rotatable joint above a
met point (targets and pins) turns but those above the pelvis's joint (:func:`_over_pelvis`:
a ground root over the hips is left as it was), and the root moves, by damped least-squares steps
(Levenberg-Marquardt, at most :data:`_MAX_TURN` a step) in the character's own bone
lengths. Pins weigh :data:`_PIN_WEIGHT` targets and no step takes one farther than half
the tolerance (:data:`_HOLD`; at least 0.5 mm on a 1 m reach, :data:`_SLACK`, brought
back by the last phase), so a target the skeleton cannot reach with its pins held comes nearer and
the pins stay. First the other canonical points weigh :data:`_FOLLOW` each, so the rest of
the body stays where the retarget laid it unless the targets need it to move; then (exact
reach) the targets alone, from there, so that no pull of the others leaves them short;
last, where a target out of reach pulled a pin off, the pins first (the targets at a tenth
of their weight, so that they do not wander). The root's move is priced as a turn at a
tenth of the body's reach (:data:`_MOVE_PRICE`), so turns come first where they do it.
The result is kept only where no pin that was met is lost and the pins' farthest miss is
smaller (a target met before may be lost for it: pins come first), or, no point that was
met lost and the pins no worse (or within half the tolerance), the targets'. The targets
the canonical answer met come as pins where the caller pinned nothing, else as targets
below the caller's pins (``core.retarget``, ``service.characters.solve_prepared``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from core.characters import F64, Pose, Skeleton, forward_kinematics
from core.characters_maps import Anchor, JointMap
from core.compiled_reach import descend_into
from core.skeleton import JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS

_PELVIS = JOINT_INDEX["pelvis"]
_STEPS = 30  # damped steps tried at most per phase (each one forward kinematics)
_MAX_TURN = 0.1  # radians per step and axis (a root's move: as much, priced)
_HOLD = 0.5  # a pin may move a half of the tolerance in the steps (or as far as it started)
_SLACK = 0.005  # ... or 0.5 mm on a 1 m reach, whichever is more (a tight tolerance froze it)
_PIN_WEIGHT = 30.0  # a pin's miss counts 30 times a target's (900 times in the squares)
_FOLLOW = 0.02  # the other points' moves count 0.02 of a target's miss: they follow
_STALL, _GAIN = 5, 0.01  # stop once 5 steps taken have gained less than 1 % of the squares
_MOVE_PRICE = 0.1  # a move of the root by d costs as a turn of d / (0.1 x the body's reach)


def _misses(points: F64, goals: F64) -> F64:
    out: F64 = np.linalg.norm(points - goals, axis=1)
    return out


def _ancestry(skel: Skeleton) -> npt.NDArray[np.bool_]:
    """``[J, J]``: True where joint ``a`` is joint ``b`` or one of its ancestors (``[a, b]``)."""
    out = np.eye(skel.size, dtype=np.bool_)
    for j, p in enumerate(skel.parents):  # parents first
        if p >= 0:
            out[:, j] |= out[:, p]
    return out


def _over_pelvis(
    skel: Skeleton, tree: npt.NDArray[np.bool_], pelvis: int, hang: npt.NDArray[np.bool_]
) -> npt.NDArray[np.bool_]:
    """``[J]``: True for the joints above the pelvis's joint ``pelvis`` that the polish leaves
    as they are (a ground root over the hips: Bandai-Namco's ``joint_Root``, UE's
    ``Reference``). The pelvis's joint turns the whole body, and it or the joint whose
    translation the polish moves carries it, so a turn of a joint above only swings the body
    about another point (a 2-11 degree turn of a root that is the identity in every frame
    of the clip). Kept movable: one that a met point (``tree``: ancestry ``[J, J]``;
    ``hang``: which met points hang from which joint, ``[J, n]``) hangs from other than
    through the pelvis's joint (a prop on the root), and, where the pelvis's joint cannot
    turn, the nearest rotatable joint above it (nothing below can turn the body)."""
    out = tree[:, pelvis].copy()
    out[pelvis] = False
    through = hang[pelvis]
    for j in np.flatnonzero(out):
        if (hang[j] & ~through).any():
            out[j] = False
    if not skel.rotatable[pelvis]:
        b = skel.parents[pelvis]
        while b >= 0 and not skel.rotatable[b]:
            b = skel.parents[b]
        if b >= 0:
            out[b] = False
    return out


def polish(
    skel: Skeleton,
    pose: Pose,
    jmap: JointMap,
    exact: Sequence[tuple[int, F64]],
    pins: Sequence[tuple[int, F64]],
    tolerance: float,
    root: int | None,
    finish: bool = True,
) -> set[int]:
    """Move ``pose`` (in place) so its canonical points ``exact`` and ``pins`` (canonical
    joint, goal; character units) are met within ``tolerance`` where the skeleton can, no
    pin moved in a step farther than half of it (or than it started, or 0.5 mm on a 1 m
    reach), the last phase bringing them back; ``root`` is the joint
    whose translation may move (None: none); ``finish``: after the phase where the other
    points follow, one for the targets alone (exact reach; soft reach stops short of it).
    Returns the joints whose rotation or translation it changed (none where it found no
    better pose: one that meets them nearer and loses none that was met)."""
    if not exact and not pins:
        return set()
    g_rot, g_pos = forward_kinematics(skel, pose)
    every = jmap.points(g_rot, g_pos)
    met = [j for j, _ in exact] + [j for j, _ in pins]
    free = [j for j in range(len(every)) if j not in set(met)]
    n, k = len(met), len(exact)
    goals = np.concatenate([np.reshape([g for _, g in exact], (-1, 3)),
                            np.reshape([g for _, g in pins], (-1, 3)), every[free]])  # fmt: skip
    start = _misses(every[met + free], goals)
    if float(start[:n].max()) <= tolerance * 0.1:
        return set()
    anchors = np.array([int(jmap.joints[j]) for j in met + free], dtype=np.intp)
    tree = _ancestry(skel)
    below = tree[:, anchors]  # [J, K]: the point hangs from the joint
    over = _over_pelvis(skel, tree, int(jmap.joints[_PELVIS]), below[:, :n])
    turns = np.asarray(skel.rotatable, dtype=np.bool_) & below[:, :n].any(axis=1) & ~over
    movable = np.flatnonzero(turns).tolist()
    moves = root is not None and bool(below[root, :n].any())
    if not movable and not moves:
        return set()
    above = np.ascontiguousarray(below[movable], dtype=np.float64)
    scale = _MOVE_PRICE * max(float(np.linalg.norm(every - every[_PELVIS], axis=1).max()), 1e-9)
    fixed = np.concatenate([np.ones(k), np.full(n - k, _PIN_WEIGHT)])
    # no pin farther than this in the steps (the last phase brings them back)
    hold = max(float(start[k:n].max(initial=0.0)), tolerance * _HOLD, scale * _SLACK)
    state = (pose.rotations.copy(), pose.translations.copy(), start.copy())
    phases = [(fixed, _FOLLOW), (fixed, 0.0)] if finish else [(fixed, _FOLLOW)]
    phases.append((np.concatenate([np.full(k, 0.1), fixed[k:]]), _FOLLOW))  # pins first, last
    for i, (front, follow) in enumerate(phases):
        if i == len(phases) - 1 and float(state[2][k:n].max(initial=0.0)) <= tolerance * 0.1:
            break  # (needed only where a target out of reach pulled a pin off)
        weight = np.concatenate([front, np.full(len(free), follow)])
        state = _descend(skel, jmap, met + free, goals, weight, state, movable, above,
                         root if moves else None, scale, hold, n, k, tolerance)  # fmt: skip
    rotations, translations, misses = state
    if not _better(start, misses, n, k, tolerance):
        return set()
    changed = {b for b in movable if not np.array_equal(rotations[b], pose.rotations[b])}
    if root is not None and not np.array_equal(translations[root], pose.translations[root]):
        changed.add(root)
    pose.rotations, pose.translations = rotations, translations
    return changed


def _better(start: F64, end: F64, n: int, k: int, tolerance: float) -> bool:
    """Whether misses ``end`` beat ``start`` (the first ``n``: ``k`` targets, then pins):
    no pin that was met lost, and the pins' farthest miss smaller (both within a tenth of
    the tolerance count as equal: a target met before may be lost for it, pins come
    first), or, no target that was met lost and the pins no worse (or within half the
    tolerance), the targets' farthest miss smaller."""
    lost = (start[:n] <= tolerance) & (end[:n] > tolerance)
    if lost[k:].any():
        return False
    p0, p1 = float(start[k:n].max(initial=0.0)), float(end[k:n].max(initial=0.0))
    if p1 < p0 - 1e-12 and p0 > tolerance * 0.1:
        return True
    if lost[:k].any():
        return False
    t0, t1 = float(start[:k].max(initial=0.0)), float(end[:k].max(initial=0.0))
    return p1 <= max(p0, tolerance * _HOLD) and t1 < t0 - 1e-12


_State = tuple[F64, F64, F64]  # local rotations, translations; the points' misses


def _descend(
    skel: Skeleton, jmap: JointMap, joints: list[int], goals: F64, weight: F64, state: _State,
    movable: list[int], above: F64, root: int | None, scale: float, hold: float, n: int,
    k: int, tolerance: float,
) -> _State:  # fmt: skip
    """Levenberg-Marquardt on the ``weight``-ed squares of the ``joints``' misses from
    ``goals`` (the first ``n`` met: ``k`` targets, then pins), by turns of ``movable`` and
    a move of ``root``; a step that takes a pin farther than ``hold`` is refused
    (:func:`core.compiled_reach.descend_into`, on copies of ``state``)."""
    rotations, translations, misses = (np.array(a, dtype=np.float64) for a in state)
    descend_into(
        np.require(skel.parent_array, np.int64, ["C", "W"]), rotations, translations,
        np.ascontiguousarray(jmap.joints[joints], dtype=np.int64),
        np.ascontiguousarray(jmap.offsets[joints, :, 0]), np.ascontiguousarray(goals),
        np.ascontiguousarray(weight, dtype=np.float64), np.array(movable, dtype=np.int64),
        above, -1 if root is None else int(root), float(scale), float(hold), int(n), int(k),
        float(tolerance), _STEPS, _MAX_TURN, _STALL, _GAIN, misses,
    )  # fmt: skip
    return rotations, translations, misses


#: The canonical skeleton's own joints as a joint map (every point on its joint), and which
#: of them turn something (a joint with children).
_CANONICAL_MAP = JointMap(
    tuple(Anchor(j, np.zeros(3), name) for j, name in enumerate(JOINT_NAMES)), "canonical"
)
_TURNS = tuple(j in PARENTS for j in range(NUM_JOINTS))


def polish_canonical(
    pose: F64,
    exact: Sequence[tuple[int, F64]],
    pins: Sequence[tuple[int, F64]],
    tolerance: float,
    finish: bool,
) -> F64 | None:
    """:func:`polish` of a canonical pose ``[21, 3]`` (world, metres) as a body of its own
    bones: each joint turns its subtree rigidly (the pelvis its spine and hips together, the
    chest its neck and collars), the pelvis moves, bone lengths stay as they are. ``exact``
    and ``pins``: (canonical joint, goal). The polished pose, or None where it found none
    better (:func:`_better`: pins first)."""
    parents = np.asarray(PARENTS)
    offsets = pose - np.where(parents[:, None] >= 0, pose[np.maximum(parents, 0)], 0.0)
    skel = Skeleton(JOINT_NAMES, PARENTS, offsets, _TURNS, tuple(p < 0 for p in PARENTS))
    body = Pose(np.tile(np.eye(3), (NUM_JOINTS, 1, 1)), offsets.copy())
    if not polish(skel, body, _CANONICAL_MAP, exact, pins, tolerance, 0, finish):
        return None
    return forward_kinematics(skel, body)[1]
