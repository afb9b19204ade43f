"""Targeted limb ends stay where the networks put them through the bone pass.

The bone pass (:func:`core.kinematics.bone_pass`) gives a character its own bone lengths
root outwards, each bone keeping the direction the networks gave it. A wrist the networks
put on its target then lands where the character's own arm, laid along those directions,
ends: on a body whose arm is longer or shorter than the one the networks drew, centimetres
away (docs/generalisation.md item 8, docs/generalisation-serving.md item 28).
:func:`keep_ends` puts it back. For each targeted wrist and ankle with no target on its
elbow or knee, its shoulder or hip, or below it:

- the end goes where the networks put it, or, out of the limb's reach, as near as the limb
  reaches on the line from the shoulder (hip) towards it;
- the elbow (knee) is placed anew by the two-bone solution (law of cosines) with the
  character's own lengths, in the plane the bone pass bent the limb in;
- the branch below the end (the foot) moves with it.

The shoulder (hip) and everything above stay as the bone pass left them; bone lengths stay
exact. A limb bent in no plane (straight along the line to the end) is left as it was
(without ``side``, below).

Which side the limb bends to (``side``, ``serving.bend_side``): where the networks drew the
limb nearly straight but the character's bones must bend it (a body whose arm is longer
than the one the networks drew), the plane they bent it in is a few millimetres of their
answer, and its side turns all the way round between two nearly equal edits (an elbow 30
cm away for a target 1 cm away; docs/generalisation-3.md item 52). With ``side`` > 0,
where the networks' bend ``n`` (the middle joint's distance from the line to the end) is
less than ``side`` times the bend ``h`` the character's lengths need, the elbow or knee
turns towards the side they bend to in the training poses for a limb pointing that way
(:data:`PREFER`): the bend plane is that of the networks' bend plus ``(1 - n / (side *
h)) * h`` times the preferred side's part across the line (a vector of length about 1, not
exactly), and goes smoothly from the one to the other as the networks' bend shrinks. ``n``
is measured after the bone pass, which keeps the networks' bone directions and so their
plane.

A targeted elbow (with ``serving.keep_elbows``) is kept the same way one level up: its
chain is collar, shoulder, elbow. Where no target is on its shoulder or collar or below it
(the wrist), the elbow goes back where the networks put it, as near as the collar bone and
the upper arm reach; the shoulder is placed anew by the two-bone solution; the forearm and
hand move with the elbow. An elbow alone has no second bone below its shoulder to take up
the difference in length, so without the collar the bone pass leaves it where the
character's trunk and upper arm end (docs/generalisation-serving.md item 29).

Batched numpy over ``[..., 21, 3]`` with one target set: the reference the compiled kernel
(``core.compiled_limbs.ends_item``, in ``unscale``) is held to in tests.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Final

import numpy as np
import numpy.typing as npt

from core.skeleton import JOINT_INDEX, NUM_JOINTS, PARENTS, SUBTREE

F64 = npt.NDArray[np.float64]

#: The limb ends (``serving.keep_ends``) and the elbows (``serving.keep_elbows``).
ENDS: Final = ("left_wrist", "right_wrist", "left_ankle", "right_ankle")
ELBOWS: Final = ("left_elbow", "right_elbow")
#: The joints kept, each with its chain (top, middle, end): shoulder or hip, elbow or knee,
#: wrist or ankle; collar, shoulder, elbow.
CHAINS: Final[npt.NDArray[np.int64]] = np.asarray(
    [(PARENTS[PARENTS[j]], PARENTS[j], j) for j in (JOINT_INDEX[n] for n in ENDS + ELBOWS)],
    dtype=np.int64,
)


#: Per chain, the joint above its top that may turn it towards its end's goal
#: (``serving.keep_collar``): a wrist's collar; -1 for the others.
COLLARS: Final[npt.NDArray[np.int64]] = np.asarray(
    [PARENTS[int(top)] if int(end) in (JOINT_INDEX[n] for n in ENDS[:2]) else -1
     for top, _, end in CHAINS],
    dtype=np.int64,
)  # fmt: skip


#: Most ``serving.keep_collar``'s turn takes a clavicle from the collars' line, radians (or
#: as far from it as it was, if farther): in TRAIN a clavicle strays from its mean direction
#: in the chest 37 degrees at the 99.9th percentile, 49 at most (``python -m bench.chest``).
CLAVICLE_CONE = float(np.radians(40.0))
#: Each collar's other one (joint index; -1 for the other joints): a clavicle's cone is
#: about the line between them (:func:`_collar_turn`).
OTHER_COLLAR: Final[npt.NDArray[np.int64]] = np.full(NUM_JOINTS, -1, dtype=np.int64)
OTHER_COLLAR[JOINT_INDEX["left_collar"]] = JOINT_INDEX["right_collar"]
OTHER_COLLAR[JOINT_INDEX["right_collar"]] = JOINT_INDEX["left_collar"]


#: The side a left elbow and a left knee bend to for a limb pointing along ``u`` (unit,
#: shoulder or hip to wrist or ankle, canonical frame: +x the body's left, +y up, +z its
#: front): ``u @ W[:3] + W[3]``, whose part across ``u`` is the side (``side`` in
#: :func:`keep_ends`). Least squares of the unit bend side of the training poses' limbs
#: bent 2 cm or more (the right ones mirrored in) on ``[u, 1]``: ``pose-trainer
#: bend-sides`` on the shipped dataset's train split, which these are; it puts 99.98 % of
#: those elbows and 99.99 % of those knees within 90 degrees of their side.
BEND_ELBOW: Final = np.asarray(
    [[-0.445, -0.29, -0.298], [0.352, -0.001, 0.491], [0.093, -0.87, 0.272], [0.596, 0.046, -0.387]]
)
BEND_KNEE: Final = np.asarray(
    [[0.114, 0.182, 0.029], [-0.269, 0.019, -0.885], [-0.238, 0.981, 0.033], [-0.1, 0.021, 0.086]]
)


def mirrored_side(w: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """The right limb's table of a left limb's ``w [4, 3]`` (x negated in and out)."""
    flip = np.asarray([-1.0, 1.0, 1.0])
    return np.asarray(w * np.concatenate([flip, [1.0]])[:, None] * flip[None, :], dtype=np.float64)


def across(v: F64, u: F64) -> F64:
    """The part of ``v [..., 3]`` across the unit line ``u [..., 3]``."""
    out: F64 = v - np.sum(v * u, axis=-1)[..., None] * u
    return out


def preferred_side(table: F64, u: F64) -> F64:
    """The side ``[..., 3]`` a limb along the unit ``u [..., 3]`` bends to by ``table [4, 3]``
    (:data:`BEND_ELBOW`, ...): ``u @ table[:3] + table[3]`` across ``u``, summed in the
    compiled kernel's order (``core.compiled_limbs.ends_item``), bit for bit."""
    side = u[..., 0:1] * table[0] + u[..., 1:2] * table[1] + u[..., 2:3] * table[2]
    return across(side + table[3], u)


