"""Core of characters: BVH writer round trip, joint maps of every naming scheme, swing-only
retarget (numpy only; real files where the archives are present)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from core import compiled_characters
from core.bvh import parse_bvh, read_bvh
from core.bvh_write import format_bvh, pose_of, row_of, skeleton_of, splice_frames
from core.characters import (
    CharacterError,
    Pose,
    build_skeleton,
    forward_kinematics,
    matrix_to_quat,
    swing,
    twist_angle,
)
from core.characters_maps import resolve_map, rest_points
from core.rest import rest_pose
from core.retarget import HEAVY, _aim_pass, _plan, _weights, canonical_points, retarget
from core.skeleton import JOINT_INDEX, JOINT_NAMES, PARENTS


def test_writer_round_trip(bvh_files: dict[str, Path]) -> None:
    for path in bvh_files.values():
        bvh = read_bvh(path)
        again = parse_bvh(format_bvh(bvh))
        assert again.joints == bvh.joints
        assert again.frame_time == bvh.frame_time
        np.testing.assert_array_equal(again.motion, bvh.motion)
        # splicing an unchanged frame with no columns gives the file back byte for byte
        assert splice_frames(bvh, {3: (bvh.motion[3], [])}) == bvh.text


def test_real_files_map_automatically(bvh_files: dict[str, Path]) -> None:
    schemes = {n: resolve_map(skeleton_of(read_bvh(p))).scheme for n, p in bvh_files.items()}
    assert schemes == {
        "fair1-child-inches-zup": "mixamo",
        "cmu-asf-bvh": "cmu-asf-bvh",
        "cmu-daz-salsa": "cmu-daz",
        "bandai": "bandai-namco",
        "reactidle-6ch": "rigify",
    }


_NAMES = {
    "unreal": ("pelvis spine_01 spine_03 neck_01 head clavicle_{s} upperarm_{s} lowerarm_{s} "
               "hand_{s} thigh_{s} calf_{s} foot_{s} ball_{s}", ("l", "r")),
    "mixamo": ("mixamorig:Hips mixamorig:Spine mixamorig:Spine2 mixamorig:Neck mixamorig:Head "
               "mixamorig:{s}Shoulder mixamorig:{s}Arm mixamorig:{s}ForeArm mixamorig:{s}Hand "
               "mixamorig:{s}UpLeg mixamorig:{s}Leg mixamorig:{s}Foot mixamorig:{s}ToeBase",
               ("Left", "Right")),
    "vrm": ("hips spine upperChest neck head {s}Shoulder {s}UpperArm {s}LowerArm {s}Hand "
            "{s}UpperLeg {s}LowerLeg {s}Foot {s}Toes", ("left", "right")),
    "vroid": ("J_Bip_C_Hips J_Bip_C_Spine J_Bip_C_Chest J_Bip_C_Neck J_Bip_C_Head "
              "J_Bip_{s}_Shoulder J_Bip_{s}_UpperArm J_Bip_{s}_LowerArm J_Bip_{s}_Hand "
              "J_Bip_{s}_UpperLeg J_Bip_{s}_LowerLeg J_Bip_{s}_Foot J_Bip_{s}_ToeBase",
              ("L", "R")),
    "rigify": ("DEF-spine DEF-spine.001 DEF-spine.003 DEF-spine.004 DEF-spine.006 "
               "DEF-shoulder.{s} DEF-upper_arm.{s} DEF-forearm.{s} DEF-hand.{s} DEF-thigh.{s} "
               "DEF-shin.{s} DEF-foot.{s} DEF-toe.{s}", ("L", "R")),
    "cmu-asf": ("root upperback thorax upperneck head {s}clavicle {s}humerus {s}radius "
                "{s}hand {s}femur {s}tibia {s}foot {s}toes", ("l", "r")),
}  # fmt: skip
_ORDER = ["pelvis", "spine1", "spine2", "neck", "head", "collar", "shoulder", "elbow", "wrist",
          "hip", "knee", "ankle", "foot"]  # fmt: skip


def _named_skeleton(scheme: str) -> tuple[list[str], list[str | None], list[list[float]]]:
    """The canonical rest pose under a scheme's names, with a twist bone in each upper arm
    and an extra spine joint (as real rigs have)."""
    pattern, sides = _NAMES[scheme]
    table = dict(zip(_ORDER, pattern.split(), strict=True))
    rest = rest_pose()

    def name(canon: str) -> str:
        for side, prefix in enumerate(("left_", "right_")):
            if canon.startswith(prefix):
                return table[canon[len(prefix) :]].replace("{s}", sides[side])
        return table[canon]

    names, parents, offsets = [], [], []
    for j, canon in enumerate(JOINT_NAMES):
        p = PARENTS[j]
        names.append(name(canon))
        parents.append(None if p < 0 else name(JOINT_NAMES[p]))
        offsets.append((rest[j] - (rest[p] if p >= 0 else 0.0)).tolist())
    # an extra spine joint between spine1 and spine2, and an upper-arm twist bone
    k = names.index(name("spine2"))
    names.append("extra_spine")
    parents.append(name("spine1"))
    offsets.append([0.0, 0.1, 0.0])
    parents[k] = "extra_spine"
    offsets[k] = [offsets[k][0], offsets[k][1] - 0.1, offsets[k][2]]
    names.append("arm_twist")
    parents.append(name("left_shoulder"))
    offsets.append([0.1, 0.0, 0.0])
    return names, parents, offsets


@pytest.mark.parametrize("scheme", list(_NAMES))
def test_synthetic_schemes(scheme: str) -> None:
    names, parents, offsets = _named_skeleton(scheme)
    skel, _ = build_skeleton(names, parents, offsets)
    jmap = resolve_map(skel)
    assert jmap.scheme == scheme
    got = jmap.describe()
    assert got["left_wrist"] == names[JOINT_INDEX["left_wrist"]]
    assert got["spine2"] == names[JOINT_INDEX["spine2"]]
    # an explicit map wins joint by joint
    forced = resolve_map(skel, {"spine1": "extra_spine"})
    assert forced.describe()["spine1"] == "extra_spine"
    assert forced.scheme == f"{scheme}+explicit"


@pytest.mark.parametrize("spines", [2, 1])
def test_biped_clavicles_on_the_neck(spines: int) -> None:
    """3ds Max Biped hangs its clavicles from ``Bip01 Neck`` (not from the chest, as the
    canonical skeleton does) under a root ``Bip01`` above the pelvis: the map still finds
    them, with the chest where it is named, each canonical point where the skeleton has it.
    A Biped of one spine joint has its chest 0.35 of the way up that joint's bone (a 422 once:
    the chest fell on the neck)."""
    rest = rest_pose()
    names: list[str] = ["Bip01"]
    parents: list[str | None] = [None]
    offsets: list[list[float]] = [rest[0].tolist()]
    label = dict(pelvis="Pelvis", spine1="Spine", spine2="Spine1", neck="Neck", head="Head",
                 collar="Clavicle", shoulder="UpperArm", elbow="Forearm", wrist="Hand",
                 hip="Thigh", knee="Calf", ankle="Foot", foot="Toe0")  # fmt: skip

    def name(canon: str) -> str:
        side, _, base = canon.partition("_")
        return f"Bip01 {side[0].upper()} {label[base]}" if base else f"Bip01 {label[canon]}"

    for j, canon in enumerate(JOINT_NAMES):
        p = JOINT_INDEX["neck"] if canon.endswith("collar") else PARENTS[j]
        if spines == 1 and canon == "spine2":
            continue
        if spines == 1 and p == JOINT_INDEX["spine2"]:
            p = JOINT_INDEX["spine1"]
        names.append(name(canon))
        parents.append("Bip01" if p < 0 else name(JOINT_NAMES[p]))
        offsets.append((rest[j] - rest[max(p, 0)]).tolist())
    skel, _ = build_skeleton(names, parents, offsets)
    jmap = resolve_map(skel)
    assert jmap.scheme == "biped"
    assert jmap.describe()["left_collar"] == "Bip01 L Clavicle"
    if spines == 2:
        assert jmap.describe()["spine2"] == "Bip01 Spine1"
        np.testing.assert_allclose(rest_points(skel, jmap), rest, rtol=0, atol=1e-12)
    else:
        assert jmap.describe()["spine2"] == "0.35 of Bip01 Spine->Bip01 Neck"


def test_a_chest_named_above_the_collars_only() -> None:
    """A review's find: ``cmu-asf-bvh`` names the chest ``Chest4|Chest3|Chest2`` (Xsens has
    four), and took ``Chest3`` where the collars hang from ``Chest2`` (a 422: the collar not
    below the chest). A named chest that is not above both collars is left to the
    structural rule: where the collars meet."""
    names = ["Hips", "Chest", "Chest2", "Chest3", "Neck", "Head"]
    parents: list[str | None] = [None, "Hips", "Chest", "Chest2", "Chest3", "Neck"]
    offsets = [[0.0, 1.0, 0.0], [0.0, 0.1, 0.0], [0.0, 0.1, 0.0], [0.0, 0.1, 0.0],
               [0.0, 0.1, 0.0], [0.0, 0.1, 0.0]]  # fmt: skip
    for side, x in (("Left", 1.0), ("Right", -1.0)):
        chain = [("Collar", "Chest2", [0.03 * x, 0.08, 0.0]),
                 ("Shoulder", "Collar", [0.15 * x, 0, 0]),
                 ("Elbow", "Shoulder", [0.28 * x, 0, 0]), ("Wrist", "Elbow", [0.25 * x, 0, 0]),
                 ("Hip", "Hips", [0.1 * x, -0.05, 0]), ("Knee", "Hip", [0, -0.45, 0]),
                 ("Ankle", "Knee", [0, -0.42, 0]), ("Toe", "Ankle", [0, -0.08, 0.12])]  # fmt: skip
        for name, parent, off in chain:
            names.append(side + name)
            parents.append(
                parent if parent.startswith("Chest") or parent == "Hips" else side + parent
            )
            offsets.append([float(v) for v in off])
    skel, _ = build_skeleton(names, parents, offsets)
    jmap = resolve_map(skel)
    assert jmap.scheme == "cmu-asf-bvh"
    assert jmap.describe()["spine2"] == "Chest2"


def test_bad_skeletons() -> None:
    with pytest.raises(CharacterError, match="cycle"):
        build_skeleton(["a", "b", "c"], [None, "c", "b"], [[0, 0, 0]] * 3)
    with pytest.raises(CharacterError, match="duplicate"):
        build_skeleton(["a", "a"], [None, "a"], [[0, 0, 0]] * 2)
    with pytest.raises(CharacterError, match="not finite"):
        build_skeleton(["a"], [None], [[0, float("nan"), 0]])


def test_retarget_swing_only_and_exact(bvh_files: dict[str, Path]) -> None:
    bvh = read_bvh(bvh_files["cmu-daz-salsa"])
    skel = skeleton_of(bvh)
    jmap = resolve_map(skel)
    pose = pose_of(bvh, 200)
    start = canonical_points(skel, pose, jmap)
    goal = start.copy()
    w, e = JOINT_INDEX["left_wrist"], JOINT_INDEX["left_elbow"]
    goal[w] = start[e] + 0.95 * (start[w] - start[e]) + np.array([0.0, 5.0, 0.0])
    out = retarget(skel, pose, jmap, start, exact=[(w, goal[w])], tolerance=0.01)
    assert np.linalg.norm(out.points[w] - goal[w]) < 0.01
    # swing only, but at and above an elbow the frame bends as a hinge (core.hinges): its
    # rotation keeps its axis, the upper arm turning about itself to suit
    for name, child in (("lShldr", "lForeArm"), ("lForeArm", "lHand")):
        j = skel.index[name]
        delta = pose.rotations[j].T @ out.pose.rotations[j]
        if twist_angle(delta, skel.offsets[skel.index[child]]) >= 1e-9:
            e = skel.index["lForeArm"]
            was, now = (matrix_to_quat(r[e])[:3] for r in (pose.rotations, out.pose.rotations))
            assert np.linalg.norm(np.cross(was / np.linalg.norm(was), now)) < 1e-9, name
            assert float(was @ now) > 0.0, name
    # FK of the answer = its points; offsets and unmapped joints untouched
    g_rot, g_pos = forward_kinematics(skel, out.pose)
    assert np.allclose(canonical_points(skel, out.pose, jmap), out.points, atol=1e-12)
    np.testing.assert_array_equal(out.pose.translations[1:], pose.translations[1:])
    for j in range(skel.size):
        if j not in out.changed:
            np.testing.assert_array_equal(out.pose.rotations[j], pose.rotations[j])
    # written back and read again: the same pose to 1e-6 degrees
    row, cols = row_of(bvh, 200, out.pose, out.changed)
    again = pose_of(bvh, 200, row)
    assert np.abs(again.rotations - out.pose.rotations).max() < 1e-7
    assert isinstance(out.pose, Pose) and cols
    assert g_pos.shape == (skel.size, 3) and g_rot.shape == (skel.size, 3, 3)


@pytest.mark.parametrize("stretch", [0.5, 0.99, 0.997, 0.9999])
def test_retarget_exact_reach_near_full_stretch(bvh_files: dict[str, Path], stretch: float) -> None:
    """A leg pinned or dragged almost straight (a standing character) reaches its goal to
    rounding: the two-bone chain is solved in closed form (FABRIK alone was still 2 mm
    short after 64 rounds at 99.7 % of the leg's length)."""
    bvh = read_bvh(bvh_files["cmu-daz-salsa"])
    skel = skeleton_of(bvh)
    jmap = resolve_map(skel)
    pose = pose_of(bvh, 200)
    start = canonical_points(skel, pose, jmap)
    h, k, a = (JOINT_INDEX[n] for n in ("left_hip", "left_knee", "left_ankle"))
    _, g_pos = forward_kinematics(skel, pose)
    hip = g_pos[jmap.anchors[h].joint]
    leg = np.linalg.norm(start[k] - hip) + np.linalg.norm(start[a] - start[k])
    down = start[a] - hip
    down = down / np.linalg.norm(down) + np.array([0.05, 0.0, 0.03])
    goal = hip + stretch * leg * down / np.linalg.norm(down)
    out = retarget(skel, pose, jmap, start, exact=[(a, goal)], tolerance=1e-6 * leg)
    assert np.linalg.norm(out.points[a] - goal) < 1e-9 * leg
    bent = out.points[k] - (hip + out.points[a]) / 2  # the knee still bends forward
    before = start[k] - (hip + start[a]) / 2
    assert bent @ before > 0


def test_retarget_exact_reach_bends_a_straight_leg_forward(bvh_files: dict[str, Path]) -> None:
    """A leg solved dead straight, its ankle then pinned nearer the hip along that line
    (a T-pose leg under a lowered pelvis): no bend plane exists, and FABRIK cannot bend a
    straight chain; the closed form bends the knee towards where the foot points."""
    bvh = read_bvh(bvh_files["cmu-daz-salsa"])
    skel = skeleton_of(bvh)
    jmap = resolve_map(skel)
    pose = pose_of(bvh, 200)
    start = canonical_points(skel, pose, jmap)
    h, k, a, f = (JOINT_INDEX[n] for n in ("left_hip", "left_knee", "left_ankle", "left_foot"))
    _, g_pos = forward_kinematics(skel, pose)
    hip = g_pos[jmap.anchors[h].joint]
    thigh = np.linalg.norm(start[k] - hip)
    leg = thigh + np.linalg.norm(start[a] - start[k])
    down = (start[a] - hip) / np.linalg.norm(start[a] - hip)
    solved = start.copy()
    solved[k] = hip + thigh * down  # straight: the knee on the hip-ankle line
    solved[a] = hip + leg * down
    solved[f] = solved[a] + (start[f] - start[a])
    goal = hip + 0.9 * leg * down
    out = retarget(skel, pose, jmap, solved, exact=[(a, goal)], tolerance=1e-6 * leg)
    assert np.linalg.norm(out.points[a] - goal) < 1e-9 * leg
    toes = start[f] - start[a]
    knee = out.points[k] - (hip + goal) / 2
    assert knee @ (toes - (toes @ down) * down) > 0  # forward, where the foot points


# --------------------------------------------------------------------------------------
# numpy rotations against an independent reference (scipy: a dev dependency, never the
# service's)
# --------------------------------------------------------------------------------------
EULER_SEQS = [a + b + c for a in "XYZ" for b in "XYZ" for c in "XYZ" if a != b and b != c]


@pytest.mark.parametrize("seq", EULER_SEQS)
def test_euler_angles_match_scipy_and_invert_euler_matrices(seq: str) -> None:
    from scipy.spatial.transform import Rotation

    from core.euler import euler_angles, euler_matrices

    rots = Rotation.random(500, random_state=7)
    mats = rots.as_matrix()
    ours = euler_angles(seq, mats)
    wrap = (ours - rots.as_euler(seq) + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(wrap).max() < 1e-12
    assert np.allclose(euler_matrices(seq, ours), mats, atol=1e-12)
    # gimbal lock: the middle angle at its bound; the answer still rebuilds the matrix
    angles = np.random.default_rng(1).uniform(-np.pi, np.pi, (40, 3))
    angles[:, 1] = np.pi / 2 * np.sign(angles[:, 1]) if seq[0] != seq[2] else 0.0
    locked = euler_matrices(seq, angles)
    assert np.allclose(euler_matrices(seq, euler_angles(seq, locked)), locked, atol=1e-9)
    with pytest.raises(ValueError, match="Euler sequence"):
        euler_angles(seq[0] * 3, mats)


def test_matrix_to_quat_matches_scipy() -> None:
    from scipy.spatial.transform import Rotation

    from core.characters import matrix_to_quat, quat_to_matrix

    mats = np.concatenate(
        [
            Rotation.random(2000, random_state=3).as_matrix(),
            np.stack([np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1])]),
        ]
    )
    noisy = mats + 1e-5 * np.random.default_rng(4).normal(size=mats.shape)
    for m in (mats, noisy):
        ref = Rotation.from_matrix(m).as_quat()
        ref = np.where(ref[:, 3:4] < 0, -ref, ref)
        ours = matrix_to_quat(m)
        assert np.minimum(abs(ours - ref).max(1), abs(ours + ref).max(1)).max() < 1e-12
        assert (ours[:, 3] >= 0).all()
    assert np.allclose(quat_to_matrix(matrix_to_quat(mats)), mats, atol=1e-12)
    assert matrix_to_quat(mats.reshape(-1, 1, 3, 3)).shape == (len(mats), 1, 4)


