"""Key-point completion (Cascadeur-style): a whole pose from 6, 11 or 16 joints, through
the engine's completion levels (onnxruntime + numpy, no torch)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from core.geometry import symmetry_views, unview
from core.skeleton import (
    BONES,
    JOINT_INDEX,
    JOINT_NAMES,
    MIRROR,
    NUM_JOINTS,
    PARENTS,
    bone_lengths,
)
from service.errors import InvalidRequest
from service.floors import FLOOR_REACH
from service.lean import BOUND_ITEMS
from service.problems import CompleteResult
from service.schemas import BONE_M
from service.upright import keypoints_warning

if TYPE_CHECKING:
    from service.engine import Engine

F64 = npt.NDArray[np.floating[Any]]


#: The base points must span at least this much (m): the networks read a body's size from
#: them, and six points at one spot have none (a 422, as a degenerate pose is for a solve).
MIN_SPAN = 0.01
#: The sizes the completion networks know, as pelvis-to-neck distances over the reference
#: skeleton's spine (its three bones): they were trained on the recorded bodies (0.93-1.29,
#: 1st-99th percentile of the training split; held-out bodies 0.86-1.45) at x0.6-1.2
#: (``trainer.train.augment``). Key points of a body outside are scaled into it first and
#: the answer back: at x3 a key point was missed by 15 % of the body's size, bones came out
#: 30 % off (reviewed 2026-12-05). Inside, nothing changes.
TORSO_BAND = (0.55, 1.55)
#: The sizes ``bone_lengths`` may give a body, as their total over the body the key points
#: imply (the networks' estimate from them), before the answer says so: real bodies' own
#: bones total REAL_BODIES times it (6 key points of 150 TEST and 150 held-out poses, the
#: shipped models, 2026-12-07), every bone at 1 mm 0.005 times, at 2 m 10.
BONES_BAND = (0.5, 2.0)
REAL_BODIES = (0.97, 1.23)
#: Each bone's index, by its child joint's name.
_BONE = {JOINT_NAMES[c]: b for b, (c, _) in enumerate(BONES)}
#: How far a real body's base key point lies from where its limb starts (a wrist from the
#: neck, an ankle from the pelvis), in pelvis-to-neck distances: at most 2.08 and 2.91 over
#: every frame of the dataset, the held-out bodies the farthest (the train split's 1.59 and
#: 2.70; ``tests/service/test_completion_reach.py`` measures it). Key points farther than
#: :data:`LIMB_MARGIN` times that (arms or legs 20 % longer and a trunk 20 % shorter than
#: the farthest-reaching body recorded) make a limb no person has: without ``bone_lengths``
#: the networks stretch it to reach them (a wrist moved 1.5 m out: an arm of 1.44 m from
#: collar to wrist against 0.67, every key point reached and no word; an API audit,
#: 2026-12-07), and the answer says so (with ``bone_lengths``, the bones' own reach says
#: it: :func:`_implausible_bones`).
LIMB_REACH = {
    **dict.fromkeys(("left_wrist", "right_wrist"), ("neck", 2.1)),
    **dict.fromkeys(("left_ankle", "right_ankle"), ("pelvis", 3.0)),
}
LIMB_MARGIN = 1.5
_TRUNK = {JOINT_INDEX[j] for j in ("pelvis", "spine1", "spine2", "neck")}


def complete(
    engine: Engine,
    keypoints: dict[str, F64],
    given_lengths: dict[str, float] | None,
    tolerance: float = 1e-3,
    floor: float = 0.0,
) -> CompleteResult:
    """The whole pose ``engine``'s completion levels build from ``keypoints`` (world
    space, metres): level after level until every given point is an input, then the
    bone pass (the given ``given_lengths``, else the network's own proportions) and a
    polish onto the key points to ``tolerance``."""
    levels = engine.manifest.completion_levels()
    if any(j not in keypoints for j in levels[0].joints):
        raise below_the_floor([list(level.joints) for level in levels], list(keypoints))
    base = np.stack([keypoints[j] for j in levels[0].joints])
    span = float(np.max(np.linalg.norm(base[:, None] - base[None], axis=-1)))
    if span < MIN_SPAN:
        raise InvalidRequest(
            f"keypoints: the six base points lie within {span * 1000:.3g} mm of each other; "
            f"a body's size is read from them: they must span at least {MIN_SPAN * 100:g} cm"
        )
    # pelvis floor projection to the origin; the networks were trained for any yaw
    origin = keypoints["pelvis"].copy()
    torso = float(np.linalg.norm(keypoints["neck"] - keypoints["pelvis"]))
    if torso < MIN_SPAN:
        raise InvalidRequest(
            f"keypoints: the pelvis and the neck lie {torso * 1000:.3g} mm apart; the body's "
            f"size is read from them: they must be at least {MIN_SPAN * 100:g} cm apart"
        )
    # (and not above the lowest key point: a floor over the feet read the standing key
    # points as a body crouched or lying on it, 93-106 mm off: an API audit, 2026-12-07)
    lowest = min(float(v[1]) for v in keypoints.values())
    origin[1] = min(max(floor, origin[1] - FLOOR_REACH * torso), lowest)
    ref = engine.reference_lengths
    lengths = ref.copy()
    scale = 1.0
    if given_lengths:
        bad = sorted(set(given_lengths) - set(_BONE))
        if bad:
            raise InvalidRequest(
                f"bone_lengths: no bone ends at {bad} (name the child joint of each bone)"
            )
        ratio = float(np.median([given_lengths[j] / ref[_BONE[j]] for j in given_lengths]))
        lengths = ref * ratio
        # networks trained on random bodies at random sizes read the size from the key
        # points; older ones are fed the size of their nearest training skeleton
        scale = float(completion_scales(engine, lengths))
        for j, value in given_lengths.items():
            lengths[_BONE[j]] = value
    scale *= _out_of_band(engine, torso)
    given = {j: (v - origin) / scale for j, v in keypoints.items()}
    last = len(levels)
    for n, entry in enumerate(levels, start=1):
        if set(given) <= set(entry.joints):
            last = n
            break
    pred: F64 | None = None
    run: list[int] = []
    for n in range(1, last + 1):
        joints = levels[n - 1].joints
        rows = []
        for j in joints:
            if j in given:
                rows.append(given[j])
            else:
                assert pred is not None
                rows.append(pred[JOINT_INDEX[j]])
        pred = complete_level(engine, n - 1, np.stack(rows))
        run.append(n)
    assert pred is not None
    if not given_lengths:  # the network's own estimate of this body's proportions
        lengths = np.asarray(bone_lengths(pred), dtype=np.float64) * scale
    # a bone whose two ends are key points has the length they fix (at least the shortest
    # a bone may be: the answer is a pose /v1/solve takes; at any size: a body 10 times
    # the networks' took their estimate for its bones over 2 m and missed key points by
    # 1.56 m, an API audit, 2026-12-07), unless bone_lengths names it (the network's
    # estimate missed them by up to 11 mm, at levels 2 and 3)
    fixed_by_points: set[str] = set()
    for b, (c, p) in enumerate(BONES):
        child, parent = JOINT_NAMES[c], JOINT_NAMES[p]
        if child in keypoints and parent in keypoints and child not in (given_lengths or {}):
            fixed = float(np.linalg.norm(keypoints[child] - keypoints[parent]))
            if fixed >= BONE_M[0]:
                lengths[b] = fixed
                fixed_by_points.add(child)
    idx = np.asarray([JOINT_INDEX[j] for j in keypoints], dtype=np.intp)
    goal = np.stack([given[j] * scale for j in keypoints])
    # the compiled exact-reach polish (core.compiled_fabrik), as a solve's exact reach runs:
    # it first gives the pose these bone lengths (the bone pass), then reaches
    polished, _, _ = engine._fabrik(
        True, (pred * scale)[None], np.asarray(lengths, dtype=np.float64)[None], goal[None],
        np.full(1, tolerance), idx.astype(np.int64), np.ones(len(idx)),
        np.zeros(len(idx), dtype=np.bool_),
    )  # fmt: skip
    world = polished[0] + origin
    errors = np.linalg.norm(world[idx] - np.stack(list(keypoints.values())), axis=-1)
    told = _scaled_bones(engine, given_lengths or {}, fixed_by_points, lengths)
    if given_lengths:  # (the networks' own estimate: its known limit, docs/service.md)
        implied = float(np.sum(bone_lengths(pred))) * scale
        told += _implausible_bones(keypoints, lengths, implied, tolerance, bool(told))
    else:
        told += _stretched_limbs(keypoints, world, torso)
    told += _scaled_points(engine, torso)
    return CompleteResult(
        pose=world, errors=errors, reached=errors <= tolerance, levels=run,
        floor=float(origin[1]), scale_warning="; ".join(told) or None,
        up_warning=keypoints_warning(keypoints["pelvis"], keypoints["neck"]),
    )  # fmt: skip


def _scaled_bones(
    engine: Engine, given: dict[str, float], fixed: set[str], lengths: F64
) -> list[str]:
    """The answer's ``scale_warning`` of ``bone_lengths`` naming some bones, not all: the
    others (but those two key points fix) take the reference lengths times the named
    ones' median ratio, a body the request never gave (``{"left_wrist": 2.0}``: bones
    totalling 34 m, every key point reached). Said, with that ratio and the body's size."""
    scaled = [JOINT_NAMES[c] for c, _ in BONES if JOINT_NAMES[c] not in {*given, *fixed}]
    if not given or not scaled:
        return []
    ref = engine.reference_lengths
    ratio = float(np.median([given[j] / ref[_BONE[j]] for j in given]))
    named = ", ".join(sorted(given)[:4]) + (", ..." if len(given) > 4 else "")
    return [
        f"bone_lengths names {len(given)} of the {len(BONES)} bones ({named}): the other "
        f"{len(scaled)} take the reference skeleton's lengths times {ratio:.3g} (the named "
        f"ones' median ratio to it), a body whose bones total {float(np.sum(lengths)):.3g} m "
        f"(the reference's {float(np.sum(ref)):.3g} m); name every bone (or none: the "
        "networks' estimate from the key points) to keep the character's proportions"
    ]


