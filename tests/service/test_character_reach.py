"""A character's targets and pins are met on its own skeleton as the canonical answer met them.

Five studios' BVH files (tests/character_files.py), each edited at its test frame: the head,
the neck or the pelvis moved with both ankles pinned. The canonical solve meets every one of
these within its tolerance; laying the answer back onto the character's own joints
(``core.retarget``) used to lose some of it (a neck 14-60 mm short, a pin broken by up to
11 mm, in soft reach a pelvis 3-6 cm from where the answer put it); ``core.reach`` polishes
what is left on the character itself.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.bvh import parse_bvh
from core.bvh_write import pose_of, skeleton_of
from core.characters_maps import resolve_map
from core.retarget import canonical_points
from core.skeleton import JOINT_INDEX, PARENTS
from core.units import UNITS
from service.bvh_models import BVHSolveRequest
from service.character_bvh import bvh_answer, character_from_bvh, read_request_bvh
from service.characters import character_problem, solve_prepared
from service.engine import Engine
from tests.character_files import FILES

TOL = 1e-3  # m, the default tolerance
PINS = ["left_ankle", "right_ankle"]
#: (canonical joint, direction, move as a fraction of the pelvis-head distance)
EDITS = [("head", "fwd", 0.10), ("head", "side", 0.10), ("neck", "fwd", 0.10),
         ("neck", "side", 0.10), ("pelvis", "up", -0.15)]  # fmt: skip


def _body(text: str, name: str, joint: str, way: str, amount: float, reach: str) -> dict[str, Any]:
    """A /v1/bvh/solve body: ``joint`` moved ``amount`` of the pelvis-head distance along the
    file's up axis (``up``) or one of the two across it, both ankles pinned."""
    _, _, units, frame = FILES[name]
    bvh = parse_bvh(text)
    skel = skeleton_of(bvh)
    jmap = resolve_map(skel)
    pts = canonical_points(skel, pose_of(bvh, frame), jmap)
    trunk = pts[JOINT_INDEX["head"]] - pts[JOINT_INDEX["pelvis"]]
    up = int(np.argmax(np.abs(trunk)))
    across = [i for i in range(3) if i != up]
    axis = {"up": up, "fwd": across[0], "side": across[1]}[way]
    goal = pts[JOINT_INDEX[joint]].copy()
    goal[axis] += amount * float(np.linalg.norm(trunk)) * (np.sign(trunk[up]) if way == "up" else 1)
    label = jmap.describe()
    body: dict[str, Any] = {
        "bvh": text,
        "frame": frame,
        "targets": [{"joint": label[joint], "position": goal.tolist()}],
        "pins": [label[p] for p in PINS],
        "options": {"reach": reach},
    }
    if units is not None:
        body["units"] = units
    return body


def _summary(rows: list[tuple[str, str, str, float, float]], what: str) -> None:
    """Prints the worst misses in mm (run with -s): the docs quote these."""
    worst = sorted(rows, key=lambda r: -r[3])[:2]
    print(f"\n{what}: worst pin {max(r[4] for r in rows) * 1e3:.3f} mm; worst targets (mm):",
          [(n, j, w, round(t * 1e3, 2)) for n, j, w, t, _ in worst])  # fmt: skip