#: Per chain (rows of :data:`CHAINS`), its side table ``[C, 4, 3]``; zeros (no side) for the
#: elbows' own chains.
PREFER: Final[npt.NDArray[np.float64]] = np.stack(
    [BEND_ELBOW, mirrored_side(BEND_ELBOW), BEND_KNEE, mirrored_side(BEND_KNEE),
     np.zeros((4, 3)), np.zeros((4, 3))]
)  # fmt: skip


#: Per chain, the joints below its end ``[4, 21]``.
_ENDS = CHAINS[:, 2]
BELOW: Final[npt.NDArray[np.bool_]] = SUBTREE[_ENDS] & ~np.eye(NUM_JOINTS, dtype=np.bool_)[_ENDS]
#: Below this (m) a length counts as none: the end on its shoulder (hip), a limb bent in no plane.
TINY = 1e-12


def active(ends: bool = True, elbows: bool = False) -> npt.NDArray[np.bool_]:
    """Which chains (rows of :data:`CHAINS`) are kept ``[C]``: the limb ends with ``ends``
    (``serving.keep_ends``), the elbows with ``elbows`` (``serving.keep_elbows``)."""
    return np.asarray([ends] * len(ENDS) + [elbows] * len(ELBOWS), dtype=np.bool_)


def kept_chains(targets: Iterable[int], chains: npt.NDArray[np.bool_] | None = None) -> list[int]:
    """The chains (rows of :data:`CHAINS`; of those ``chains`` marks, default the limb ends)
    whose end :func:`keep_ends` keeps for a target set: the end targeted; its middle
    joint, its top joint and the joints below it not."""
    on = active() if chains is None else chains
    targeted = np.zeros(NUM_JOINTS, dtype=bool)
    targeted[list(targets)] = True
    return [
        c
        for c, (top, mid, end) in enumerate(CHAINS.tolist())
        if on[c]
        and targeted[end]
        and not targeted[mid]
        and not targeted[top]
        and not targeted[BELOW[c]].any()
    ]


