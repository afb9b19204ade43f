"""Targeted limb ends kept through the bone pass (core.ends) on real poses, and its compiled
kernel (core.compiled_limbs.ends_item) against it."""

from __future__ import annotations

import numpy as np
import pytest

from core import compiled
from core.compiled_limbs import ends_item
from core.ends import (
    BELOW,
    CHAINS,
    CLAVICLE_CONE,
    PREFER,
    active,
    keep_ends,
    kept_chains,
    soft_reach,
)
from core.skeleton import JOINT_INDEX, bone_lengths
from tests.conftest import PosePairs

J = JOINT_INDEX
L_ARM = (J["left_shoulder"], J["left_elbow"], J["left_wrist"])
R_LEG = (J["right_hip"], J["right_knee"], J["right_ankle"])
L_UPPER = (J["left_collar"], J["left_shoulder"], J["left_elbow"])
ELBOWS = active(ends=True, elbows=True)


def _idx(*names: str) -> list[int]:
    return [J[n] for n in names]


def test_chains_kept_only_for_free_limb_ends() -> None:
    def kept(*names: str, chains: np.ndarray | None = None) -> set[int]:
        return {int(CHAINS[c, 2]) for c in kept_chains(_idx(*names), chains)}

    assert tuple(CHAINS[0]) == L_ARM and tuple(CHAINS[3]) == R_LEG
    assert tuple(CHAINS[4]) == L_UPPER and BELOW[4].sum() == 1 and BELOW[4, J["left_wrist"]]
    # elbows only where asked for, and only with no target on the wrist, shoulder or collar
    assert kept("left_elbow", "right_elbow") == set()
    assert kept("left_elbow", "right_elbow", chains=ELBOWS) == {J["left_elbow"], J["right_elbow"]}
    assert kept("left_elbow", chains=active(ends=False, elbows=True)) == {J["left_elbow"]}
    assert kept("left_wrist", chains=active(ends=False, elbows=True)) == set()
    for other in ("left_wrist", "left_shoulder", "left_collar"):
        assert kept("left_elbow", other, chains=ELBOWS) <= {J["left_wrist"]}
    assert kept("left_wrist", "right_ankle", "head") == {J["left_wrist"], J["right_ankle"]}
    # a target on the elbow, the shoulder or below the ankle (the foot) leaves the chain be
    assert kept("left_wrist", "left_elbow") == set()
    assert kept("left_wrist", "left_shoulder") == set()
    assert kept("left_ankle", "left_foot") == set()
    assert kept("left_knee", "pelvis", "spine2") == set()
    assert BELOW[3, J["right_foot"]] and BELOW[3].sum() == 1 and not BELOW[0].any()


@pytest.fixture(scope="module")
def limbs(real_poses: PosePairs) -> tuple[np.ndarray, np.ndarray]:
    """Stand-in network answers (goals on bodies with other limb lengths) and the same
    answers after the bone pass onto their starts' lengths."""
    start = real_poses.poses[real_poses.starts]
    goal = real_poses.poses[real_poses.goals]
    rng = np.random.default_rng(3)
    scale = rng.uniform(0.8, 1.25, (len(goal), 20))
    lens = np.ascontiguousarray(bone_lengths(start))
    network = compiled.bone_pass_batch(
        np.ascontiguousarray(goal), np.ascontiguousarray(lens * scale), goal, True
    )
    return network, compiled.bone_pass_batch(network, lens, start, True)