def test_exact_reach_meets_trunk_targets_and_holds_pins(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    """Every pin within 1 mm on every edit (the report measures the file as written); every
    target met but at most one of the 25 edits, and a miss says so."""
    rows = []
    for name, path in bvh_files.items():
        text = path.read_text()
        for joint, way, amount in EDITS:
            r = client.post("/v1/bvh/solve", json=_body(text, name, joint, way, amount, "exact"))
            assert r.status_code == 200, r.text
            out = r.json()
            (target,) = out["targets"]
            assert target["reached"] is (target["error"] <= TOL)
            pin = max(p["error"] for p in out["pins"])
            rows.append((name, joint, way, float(target["error"]), float(pin)))
    _summary(rows, "exact")
    assert max(r[4] for r in rows) <= TOL
    missed = [r for r in rows if r[3] > TOL]
    assert len(missed) <= 1, missed


def test_soft_reach_lays_targets_where_the_canonical_answer_put_them(
    engine: Engine, bvh_files: dict[str, Path]
) -> None:
    """In soft reach the character's targeted joint ends as near its target as the
    canonical answer's did (within the tolerance), and its pins are held."""
    rows = []
    for name, path in bvh_files.items():
        text = path.read_text()
        bvh = read_request_bvh(text)
        for joint, way, amount in EDITS:
            req = BVHSolveRequest.model_validate(_body(text, name, joint, way, amount, "soft"))
            ch = character_from_bvh(bvh, req, req.frame)
            edit = solve_prepared(engine, ch, character_problem(ch, req))
            got = canonical_points(ch.skel, edit.pose, ch.jmap)
            p = edit.problem
            miss = np.linalg.norm(ch.to_service(got)[p.target_idx] - p.target_pos, axis=1)
            off = abs(float(miss[0]) - float(edit.result.errors[0]))
            rows.append((name, joint, way, off, float(miss[p.n_targets :].max())))
    _summary(rows, "soft (target: off the canonical answer's miss)")
    assert max(r[3] for r in rows) <= TOL
    assert max(r[4] for r in rows) <= TOL


def _answer(engine: Engine, text: str, name: str, body: dict[str, Any]) -> tuple[Any, Any]:
    """(the canonical answer, the character's report) of one /v1/bvh/solve body."""
    _, _, units, frame = FILES[name]
    body = {"bvh": text, "frame": frame, **body}
    if units is not None:
        body["units"] = units
    req = BVHSolveRequest.model_validate(body)
    bvh = read_request_bvh(text)
    ch = character_from_bvh(bvh, req, req.frame)
    edit = solve_prepared(engine, ch, character_problem(ch, req))
    return edit.result, bvh_answer(bvh, ch, req, edit)


@pytest.mark.parametrize("name", ["bandai", "cmu-daz-salsa", "reactidle-6ch"])
def test_a_wrist_out_of_reach_neither_breaks_a_pin_nor_loses_the_pelvis(
    engine: Engine, bvh_files: dict[str, Path], name: str
) -> None:
    """A review's finds: for a wrist out of reach the whole body was shifted towards it, so
    a pinned pelvis moved up to 0.97 m and a pelvis target the answer met was missed by up
    to 2.2 m; a pin the answer broke for a target (an elbow far from its pinned wrist) was
    held by the character instead, which left the elbow 1.4 m from where the answer put it."""
    text = bvh_files[name].read_text()
    pts = _points(text, name)
    up = pts[JOINT_INDEX["head"]] - pts[JOINT_INDEX["pelvis"]]
    label = resolve_map(skeleton_of(parse_bvh(text))).describe()
    # either wrist, 4 m across (the left one's variant, docs/generalisation-3.md item 62:
    # at 4847cde the character's pelvis ended 7.2 cm from bandai's soft answer's; met since)
    for side, reach in [(s, r) for s in ("right_wrist", "left_wrist") for r in ("exact", "soft")]:
        far = (pts[JOINT_INDEX[side]] + 4.0 * np.roll(up, 1)).tolist()  # across, far
        wrist = {"joint": label[side], "position": far}
        # a pinned pelvis stays where it was
        result, out = _answer(engine, text, name, {"targets": [wrist], "pins": [label["pelvis"]],
                                                    "options": {"reach": reach}})  # fmt: skip
        assert result.pin_errors[0] <= TOL and out["pins"][0]["error"] <= TOL, (reach, out["pins"])
        # a pelvis target the answer met is met
        low = (pts[JOINT_INDEX["pelvis"]] - 0.1 * up).tolist()
        pelvis = {"joint": label["pelvis"], "position": low}
        result, out = _answer(
            engine, text, name, {"targets": [pelvis, wrist], "options": {"reach": reach}}
        )
        assert result.errors[0] <= TOL, (reach, result.errors)
        # exact: held as a pin is; soft: near where the answer put it (the polish's first
        # phase only, docs/characters.md, a compromise with the wrist 1.5 m out of reach:
        # 0.5-0.9 mm with the models of mx1-3ca9545e56de, up to 1.6 mm (CMU salsa) since)
        near = TOL if reach == "exact" else 5 * TOL
        assert out["targets"][0]["error"] <= result.errors[0] + near, (reach, out["targets"])
    # an elbow 2 m from its pinned wrist: where the answer breaks the pin for it, the
    # character follows the answer (it held the pin: the elbow 1.4 m off); soft reach ends
    # its polish before the targets alone, so it may stay a few cm short of the answer
    units = _scale(out)
    across = np.roll(up, 1) / np.linalg.norm(up)
    elbow = {
        "joint": label["left_elbow"],
        "position": (pts[JOINT_INDEX["left_wrist"]] + 2.0 / units * across).tolist(),
    }
    result, out = _answer(engine, text, name, {"targets": [elbow], "pins": [label["left_wrist"]],
                                                "options": {"reach": "soft"}})  # fmt: skip
    assert out["targets"][0]["error"] <= result.errors[0] + 0.05, (out, result.errors)
    if result.pin_errors[0] > TOL:  # the answer broke the pin: so does the character
        assert out["pins"][0]["error"] > TOL


def _points(text: str, name: str) -> np.ndarray:
    bvh = parse_bvh(text)
    skel = skeleton_of(bvh)
    out: np.ndarray = canonical_points(skel, pose_of(bvh, FILES[name][3]), resolve_map(skel))
    return out


def _scale(out: dict[str, Any]) -> float:
    """Metres per unit of an answer's file."""
    units = out["units"]
    return float(UNITS[units]) if isinstance(units, str) else float(units)


@pytest.mark.parametrize("name", ["cmu-asf-bvh", "bandai"])
def test_a_dragged_pelvis_meets_its_target_beside_older_ones(
    engine: Engine, bvh_files: dict[str, Path], name: str
) -> None:
    """The editor's case: a pelvis dragged 20 cm down or across while both ankles and a
    wrist keep targets from earlier drags (exact reach). The canonical answer meets all
    four; at 9a8bcd9 the character left the pelvis 1.2-4.6 mm off (a helper measured 9-14 cm
    in the editor on a tree between the two)."""
    text = bvh_files[name].read_text()
    pts = _points(text, name)
    label = resolve_map(skeleton_of(parse_bvh(text))).describe()
    up = pts[JOINT_INDEX["head"]] - pts[JOINT_INDEX["pelvis"]]
    older = [
        {"joint": label[j], "position": pts[JOINT_INDEX[j]].tolist()}
        for j in ("left_ankle", "right_ankle", "left_wrist")
    ]
    for way in (-up, np.roll(up, 1)):
        at = pts[JOINT_INDEX["pelvis"]] + 0.2 * float(
            np.linalg.norm(up)
        ) / 0.55 * way / np.linalg.norm(way)
        dragged = {"joint": label["pelvis"], "position": at.tolist()}
        for method in ("neural", "fabrik"):
            body = {"targets": [dragged, *older], "options": {"reach": "exact", "method": method}}
            result, out = _answer(engine, text, name, body)
            met = result.errors <= TOL
            got = np.array([t["error"] for t in out["targets"]])
            assert (got[met] <= TOL).all(), (method, result.errors, got)


def test_a_chain_whose_top_sits_on_its_parent_solves_without_a_numeric_warning(
    engine: Engine, bvh_files: dict[str, Path]
) -> None:
    """A review's find: on cmu1/jumping_jacks a chain's top joint sits on the origin of the
    joint that aims it (a zero offset), and the exact-reach widening asked for the turn
    between two zero-length directions: numpy's "invalid value in divide", NaN goals the
    caller then threw away. Two of the review's edits, solved with warnings as errors: the
    character's target as near as the canonical answer's."""
    text = bvh_files["cmu-asf-bvh"].read_text()
    bvh = parse_bvh(text)
    skel = skeleton_of(bvh)
    label = resolve_map(skel).describe()
    pts = canonical_points(skel, pose_of(bvh, 62), resolve_map(skel))
    size = float(np.linalg.norm(pts[JOINT_INDEX["head"]] - pts[JOINT_INDEX["pelvis"]]))
    # (joint, move in pelvis-head lengths, tolerance, pins): two of the review's edits
    for joint, move, tolerance, pins in (
        ("left_elbow", [0.466, 0.826, 0.147], 1e-4, []),
        ("left_wrist", [0.777, -0.096, 0.554], 1e-2, ["left_ankle", "right_ankle"]),
    ):
        goal = (pts[JOINT_INDEX[joint]] + size * np.array(move)).tolist()
        body = {"frame": 62, "targets": [{"joint": label[joint], "position": goal}],
                "pins": [label[p] for p in pins],
                "options": {"reach": "exact", "tolerance": tolerance}}  # fmt: skip
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            result, out = _answer(engine, text, "cmu-asf-bvh", body)
        # (the elbow is out of the arm's reach: the character holds what the answer met)
        assert out["targets"][0]["error"] <= result.errors[0] + tolerance, (joint, out, result)


def test_targets_the_answer_met_do_not_carry_the_body_across(
    engine: Engine, bvh_files: dict[str, Path]
) -> None:
    """Exact reach, a wrist or an elbow moved 10-40 cm (seeded directions, no pins): where
    the canonical answer meets it, so does the character (on these edits: where the answer
    bent what is rigid on the character, it cannot, the next test), with its pelvis where
    the answer put it. The character's chest is rigid where the answer may swing a collar,
    so the arm's chain can start out of reach; that used to move the whole body towards the
    target, held as a pin (at 32857ee the pelvis ended up to 30 cm from the answer's, 13 of
    44 edits beyond 5 cm; now 2.9 cm at most); the polish turns the joints above the chain
    instead."""
    rng = np.random.default_rng(7)
    off = []
    for name, path in bvh_files.items():
        text = path.read_text()
        _, _, units, frame = FILES[name]
        bvh = read_request_bvh(text)
        for joints in (["left_elbow"], ["right_wrist"], ["left_wrist", "right_wrist"]) * 3:
            head = {"joint": "head", "position": [0, 0, 0]}  # (replaced below)
            body: dict[str, Any] = {"bvh": text, "frame": frame, "targets": [head],
                                    "options": {"reach": "exact"}}  # fmt: skip
            if units is not None:
                body["units"] = units
            ch = character_from_bvh(bvh, BVHSolveRequest.model_validate(body), body["frame"])
            pts = canonical_points(ch.skel, ch.pose, ch.jmap)
            label = ch.jmap.describe()
            body["targets"] = []
            for j in joints:
                way = rng.normal(size=3)
                move = way / np.linalg.norm(way) * rng.uniform(0.1, 0.4) / ch.scale
                goal = (pts[JOINT_INDEX[j]] + move).tolist()
                body["targets"].append({"joint": label[j], "position": goal})
            req = BVHSolveRequest.model_validate(body)
            edit = solve_prepared(engine, ch, character_problem(ch, req))
            if (edit.result.errors > TOL).any():
                continue  # (out of the canonical skeleton's reach too: not this test's case)
            got = ch.to_service(canonical_points(ch.skel, edit.pose, ch.jmap))
            p = edit.problem
            miss = np.linalg.norm(got[p.target_idx] - p.target_pos, axis=1)
            assert miss.max() <= TOL, (name, joints, miss)
            pelvis = np.asarray(edit.result.pose)[JOINT_INDEX["pelvis"]]
            off.append(float(np.linalg.norm(got[JOINT_INDEX["pelvis"]] - pelvis)))
    assert len(off) >= 30, len(off)
    print(f"\npelvis off the answer's (mm): max {max(off) * 1e3:.1f}, "
          f"{sum(o > 0.05 for o in off)}/{len(off)} beyond 50 mm")  # fmt: skip
    assert max(off) <= 0.05


#: fair1's dab.bvh at frame 120, inches: both wrists moved 10-40 cm apart (a seeded edit of
#: ``scripts/figures/pelvis_distance.py``, 38.7 in from one another)
_WRISTS_APART = {
    "LeftHand": [-26.72316336254317, 8.016091081622708, 21.037932163846822],
    "RightHand": [10.571671287172157, 8.552015399209855, 31.495950483653328],
}


@pytest.mark.parametrize("pins", [[], PINS], ids=["free", "ankles"])
def test_wrists_the_answer_met_beyond_a_rigid_chest_are_missed_by_no_more_than_they_must(
    engine: Engine, bvh_files: dict[str, Path], pins: list[str]
) -> None:
    """Where the canonical answer meets a target only by bending what is rigid on the
    character, the character misses it, by the least its own skeleton can. The canonical
    skeleton's chest is bones that turn apart (``core.kinematics``: bone lengths, no rigid
    groups): to meet both wrists of this edit, the answer swings its collars from 1.58 to
    8.9 in apart. The child's collars hang 1.58 in apart from one rigid ``Spine3``, so its
    wrists are never farther apart than two arms (collar to wrist) and that: the two misses
    add up to what the targets lie beyond it at least, the farther to half of it (42.0 mm),
    whatever the retarget does; the character's spine folding there is the polish taking
    that least. Pins held, ``reached`` false; the miss within 1 mm of that bound."""
    name = "fair1-child-inches-zup"
    text = bvh_files[name].read_text()
    _, _, units, frame = FILES[name]
    body: dict[str, Any] = {"bvh": text, "frame": frame, "units": units, "pins": pins,
                            "options": {"reach": "exact"},
                            "targets": [{"joint": j, "position": p}
                                        for j, p in _WRISTS_APART.items()]}  # fmt: skip
    req = BVHSolveRequest.model_validate(body)
    ch = character_from_bvh(read_request_bvh(text), req, req.frame)
    edit = solve_prepared(engine, ch, character_problem(ch, req))
    p, res = edit.problem, edit.result
    solved = np.asarray(res.pose)
    wrists = [JOINT_INDEX[f"{s}_wrist"] for s in ("left", "right")]
    collars = [JOINT_INDEX[f"{s}_collar"] for s in ("left", "right")]
    assert (res.errors <= TOL).all() and (res.pin_errors <= TOL).all()  # the answer meets
    before = ch.to_service(canonical_points(ch.skel, ch.pose, ch.jmap))
    after = ch.to_service(canonical_points(ch.skel, edit.pose, ch.jmap))
    span = float(np.linalg.norm(np.subtract(*before[collars])))
    assert np.linalg.norm(np.subtract(*solved[collars])) > 4 * span  # the answer's collars
    assert abs(np.linalg.norm(np.subtract(*after[collars])) - span) < 1e-9  # rigid here
    # an arm's reach: its three bones, collar to wrist (the character's own lengths)
    bones = [(w, PARENTS[w], PARENTS[PARENTS[w]]) for w in wrists]
    arm = [sum(float(np.linalg.norm(before[c] - before[PARENTS[c]])) for c in b) for b in bones]
    apart = float(np.linalg.norm(np.subtract(*p.target_pos[:2])))
    least = (apart - span - sum(arm)) / 2  # each wrist's least miss, were both missed alike
    assert least > 0.04  # 42.0 mm: out of the character's reach
    miss = np.linalg.norm(after[p.target_idx] - p.target_pos, axis=1)
    assert miss[:2].sum() >= 2 * least - 1e-9  # (no pose does better: a check of the bound)
    assert miss[:2].max() <= least + TOL, (miss, least)
    if pins:
        assert miss[2:].max() <= TOL


@pytest.mark.parametrize(
    "pins",
    [("head",), ("neck",), ("neck", "left_ankle", "right_ankle")],
    ids=["head", "neck", "neck+ankles"],
)
@pytest.mark.parametrize("name", sorted(FILES))
def test_a_pinned_head_or_neck_holds_on_the_character_under_far_wrists(
    engine: Engine, bvh_files: dict[str, Path], name: str, pins: tuple[str, ...]
) -> None:
    """Both wrists dragged 1.5 m (seeded directions), the head or the neck pinned: the
    canonical answer holds the pin, and the character's chest, which aims its neck and
    both collars as one rigid turn, used to split the difference and left the head up to
    90 mm off (FABRIK, exact; a pinned neck up to 0.3 m). The pinned child, or the child
    above the pin, now weighs most in that turn (``core.retarget.HEAVY``), and the polish
    puts the pin before the wrists the answer met (``core.reach._better``). A pinned neck
    still ended up to 1 cm off in exact reach on some of these files (its anchor is not
    where the canonical neck is on every chest, and the polish's steps, cut short by the
    far wrist's swing of the arm, did not bring it back): now within 2 mm, as the head, and
    with both ankles pinned too (the neck was 42 mm off on CMU salsa)."""
    bound = 2e-3
    text = bvh_files[name].read_text()
    pts = _points(text, name)
    label = resolve_map(skeleton_of(parse_bvh(text))).describe()
    still = {"joint": label["head"], "position": pts[JOINT_INDEX["head"]].tolist()}
    far = 1.5 / _scale(_answer(engine, text, name, {"targets": [still]})[1])  # 1.5 m in units
    rng = np.random.default_rng(11)
    for options in ({"method": "fabrik", "reach": "exact"}, {"reach": "soft"}, {"reach": "exact"}):
        for _ in range(2):
            d = rng.normal(size=(2, 3))
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            wrists = [
                {"joint": label[w], "position": (pts[JOINT_INDEX[w]] + far * d[k]).tolist()}
                for k, w in enumerate(("left_wrist", "right_wrist"))
            ]
            body = {"targets": wrists, "pins": [label[p] for p in pins], "options": options}
            _, out = _answer(engine, text, name, body)
            assert max(p["error"] for p in out["pins"]) <= bound, (options, out["pins"])


@pytest.mark.parametrize("name", sorted(FILES))
def test_a_pelvis_lowered_in_exact_reach_keeps_the_body_upright(
    engine: Engine, bvh_files: dict[str, Path], name: str
) -> None:
    """An API audit (2026-12-07): a character's pelvis lowered 15-25 % of its height in
    exact reach came back turned over (the pelvis-to-spine line 139-161 degrees from up on
    AnimatedDrawings' children, 51 on CMU's jumping jacks) with its shoulders shrugged to
    0.66-0.78 of their width, where soft reach and the pose form crouched it upright: the
    pelvis's fit weighed an exact pelvis target 100 times (``core.retarget._place_pelvis``).
    Now, free and over pinned ankles: the shoulders keep 80 % of their width, the spine
    leans less than 90 degrees from up, and the pelvis is met."""
    text = bvh_files[name].read_text()
    pts = _points(text, name)
    label = resolve_map(skeleton_of(parse_bvh(text))).describe()
    up = pts[JOINT_INDEX["head"]] - pts[JOINT_INDEX["pelvis"]]
    up = up / np.linalg.norm(up)
    sh = [JOINT_INDEX["left_shoulder"], JOINT_INDEX["right_shoulder"]]
    width = float(np.linalg.norm(np.subtract(*pts[sh])))
    height = float(np.linalg.norm(pts[JOINT_INDEX["head"]] - pts[JOINT_INDEX["left_ankle"]]))
    for drop in (0.15, 0.25):
        at = pts[JOINT_INDEX["pelvis"]] - drop * height * up
        for pins in ([], [label[p] for p in PINS]):
            body = {
                "targets": [{"joint": label["pelvis"], "position": at.tolist()}],
                "pins": pins,
                "options": {"reach": "exact"},
            }
            _, out = _answer(engine, text, name, body)
            got = _points(out["bvh"], name)
            spine = got[JOINT_INDEX["spine1"]] - got[JOINT_INDEX["pelvis"]]
            lean = np.degrees(np.arccos(spine @ up / np.linalg.norm(spine)))
            ratio = float(np.linalg.norm(np.subtract(*got[sh]))) / width
            assert ratio >= 0.8 and lean < 90.0, (drop, pins, ratio, lean)
            assert out["targets"][0]["error"] <= TOL, out["targets"]