#: The largest ``soft`` distance a request may ask for (m; the API's ``soft_ik``): about a
#: fifth of an adult arm's reach; eased over more, a limb never gets near straight.
SOFT_IK_MAX: Final[float] = 0.1
#: ... and at most this share of the limb's own reach (a doll's arm of 10 cm asked to ease
#: over 10 cm would fold: :func:`soft_reach`).
SOFT_IK_LIMB: Final[float] = 0.25


def soft_reach(d: F64, reach: F64, soft: npt.ArrayLike) -> F64:
    """How far a limb of full ``reach`` (m) reaches towards a goal ``d`` (m) away when it
    eases into full stretch over ``soft`` (m; 0: none) ("soft IK"): ``d`` up to ``reach -
    soft``, then ``reach - soft exp(-(d - reach + soft) / soft)``, continuous with its first
    derivative and never quite ``reach``, so that the elbow or knee no longer swings from
    bent to straight as the goal crosses the limb's reach (its distance off the line grows
    as the square root of how far inside the reach the end is); the end falls short of
    the goal by at most ``soft / e`` where the goal lies at ``reach``. ``soft`` is taken
    at most :data:`SOFT_IK_LIMB` times ``reach`` (larger, the eased distance went to zero
    or below, and the limb folded onto its top). Per element."""
    d = np.asarray(d, dtype=np.float64)
    asked = np.broadcast_to(np.asarray(soft, dtype=np.float64), d.shape)
    k = np.minimum(asked, SOFT_IK_LIMB * np.asarray(reach, dtype=np.float64))
    knee = reach - k
    over = (k > 0.0) & (d > knee)
    if not over.any():
        return d
    safe = np.where(over, k, 1.0)
    out: F64 = np.where(over, reach - safe * np.exp(-(d - knee) / safe), d)
    return out


def keep_ends(
    pose: F64,
    network: F64,
    targets: Iterable[int],
    chains: npt.NDArray[np.bool_] | None = None,
    ease: float = 0.0,
    collar: bool = False,
    side: float = 0.0,
    soft: npt.ArrayLike = 0.0,
) -> F64:
    """``pose [..., 21, 3]`` (after the bone pass: the character's lengths) with each kept
    chain's end (of those ``chains`` marks, default the limb ends) where ``network`` (the
    same poses before the bone pass) has it, as near as the limb reaches; see the module.
    ``ease`` (m, > 0): an end the bone pass left ``g`` < ``ease`` from the network's goes
    only ``g / ease`` of the way back (a millimetre of the networks' ankle no longer bends
    a straight knee; continuous in ``g``). ``collar``: a kept wrist whose goal lies beyond
    the arm's reach from its shoulder first turns the shoulder about its collar towards the
    goal, as little as brings it within reach (all the way where nothing does), the arm
    moving with it. ``side`` (0-1): a limb the networks bent less than ``side`` times what the
    character's lengths need bends towards :data:`PREFER` (see the module). ``soft`` (m,
    scalar or ``[...]``): the limb eases into full stretch over that distance
    (:func:`soft_reach`). A new array."""
    out = np.array(pose, dtype=np.float64, copy=True)
    net = np.asarray(network, dtype=np.float64)
    targets = list(targets)
    for c in kept_chains(targets, chains):
        top, mid, end = CHAINS[c].tolist()
        s, e0, w0 = out[..., top, :], out[..., mid, :], out[..., end, :]
        a = np.sqrt(np.sum((e0 - s) ** 2, axis=-1))
        b = np.sqrt(np.sum((w0 - e0) ** 2, axis=-1))
        goal = net[..., end, :]
        if ease > 0.0:
            gap = np.sqrt(np.sum((net[..., end, :] - w0) ** 2, axis=-1))
            part = w0 + (gap / ease)[..., None] * (net[..., end, :] - w0)
            goal = np.where((gap < ease)[..., None], part, goal)
        k = int(COLLARS[c])
        if collar and k >= 0 and k not in targets:
            other = out[..., OTHER_COLLAR[k], :]
            shift = _collar_turn(out[..., k, :], s, goal, a + b, out[..., k, :] - other)
            for j in (top, mid, end, *np.flatnonzero(BELOW[c]).tolist()):
                out[..., j, :] = out[..., j, :] + shift
            s, e0, w0 = out[..., top, :], out[..., mid, :], out[..., end, :]
        line = goal - s
        d0 = np.sqrt(np.sum(line**2, axis=-1))
        u = line / np.where(d0 > TINY, d0, 1.0)[..., None]
        d = np.minimum(np.maximum(soft_reach(d0, a + b, soft), np.abs(a - b)), a + b)
        bend = across(e0 - s, u)
        reach = (d0 > TINY) & (a > TINY)
        cos = np.clip((a * a + d * d - b * b) / np.where(reach, 2.0 * a * d, 1.0), -1.0, 1.0)
        sin = np.sqrt(np.maximum(0.0, 1.0 - cos * cos))
        if side > 0.0:  # towards PREFER where the networks' bend is short of what is needed
            need = a * sin
            nb = np.sqrt(np.sum(bend**2, axis=-1))
            w = np.where(need > TINY, 1.0 - nb / np.where(need > TINY, side * need, 1.0), 0.0)
            pref = preferred_side(PREFER[c], u)
            bend = bend + (np.maximum(w, 0.0) * need)[..., None] * pref
        nb = np.sqrt(np.sum(bend**2, axis=-1))
        v = bend / np.where(nb > TINY, nb, 1.0)[..., None]
        ok = reach & (nb > TINY)
        elbow = s + a[..., None] * (cos[..., None] * u + sin[..., None] * v)
        wrist = s + d[..., None] * u
        shift = np.where(ok[..., None], wrist - w0, 0.0)
        out[..., mid, :] = np.where(ok[..., None], elbow, e0)
        out[..., end, :] = w0 + shift
        out[..., BELOW[c], :] += shift[..., None, :]
    return out