def _implausible_bones(
    keypoints: dict[str, F64], lengths: F64, implied: float, tolerance: float, scaled: bool
) -> list[str]:
    """The answer's ``scale_warning`` of ``bone_lengths`` the key points' body does not
    have (each bone within :data:`service.schemas.BONE_M`, so not refused): where the body
    they give (``lengths`` ``[20]``) totals outside :data:`BONES_BAND` times the body the
    key points imply (``implied``: the networks' estimate from them, m; unless
    :func:`_scaled_bones` said its size: ``scaled``), and where key
    points lie farther from their nearest key point up the skeleton than the bones between
    them reach at full stretch (beyond ``tolerance``): the answer misses them. Every bone
    at 1 mm was answered 200 with key points 0.66 m off and no word (an API audit,
    2026-12-07); bodies of 2 m bones (40 m in all) reached every key point folded up."""
    told = []
    total = float(np.sum(lengths))
    lo, hi = BONES_BAND
    if not scaled and implied > 0 and not lo <= total / implied <= hi:
        told.append(
            f"bone_lengths: the bones total {total:.3g} m, {total / implied:.3g} times the "
            f"body the key points imply ({implied:.3g} m, the networks' estimate from them; "
            f"real bodies' bones total {REAL_BODIES[0]:g}-{REAL_BODIES[1]:g} times it): "
            "bone lengths are metres, the body's own"
        )
    short = []
    for j, at in keypoints.items():
        chain, k = 0.0, JOINT_INDEX[j]
        while k > 0 and (k == JOINT_INDEX[j] or JOINT_NAMES[k] not in keypoints):
            chain += float(lengths[_BONE[JOINT_NAMES[k]]])
            k = PARENTS[k]
        if k < 0 or k == JOINT_INDEX[j] or JOINT_NAMES[k] not in keypoints:
            continue
        gap = float(np.linalg.norm(at - keypoints[JOINT_NAMES[k]]))
        if gap > chain + tolerance:
            short.append(
                f"{j} lies {gap:.3g} m from {JOINT_NAMES[k]}, the bones between them reach "
                f"{chain:.3g} m"
            )
    if short:
        more = f" (and {len(short) - 3} more)" if len(short) > 3 else ""
        told.append(
            f"bone_lengths: these bones cannot reach the key points: {'; '.join(short[:3])}"
            f"{more}; the answer misses them by as much (keypoints' error)"
        )
    return told