def test_character_modules_import_no_scipy() -> None:
    import subprocess
    import sys

    # scipy made unimportable: the modules must not need it (numba, the service's JIT,
    # imports scipy for a version check when it happens to be installed, so "not in
    # sys.modules" would test the venv, not these modules)
    code = (
        "import sys; sys.modules['scipy'] = None; "
        "import core.bvh, core.bvh_write, core.characters, core.characters_maps, "
        "core.retarget, service.characters"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_compiled_forward_kinematics_is_the_matrix_products_of_the_joints(
    bvh_files: dict[str, Path],
) -> None:
    """core.compiled_characters against the plain numpy products, joint by joint, on
    every file's skeleton and several of its frames; the same answer on every call, and
    the anchors' points as the per-anchor formula gives them."""
    for name, path in bvh_files.items():
        bvh = read_bvh(path)
        skel = skeleton_of(bvh)
        jmap = resolve_map(skel, None)
        for frame in range(0, bvh.num_frames, max(1, bvh.num_frames // 5)):
            pose = pose_of(bvh, frame)
            g_rot, g_pos = forward_kinematics(skel, pose)
            ref_rot, ref_pos = np.empty_like(g_rot), np.empty_like(g_pos)
            for j, p in enumerate(skel.parents):
                if p < 0:
                    ref_rot[j], ref_pos[j] = pose.rotations[j], pose.translations[j]
                else:
                    ref_rot[j] = ref_rot[p] @ pose.rotations[j]
                    ref_pos[j] = ref_pos[p] + ref_rot[p] @ pose.translations[j]
            scale = max(1.0, float(np.abs(ref_pos).max()))
            np.testing.assert_allclose(g_rot, ref_rot, rtol=0, atol=1e-12, err_msg=name)
            np.testing.assert_allclose(g_pos, ref_pos, rtol=0, atol=1e-12 * scale, err_msg=name)
            again = forward_kinematics(skel, Pose(pose.rotations.copy(), pose.translations.copy()))
            assert again[0].tobytes() == g_rot.tobytes() and again[1].tobytes() == g_pos.tobytes()
            points = np.stack([g_pos[a.joint] + g_rot[a.joint] @ a.offset for a in jmap.anchors])
            got = jmap.points(g_rot, g_pos)
            np.testing.assert_allclose(got, points, rtol=0, atol=1e-12 * scale)


def test_compiled_swing_is_the_numpy_swing() -> None:
    """core.compiled_characters.swing_matrix_into against core.characters.swing: random
    directions, parallel ones (no turn) and opposite ones (a half turn about the axis
    perpendicular to the smallest component), each a rotation taking a onto b; none where
    either has no direction."""
    rng = np.random.default_rng(3)
    pairs = [(rng.normal(size=3), rng.normal(size=3)) for _ in range(200)]
    for a in [*rng.normal(size=(20, 3)), np.array([0.0, 0.0, 2.0]), np.array([1.0, 1e-9, 0.0])]:
        pairs += [(a, 3.0 * a), (a, -0.5 * a)]
    out = np.empty((3, 3))
    for a, b in [(np.zeros(3), pairs[0][1]), (pairs[0][0], np.zeros(3))]:  # no direction
        with np.errstate(all="raise"):
            compiled_characters.swing_matrix_into(a, b, out)
            assert (out == np.eye(3)).all() and (swing(a, b) == np.eye(3)).all()
    for a, b in pairs:
        compiled_characters.swing_matrix_into(a, b, out)
        np.testing.assert_allclose(out, swing(a, b), rtol=0, atol=1e-14)
        ua, ub = a / np.linalg.norm(a), b / np.linalg.norm(b)
        np.testing.assert_allclose(out @ ua, ub, rtol=0, atol=1e-12)


def _svd_rotation(v: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The reference weighted Kabsch: numpy's SVD, the reflection taken out."""
    uu, _, vt = np.linalg.svd((v * w[:, None]).T @ u)
    d = np.sign(np.linalg.det(vt.T @ uu.T)) or 1.0
    return np.asarray(vt.T @ np.diag([1.0, 1.0, d]) @ uu.T)


def test_compiled_best_rotation_is_the_svd_kabsch() -> None:
    """core.compiled_characters.best_rotation (Horn's quaternion by Jacobi sweeps) against
    numpy's SVD Kabsch: random rotations of 2-6 unit directions with noise and uneven
    weights (one child 100 times the others, as a pin weighs), the exact turn where there
    is no noise, a proper rotation always, the same bytes on a second call."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(11)
    turns = Rotation.random(300, random_state=5).as_matrix()
    for i, turn in enumerate(turns):
        k = 2 + i % 5
        v = rng.normal(size=(k, 3))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        noise = 0.0 if i % 3 == 0 else rng.uniform(0.0, 0.3)
        u = v @ turn.T + noise * rng.normal(size=(k, 3))
        w = rng.uniform(0.2, 1.0, k)
        if i % 4 == 1:
            w[0] *= HEAVY
        w /= w.sum()
        got = compiled_characters.best_rotation(v, u, w)
        np.testing.assert_allclose(got, _svd_rotation(v, u, w), rtol=0, atol=1e-12)
        np.testing.assert_allclose(got @ got.T, np.eye(3), rtol=0, atol=1e-14)
        assert np.linalg.det(got) > 0
        if noise == 0.0:
            np.testing.assert_allclose(got, turn, rtol=0, atol=1e-13)
        assert compiled_characters.best_rotation(v, u, w).tobytes() == got.tobytes()


def _numpy_aim(skel, pose, jmap, b, kids, goal, original, weigh) -> bool:  # type: ignore[no-untyped-def]
    """The reference aim of one group (numpy, the SVD): joint ``b`` from its ``original``
    rotation turned so its canonical children ``kids`` point at ``goal``; True where its
    rotation changed."""
    pose.rotations[b] = original.rotations[b]
    g_rot, g_pos = forward_kinematics(skel, pose)
    pivot = g_pos[b]
    v = jmap.points(g_rot, g_pos)[kids] - pivot
    u = goal[kids] - pivot
    nv, nu = np.linalg.norm(v, axis=1), np.linalg.norm(u, axis=1)
    ok = (nv > 1e-9 * max(1.0, float(nv.max()))) & (nu > 1e-12)
    if not ok.any():
        return False
    if ok.sum() == 1:
        k = int(np.argmax(ok))
        turn = swing(v[k], u[k])
    else:
        w = nv * weigh[kids]
        turn = _svd_rotation(v[ok] / nv[ok, None], u[ok] / nu[ok, None], w[ok] / w[ok].sum())
    new_global = turn @ g_rot[b]
    parent = skel.parents[b]
    local = new_global if parent < 0 else g_rot[parent].T @ new_global
    if (np.abs(local - original.rotations[b]) <= 1e-15).all():
        return False
    pose.rotations[b] = local
    return True


def test_compiled_aim_pass_is_the_numpy_aim_of_each_group(bvh_files: dict[str, Path]) -> None:
    """The compiled aim pass (``core.retarget._aim_pass``) against the numpy aim of every
    group in turn (:func:`_numpy_aim`: swings and numpy's SVD), on every file's skeleton,
    two frames each, goals the start's points moved by up to a tenth of the body's size
    (one run skipping the first group, as a turned pelvis is; one with a pinned neck's
    weights): rotations to 1e-12, the same joints changed, the same bytes on a second run."""
    rng = np.random.default_rng(7)
    pinned = _weights(frozenset({JOINT_INDEX["neck"], JOINT_INDEX["spine2"]}))
    for name, path in bvh_files.items():
        bvh = read_bvh(path)
        skel = skeleton_of(bvh)
        jmap = resolve_map(skel, None)
        plan = _plan(skel, jmap)
        several = [b for b in plan.groups if len(plan.groups[b]) > 1]
        assert several, name  # a chest or a pelvis: the least-squares turn is exercised
        for frame, skip, weigh in (
            (0, None, _weights(frozenset())),
            (bvh.num_frames // 2, int(plan.aims[0]), pinned),
        ):
            pose = pose_of(bvh, frame)
            start = canonical_points(skel, pose, jmap)
            goal = start + rng.normal(0.0, 0.1 * float(np.ptp(start, axis=0).max()), start.shape)
            got = pose.copy()
            changed = _aim_pass(skel, got, jmap, plan, goal, skip, pose, weigh)
            want, want_changed = pose.copy(), set()
            for b in sorted(plan.groups):
                if b != skip and _numpy_aim(skel, want, jmap, b, plan.groups[b], goal, pose, weigh):
                    want_changed.add(b)
            np.testing.assert_allclose(got.rotations, want.rotations, rtol=0, atol=1e-12)
            assert changed == want_changed and len(changed) > len(plan.groups) // 2, name
            assert set(several) - {skip} <= changed, name
            again = pose.copy()
            assert _aim_pass(skel, again, jmap, plan, goal, skip, pose, weigh) == changed
            assert again.rotations.tobytes() == got.rotations.tobytes(), name
            # the pose turned in place, its own original: the same turns, the same report
            alias = pose.copy()
            assert _aim_pass(skel, alias, jmap, plan, goal, skip, alias, weigh) == changed, name
            np.testing.assert_allclose(alias.rotations, got.rotations, rtol=0, atol=1e-12)


def test_collars_on_one_point_slide_apart() -> None:
    """CMU ASF's clavicles both start where the neck does (the end of ``thorax``), not on
    the chest: the two collars were mapped to one midline point, a body the networks never
    saw, and a map that slid them (sent back as the answer's own labels) was refused. Now
    both slide a quarter along their bones, as collars on the chest do."""
    names, parents, offsets = _named_skeleton("cmu-asf")
    rest = rest_pose()
    neck = rest[JOINT_INDEX["neck"]] - rest[JOINT_INDEX["spine2"]]
    for side in ("left", "right"):
        collar, shoulder = JOINT_INDEX[f"{side}_collar"], JOINT_INDEX[f"{side}_shoulder"]
        offsets[collar] = neck.tolist()  # on the neck's point, from the chest
        offsets[shoulder] = (rest[shoulder] - rest[JOINT_INDEX["spine2"]] - neck).tolist()
    skel, _ = build_skeleton(names, parents, offsets)
    jmap = resolve_map(skel)
    got = jmap.describe()
    assert got["left_collar"] == "0.25 of lclavicle->lhumerus"
    assert got["right_collar"] == "0.25 of rclavicle->rhumerus"
    pts = rest_points(skel, jmap)
    left, right = pts[JOINT_INDEX["left_collar"]], pts[JOINT_INDEX["right_collar"]]
    width = np.linalg.norm(rest[JOINT_INDEX["left_shoulder"]] - rest[JOINT_INDEX["right_shoulder"]])
    assert np.linalg.norm(left - right) > 0.2 * width
    assert resolve_map(skel, {"left_collar": got["left_collar"]}).describe() == got