def _collar_turn(collar: F64, shoulder: F64, goal: F64, reach: F64, across: F64) -> F64:
    """How far ``shoulder [..., 3]`` moves when it turns about ``collar`` (on its sphere)
    just far enough towards ``goal`` that the goal is ``reach`` from it (0 where it already
    is within reach; towards the goal all the way where no turn brings it within reach),
    the clavicle kept within :data:`CLAVICLE_CONE` of ``across`` (from the other
    collar; or as far from it as it was, if farther): turned freely, it folded soft
    answers' shoulders below 80 % of their width in 9 of 240 far wrist reaches more
    (87 against 78: ``python -m bench.chest``)."""
    p = shoulder - collar
    cl = np.sqrt(np.sum(p**2, axis=-1))
    w = goal - collar
    d = goal - shoulder
    far = (np.sum(d**2, axis=-1) > reach * reach) & (cl > TINY)
    pu = p / np.where(cl > TINY, cl, 1.0)[..., None]
    wp = np.sum(w * pu, axis=-1)
    q = w - wp[..., None] * pu
    wq = np.sqrt(np.sum(q**2, axis=-1))
    ok = far & (wq > TINY)
    qu = q / np.where(wq > TINY, wq, 1.0)[..., None]
    rho = np.sqrt(wp * wp + wq * wq)
    kk = (np.sum(w**2, axis=-1) + cl * cl - reach * reach) / np.where(ok, 2.0 * cl, 1.0)
    phi = np.arctan2(wq, wp)
    th = np.where(kk < rho, phi - np.arccos(np.minimum(kk / np.where(ok, rho, 1.0), 1.0)), phi)
    th = np.maximum(th, 0.0)
    na = np.sqrt(np.sum(across**2, axis=-1))
    m = across / np.where(na > TINY, na, 1.0)[..., None]
    ca, cb = np.sum(m * pu, axis=-1), np.sum(m * qu, axis=-1)
    lim = np.minimum(np.cos(CLAVICLE_CONE), ca)  # cos th ca + sin th cb >= lim
    r = np.sqrt(ca * ca + cb * cb)
    cone = (na > TINY) & (r > TINY)
    top = np.arctan2(cb, ca) + np.arccos(np.clip(lim / np.where(cone, r, 1.0), -1.0, 1.0))
    th = np.where(cone, np.minimum(th, top), th)
    moved = collar + cl[..., None] * (np.cos(th)[..., None] * pu + np.sin(th)[..., None] * qu)
    return np.where(ok[..., None], moved - shoulder, 0.0)