def limb_reaches(keypoints: dict[str, F64]) -> dict[str, float]:
    """How far each base wrist and ankle of ``keypoints`` lies from where its limb starts,
    in pelvis-to-neck distances (:data:`LIMB_REACH`)."""
    torso = float(np.linalg.norm(keypoints["neck"] - keypoints["pelvis"]))
    return {
        j: float(np.linalg.norm(keypoints[j] - keypoints[root])) / torso
        for j, (root, _) in LIMB_REACH.items()
    }


def _stretched_limbs(keypoints: dict[str, F64], world: F64, torso: float) -> list[str]:
    """The answer's ``scale_warning`` of key points no person's limb reaches
    (:data:`LIMB_REACH` times :data:`LIMB_MARGIN`), without ``bone_lengths``: the limb
    the answer drew to reach each (``world``: the answer, ``[21, 3]``)."""
    told = []
    for j, reach in limb_reaches(keypoints).items():
        root, most = LIMB_REACH[j]
        if reach <= LIMB_MARGIN * most:
            continue
        k, drawn = JOINT_INDEX[j], 0.0
        while k not in _TRUNK:  # up to the collar's or the hip's bone, both included
            drawn += float(np.linalg.norm(world[k] - world[PARENTS[k]]))
            k = PARENTS[k]
        limb = "arm (collar to wrist)" if root == "neck" else "leg (hip to ankle)"
        told.append(
            f"{j} lies {reach * torso:.3g} m from the {root}, {reach:.3g} times the pelvis-to-"
            f"neck distance ({torso:.3g} m; no person's reaches farther than {most:g} times): "
            f"the answer's {limb} is {drawn:.3g} m"
        )
    if not told:
        return []
    return [
        f"keypoints: {'; '.join(told)}; check the key points, or give bone_lengths (the "
        "body's own bones: the answer keeps them and says which key points they cannot reach)"
    ]