def test_ends_go_back_where_the_network_put_them(limbs: tuple[np.ndarray, np.ndarray]) -> None:
    network, passed = limbs
    out = keep_ends(passed, network, _idx("left_wrist", "right_ankle"))
    # bone lengths stay the character's
    assert np.abs(bone_lengths(out) / bone_lengths(passed) - 1).max() < 1e-12
    moved = [*L_ARM[1:], *R_LEG[1:], J["right_foot"]]
    rest = np.setdiff1d(np.arange(21), moved)
    assert np.array_equal(out[:, rest], passed[:, rest])  # the top and the rest stay
    for top, mid, end in (L_ARM, R_LEG):
        reach = np.linalg.norm(passed[:, mid] - passed[:, top], axis=-1) + np.linalg.norm(
            passed[:, end] - passed[:, mid], axis=-1
        )
        far = np.linalg.norm(network[:, end] - passed[:, top], axis=-1)
        inside = far < reach
        assert inside.mean() > 0.5 and (~inside).any()
        # within the limb's reach the end is the network's; beyond, on the line towards it
        assert np.abs(out[inside, end] - network[inside, end]).max() < 1e-9
        line = network[~inside, end] - passed[~inside, top]
        got = out[~inside, end] - passed[~inside, top]
        unit = line / np.linalg.norm(line, axis=-1, keepdims=True)
        assert np.abs(got - unit * reach[~inside, None]).max() < 1e-9
        # the bone pass moved the end; keeping it brings it nearer the network's
        before = np.linalg.norm(passed[:, end] - network[:, end], axis=-1)
        after = np.linalg.norm(out[:, end] - network[:, end], axis=-1)
        assert np.all(after <= before + 1e-12) and before.mean() > 0.01
        # the elbow (knee) stays in the plane the bone pass bent the limb in
        normal = np.cross(passed[:, mid] - passed[:, top], network[:, end] - passed[:, top])
        assert np.abs(np.sum((out[:, mid] - passed[:, top]) * normal, axis=-1)).max() < 1e-9
    # the foot moves with the ankle, as it hung below it
    foot, ankle = J["right_foot"], J["right_ankle"]
    np.testing.assert_allclose(out[:, foot] - out[:, ankle], passed[:, foot] - passed[:, ankle])


def test_compiled_ends_match_numpy(limbs: tuple[np.ndarray, np.ndarray]) -> None:
    network, passed = limbs
    flags, vecs = np.empty(21, np.int64), np.empty((5, 3))
    for names in [("left_wrist",), ("left_wrist", "right_wrist", "left_ankle", "right_ankle"),
                  ("right_ankle", "right_foot"), ("head", "left_elbow")]:  # fmt: skip
        targets = _idx(*names)
        tidx = np.asarray(targets + [0] * (5 - len(targets)), dtype=np.int64)
        ref = keep_ends(passed, network, targets)
        got = passed.copy()
        for b in range(len(got)):
            ends_item(got[b], network[b], tidx, len(targets), active(), flags, vecs, 0.0, False,
                      0.0, 0.0)  # fmt: skip
        assert np.array_equal(got, ref)  # bit for bit
    for names in [("left_elbow",), ("left_elbow", "right_elbow", "left_ankle"),
                  ("right_elbow", "right_wrist", "head")]:  # fmt: skip
        targets = _idx(*names)
        tidx = np.asarray(targets + [0] * (5 - len(targets)), dtype=np.int64)
        ref = keep_ends(passed, network, targets, ELBOWS)
        got = passed.copy()
        for b in range(len(got)):
            ends_item(got[b], network[b], tidx, len(targets), ELBOWS, flags, vecs, 0.0, False, 0.0,
                      0.0)  # fmt: skip
        assert np.array_equal(got, ref)  # bit for bit
    # degenerate: the network's wrist on the shoulder; an arm straight along the line to it
    bad, net = passed[:2].copy(), network[:2].copy()
    top, mid, end = L_ARM
    net[0, end] = bad[0, top]
    bad[1, mid] = bad[1, top] + 0.3 * (net[1, end] - bad[1, top])
    ref = keep_ends(bad, net, [end])
    got = bad.copy()
    for b in range(2):
        ends_item(got[b], net[b], np.asarray([end]), 1, active(), flags, vecs, 0.0, False, 0.0, 0.0)
    assert np.all(np.isfinite(got)) and np.array_equal(got, ref)
    assert np.array_equal(got, bad)  # nothing to place by: left as the bone pass had it