def _scaled_points(engine: Engine, torso: float) -> list[str]:
    """The answer's ``scale_warning`` of key points of a body outside :data:`TORSO_BAND`:
    completed scaled into it and answered back at their size (centimetres sent as metres:
    a body 100 times larger, its bones totalling hundreds of metres)."""
    band = _out_of_band(engine, torso)
    if band == 1.0:
        return []
    spine = _spine(engine)
    lo, hi = TORSO_BAND
    return [
        f"keypoints: the pelvis and the neck lie {torso:.3g} m apart, {torso / spine:.3g} "
        f"times the reference skeleton's spine ({spine:.3g} m), outside the {lo:g}-{hi:g} "
        f"times the networks know: completed scaled by {1 / band:.3g} into it and answered "
        "back at the key points' size; key points are metres"
    ]


def _out_of_band(engine: Engine, torso: float) -> float:
    """How much the key points are scaled down (below 1: up) to bring a body whose
    pelvis-to-neck distance is ``torso`` into :data:`TORSO_BAND`; 1 inside it."""
    ratio = torso / _spine(engine)
    return ratio / min(max(ratio, TORSO_BAND[0]), TORSO_BAND[1])


def _spine(engine: Engine) -> float:
    """The reference skeleton's pelvis-to-neck length along its spine (m)."""
    return sum(float(engine.reference_lengths[_BONE[j]]) for j in ("spine1", "spine2", "neck"))


def completion_scales(engine: Engine, lengths: F64) -> F64:
    """How much bigger characters ``[..., 20]`` are than what ``engine``'s completion
    networks are fed: networks trained on bodies of every size (``serving.body =
    total_length``) read the size from the key points (1); older ones see the size of
    their nearest training skeleton (``Engine.scales_of``)."""
    if engine.serving.body == "total_length":
        return np.ones(np.shape(lengths)[:-1])
    return engine.scales_of(lengths)


def implied_bodies(engine: Engine, poses: F64) -> F64:
    """The bodies completion level 1 builds from the base key points of ``poses
    [N, 21, 3]`` (pelvis floor point at the origin, as the networks were trained): one
    network run for all, one view (the turn search's critic, :mod:`service.turns`)."""
    idx = engine.base_points
    if engine.serving.body == "total_length":  # the size read from the points: scale 1
        # (x / 1 and x * 1 are x: no bone lengths to work out, ~15 us of a turn search)
        x = poses[:, idx].reshape(len(poses), -1).astype(np.float32)
        net = engine.completion[0]  # (a lone edit's 13 candidates: its bound run, ~5 us less)
        got = net.few((x,)) if len(x) <= BOUND_ITEMS else net(x)
        same: F64 = got.astype(np.float64).reshape(poses.shape)
        return same
    scale = completion_scales(engine, bone_lengths(poses))[:, None, None]
    x = (poses[:, idx] / scale).reshape(len(poses), -1).astype(np.float32)
    out: F64 = engine.completion[0](x).astype(np.float64).reshape(poses.shape) * scale
    return out


def below_the_floor(sets: list[list[str]], given: list[str]) -> InvalidRequest:
    """The 422 of key points without every base point (``sets``: each completion level's
    joints, the first the base): the sets a completion takes, and what the nearest set
    (fewest missing, then fewest points) lacks, in ``missing``, with the sets as
    ``key_point_sets``."""
    nearest = min(sets, key=lambda s: (sum(j not in given for j in s), len(s)))
    missing = [j for j in nearest if j not in given]
    which = f"the {len(nearest)} {'base ' if nearest is sets[0] else ''}points"
    told = []
    for n, s in enumerate(sets):
        before = sets[n - 1] if n else []
        if n and set(before) <= set(s):  # the one before and more
            extra = [j for j in s if j not in before]
            told.append(f"{len(s)} (the {len(before)} and {', '.join(extra)})")
        else:
            told.append(f"{len(s)} points ({', '.join(s)})")
    takes = ", ".join(told[:-1]) + f" or {told[-1]}" if len(told) > 1 else told[0]
    return InvalidRequest(
        f"keypoints: the nearest key point set a completion takes, {which}, lacks "
        f"{', '.join(missing)} (given: {', '.join(given)}); it takes {takes}; any other "
        "joints besides",
        missing=missing,
        key_point_sets=sets,
    )


def complete_level(engine: Engine, level: int, keys: F64) -> F64:
    """Completion level ``level`` (0-based) of key points ``[K, 3]`` (floor-centred,
    the networks' scale): the mean of its answers over the symmetry views the manifest
    asks for (``serving.completion_yaws`` turns about +Y, each also mirrored with
    ``serving.completion_mirror``), each answer taken back to the first view; one
    network run for all views. One view: the network's answer as it is."""
    yaws, mirror = (
        engine.serving.completion_yaws,
        engine.serving.completion_mirror,
    )
    views = symmetry_views(keys, engine.level_mirror[level], yaws, mirror)
    x = views.reshape(len(views), -1).astype(np.float32)
    out = engine.completion[level](x).astype(np.float64).reshape(len(views), NUM_JOINTS, 3)
    return np.asarray(unview(out, MIRROR, yaws, mirror).mean(axis=0))