def test_a_limb_drawn_too_straight_bends_to_the_preferred_side(
    limbs: tuple[np.ndarray, np.ndarray],
) -> None:
    """``side``: an arm or leg the networks drew nearly straight, which the character's
    lengths must bend, bends out, down and back (elbows) or forward (knees), and its
    elbow no longer turns round the line to the end for a millimetre of the networks'
    answer; a limb the networks bent enough keeps their plane; the compiled kernel agrees."""
    network, passed = limbs
    targets = _idx("left_wrist", "right_ankle")
    plain = keep_ends(passed, network, targets)
    sided = keep_ends(passed, network, targets, side=0.5)
    assert np.abs(bone_lengths(sided) / bone_lengths(passed) - 1).max() < 1e-12
    np.testing.assert_allclose(sided[:, L_ARM[2]], plain[:, L_ARM[2]], atol=1e-12)  # same end

    def bend(pose: np.ndarray, top: int, mid: int, end: int) -> np.ndarray:
        """The middle joint's distance off the line from the top to where the end goes."""
        u = network[:, end] - pose[:, top]
        u /= np.linalg.norm(u, axis=-1, keepdims=True)
        v = pose[:, mid] - pose[:, top]
        return np.linalg.norm(v - np.sum(v * u, axis=-1, keepdims=True) * u, axis=-1)

    for top, mid, end in (L_ARM, R_LEG):
        # the networks' bend (the bone pass keeps their plane) against what is needed
        enough = bend(passed, top, mid, end) >= 0.5 * bend(plain, top, mid, end)
        assert enough.mean() > 0.5 and (~enough).sum() >= 3
        np.testing.assert_allclose(sided[enough, mid], plain[enough, mid], atol=1e-12)
        assert np.abs(sided[~enough, mid] - plain[~enough, mid]).max() > 0.01
    # the networks' arm straight but for 1 mm, its side turned round: the answer stays put
    top, mid, end = L_ARM
    base = passed[:1].copy()
    u = network[0, end] - base[0, top]
    u /= np.linalg.norm(u)
    side = np.cross(u, [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    answers = []
    for sign in (1.0, -1.0):
        bent = base.copy()
        along = np.dot(bent[0, mid] - bent[0, top], u)
        bent[0, mid] = bent[0, top] + along * u + sign * 0.001 * side
        answers.append([keep_ends(bent, network[:1], [end], side=s)[0, mid] for s in (0.0, 0.5)])
    (plain_a, sided_a), (plain_b, sided_b) = answers
    assert np.linalg.norm(plain_a - plain_b) > 0.1  # the plane of 1 mm: across the arm
    assert np.linalg.norm(sided_a - sided_b) < 0.01
    # ... towards the side the training poses' elbows bend to for an arm pointing so
    off = sided_a - base[0, top] - np.dot(sided_a - base[0, top], u) * u
    pref = u @ PREFER[0, :3] + PREFER[0, 3]
    pref -= np.dot(pref, u) * u
    assert np.dot(off, pref) > 0.9 * np.linalg.norm(off) * np.linalg.norm(pref)
    flags, vecs = np.empty(21, np.int64), np.empty((5, 3))
    for names, chains in ((("left_wrist", "right_ankle"), active()),
                          (("left_elbow", "right_wrist", "left_ankle"), ELBOWS)):  # fmt: skip
        idx = _idx(*names)
        tidx = np.asarray(idx + [0] * (5 - len(idx)), dtype=np.int64)
        ref = keep_ends(passed, network, idx, chains, side=0.5)
        got = passed.copy()
        for b in range(len(got)):
            ends_item(got[b], network[b], tidx, len(idx), chains, flags, vecs, 0.0, False, 0.5, 0.0)
        assert np.array_equal(got, ref)  # bit for bit


def test_elbows_go_back_where_the_network_put_them(limbs: tuple[np.ndarray, np.ndarray]) -> None:
    """With the elbows kept (``serving.keep_elbows``): a lone targeted elbow goes back where
    the network put it, as near as the collar bone and the upper arm reach; the shoulder
    moves in the plane they were bent in; the forearm and hand move with the elbow."""
    network, passed = limbs
    out = keep_ends(passed, network, _idx("left_elbow"), ELBOWS)
    assert np.array_equal(keep_ends(passed, network, _idx("left_elbow")), passed)  # not asked
    assert np.abs(bone_lengths(out) / bone_lengths(passed) - 1).max() < 1e-12
    top, mid, end = L_UPPER
    wrist = J["left_wrist"]
    rest = np.setdiff1d(np.arange(21), [mid, end, wrist])
    assert np.array_equal(out[:, rest], passed[:, rest])  # the collar and the rest stay
    reach = np.linalg.norm(passed[:, mid] - passed[:, top], axis=-1) + np.linalg.norm(
        passed[:, end] - passed[:, mid], axis=-1
    )
    inside = np.linalg.norm(network[:, end] - passed[:, top], axis=-1) < reach
    assert inside.mean() > 0.5
    assert np.abs(out[inside, end] - network[inside, end]).max() < 1e-9
    before = np.linalg.norm(passed[:, end] - network[:, end], axis=-1)
    after = np.linalg.norm(out[:, end] - network[:, end], axis=-1)
    assert np.all(after <= before + 1e-12) and before.mean() > 0.01
    normal = np.cross(passed[:, mid] - passed[:, top], network[:, end] - passed[:, top])
    assert np.abs(np.sum((out[:, mid] - passed[:, top]) * normal, axis=-1)).max() < 1e-9
    # the forearm keeps its direction: the wrist moves with the elbow
    np.testing.assert_allclose(out[:, wrist] - out[:, end], passed[:, wrist] - passed[:, end])


def test_eased_ends_go_back_in_proportion_and_match_compiled(
    limbs: tuple[np.ndarray, np.ndarray],
) -> None:
    """``ease``: an end the bone pass left ``g`` < ``ease`` from the network's goes back
    ``g / ease`` of the way (within the limb's reach), beyond ``ease`` all the way, as
    without it, bit for bit; the compiled kernel agrees."""
    network, passed = limbs
    targets = _idx("left_wrist", "right_ankle", "right_elbow")
    ease = 0.02
    plain, eased = (keep_ends(passed, network, targets, ELBOWS, e) for e in (0.0, ease))
    flags, vecs = np.empty(21, np.int64), np.empty((5, 3))
    tidx = np.asarray([*targets, 0, 0], dtype=np.int64)
    got = passed.copy()
    for b in range(len(got)):
        ends_item(got[b], network[b], tidx, len(targets), ELBOWS, flags, vecs, ease, False, 0.0,
                  0.0)  # fmt: skip
    assert np.abs(got - eased).max() < 1e-12
    assert np.abs(bone_lengths(eased) / bone_lengths(passed) - 1).max() < 1e-12
    for top, mid, end in (L_ARM, R_LEG):
        gap = np.linalg.norm(network[:, end] - passed[:, end], axis=-1)
        far = gap >= ease
        assert far.any() and (~far).any()
        assert np.array_equal(eased[far][:, end], plain[far][:, end])
        reach = np.linalg.norm(passed[:, mid] - passed[:, top], axis=-1) + np.linalg.norm(
            passed[:, end] - passed[:, mid], axis=-1
        )
        near = ~far & (np.linalg.norm(network[:, end] - passed[:, top], axis=-1) < reach)
        want = passed[near, end] + (gap[near] / ease)[:, None] * (
            network[near, end] - passed[near, end]
        )
        assert np.abs(eased[near, end] - want).max() < 1e-9


def test_a_wrist_out_of_reach_turns_its_shoulder_about_the_collar(
    limbs: tuple[np.ndarray, np.ndarray],
) -> None:
    """``collar``: a kept wrist whose goal lies beyond the arm's reach from its shoulder
    turns the shoulder on its collar's sphere towards it, as little as brings it within
    reach; within reach nothing changes; lengths hold; the compiled kernel agrees."""
    network, passed = limbs
    shoulder, elbow, wrist = L_ARM
    collar = J["left_collar"]
    net = network.copy()
    rng = np.random.default_rng(5)
    # push half of the goals out of the arm's reach: 5-30 cm further along the line
    far = rng.random(len(net)) < 0.5
    line = net[:, wrist] - passed[:, shoulder]
    net[far, wrist] += (
        line[far]
        / np.linalg.norm(line[far], axis=-1, keepdims=True)
        * (rng.uniform(0.05, 0.3, (far.sum(), 1)))
    )
    targets = _idx("left_wrist")
    plain, turned = (keep_ends(passed, net, targets, collar=k) for k in (False, True))
    reach = np.linalg.norm(passed[:, elbow] - passed[:, shoulder], axis=-1) + np.linalg.norm(
        passed[:, wrist] - passed[:, elbow], axis=-1
    )
    out = np.linalg.norm(net[:, wrist] - passed[:, shoulder], axis=-1) > reach
    assert out.sum() > 0.2 * len(out) and (~out).any()
    assert np.array_equal(turned[~out], plain[~out])  # within reach: as without it
    assert np.abs(bone_lengths(turned) / bone_lengths(passed) - 1).max() < 1e-12
    rest = np.setdiff1d(np.arange(21), [shoulder, elbow, wrist])
    assert np.array_equal(turned[:, rest], passed[:, rest])  # the collar and the rest stay
    miss = (np.linalg.norm(o[:, wrist] - net[:, wrist], axis=-1) for o in (plain, turned))
    before, after = miss
    assert np.all(after[out] <= before[out] + 1e-12)
    assert (after[out] < before[out]).mean() > 0.9 and after[out].mean() < 0.8 * before[out].mean()
    # brought within reach by the turn: the wrist on its goal; else the shoulder turned all
    # the way, onto the line from the collar to the goal, or as far as the clavicle's cone
    # about the collars' line lets it (core.ends.CLAVICLE_CONE, or the start's angle)
    on = after[out] < 1e-9
    assert 0.2 < on.mean() < 1.0
    rest_out = np.flatnonzero(out)[~on]
    to_goal = net[rest_out, wrist] - passed[rest_out, collar]
    to_shoulder = turned[rest_out, shoulder] - passed[rest_out, collar]
    unit = lambda v: v / np.linalg.norm(v, axis=-1, keepdims=True)  # noqa: E731
    line = np.linalg.norm(np.cross(unit(to_goal), unit(to_shoulder)), axis=-1) < 1e-9
    across = unit(passed[rest_out, collar] - passed[rest_out, J["right_collar"]])
    was = unit(passed[rest_out, shoulder] - passed[rest_out, collar])
    limit = np.maximum(CLAVICLE_CONE, np.arccos(np.sum(was * across, axis=-1)))
    edge = np.abs(np.arccos(np.sum(unit(to_shoulder) * across, axis=-1)) - limit) < 1e-9
    assert np.all(line | edge) and edge.any()  # (here every one stops at the cone)
    assert np.all(np.sum(to_goal * to_shoulder, axis=-1) > 0)
    flags, vecs = np.empty(21, np.int64), np.empty((5, 3))
    got = passed.copy()
    for b in range(len(got)):
        ends_item(
            got[b], net[b], np.asarray(targets), 1, active(), flags, vecs, 0.0, True, 0.0, 0.0
        )
    assert np.abs(got - turned).max() < 1e-12
    assert collar not in targets


def test_soft_reach_eases_a_limb_into_full_stretch() -> None:
    """Soft IK: the goal's distance as it is up to ``reach - soft``; beyond, a curve that
    meets it with the same slope, rises towards ``reach`` without reaching it, and falls
    short of a goal at full reach by ``soft / e``; ``soft`` 0 changes nothing."""
    reach, k = 0.6, 0.01
    d = np.linspace(0.5, 0.7, 20001)
    out = soft_reach(d, reach, k)
    below = d <= reach - k
    assert np.array_equal(out[below], d[below])
    assert np.all(out < reach) and np.all(np.diff(out) > 0.0)
    slope = np.diff(out) / np.diff(d)
    assert slope.max() <= 1.0 + 1e-9 and abs(slope[np.searchsorted(d, reach - k)] - 1.0) < 1e-3
    assert soft_reach(np.asarray(reach), reach, k) == pytest.approx(reach - k / np.e, abs=1e-15)
    assert np.array_equal(soft_reach(d, reach, 0.0), d)
    # per element: a batch with soft 0 and soft k answers each as alone
    both = soft_reach(np.stack([d, d]), reach, np.asarray([[0.0], [k]]))
    assert np.array_equal(both[0], d) and np.array_equal(both[1], out)


def test_soft_ik_bends_a_limb_near_full_stretch_and_matches_the_kernel(
    limbs: tuple[np.ndarray, np.ndarray],
) -> None:
    """With ``soft``, an arm whose goal lies near or past its reach keeps a bend (its
    wrist a little short), one well inside it is placed as without; the compiled kernel
    gives the numpy reference's answers (to the last bits of ``exp``)."""
    network, passed = limbs
    wrist = _idx("left_wrist")
    top, mid, end = (JOINT_INDEX[n] for n in ("left_shoulder", "left_elbow", "left_wrist"))
    plain = keep_ends(passed, network, wrist)
    soft = keep_ends(passed, network, wrist, soft=0.02)
    a = np.linalg.norm(passed[:, mid] - passed[:, top], axis=-1)
    b = np.linalg.norm(passed[:, end] - passed[:, mid], axis=-1)
    d = np.linalg.norm(network[:, end] - plain[:, top], axis=-1)
    inside, near = d < a + b - 0.05, d > a + b - 0.005
    assert inside.any() and near.any()
    assert np.array_equal(soft[inside], plain[inside])
    short = np.linalg.norm(soft[near, end] - network[near, end], axis=-1)
    assert np.all(short > np.linalg.norm(plain[near, end] - network[near, end], axis=-1))
    extent = np.linalg.norm(soft[near, end] - soft[near, top], axis=-1)
    assert np.all(extent < (a + b)[near])  # never quite straight
    flags, vecs = np.empty(21, np.int64), np.empty((5, 3))
    got = passed.copy()
    tidx = np.asarray(wrist, dtype=np.int64)
    for i in range(len(got)):
        ends_item(got[i], network[i], tidx, 1, active(), flags, vecs, 0.0, False, 0.0, 0.02)
    assert np.abs(got - soft).max() < 1e-12
