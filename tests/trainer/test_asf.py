"""Acclaim ASF/AMC reader (trainer/data/asf.py): hand-computed FK, real CMU subjects, the
convention checked against CMU's own BVH conversion of the same take, and clear errors."""

from __future__ import annotations

import pickle
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.bvh import read_bvh
from core.geometry import canonicalise
from core.skeleton import JOINT_INDEX, bone_lengths
from tests.conftest import _KAY, untar
from trainer.data.asf import CMU_FPS, ASFError, parse_amc, parse_asf, read_amc, read_asf
from trainer.data.maps import joint_positions, load_map

MAPS = Path(__file__).resolve().parents[2] / "trainer" / "maps"

TINY_ASF = """# a root and two bones
:version 1.10
:units
  mass 1.0
  length 0.45
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name a
     direction 1 0 0
     length 2
     axis 0 0 90 XYZ
    dof rx
  end
  begin
     id 2
     name b
     direction 0 1 0
     length 1
     axis 0 0 0 XYZ
  end
:hierarchy
  begin
    root a
    a b
  end
"""
TINY_AMC = """:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 0 0 0
a 0
2
root 1 2 3 0 0 0
a 90
3
root 0 0 0 90 0 90
a 0
"""


def test_fk_matches_hand_computed_poses() -> None:
    sk = parse_asf(TINY_ASF, "tiny.asf")
    assert sk.joint_names == ("root", "a", "b")
    assert sk.metres_per_unit == pytest.approx(0.0254 / 0.45)
    amc = parse_amc(TINY_AMC, sk, "tiny.amc")
    assert (amc.num_frames, amc.fps) == (3, CMU_FPS)
    pos = amc.forward_kinematics()
    expected = [
        # rest: a ends 2 along +X from the root, b 1 further along +Y.
        [[1, 2, 3], [3, 2, 3], [3, 3, 3]],
        # a's rx = 90 is about its OWN x axis, which C = Rz(90) turns to world +Y:
        # C Rx(90) C^-1 is a 90-degree turn about +Y, taking +X to -Z (and b's +Y stays).
        [[1, 2, 3], [1, 2, 1], [1, 3, 1]],
        # root rx = rz = 90, order "RX RY RZ": x applied first, M = Rz(90) @ Rx(90):
        # +X -> +Y and +Y -> +Z. (Rx(90) @ Rz(90) would take +X to +Z.)
        [[0, 0, 0], [0, 2, 0], [0, 2, 1]],
    ]
    np.testing.assert_allclose(pos, expected, atol=1e-9)
    np.testing.assert_allclose(amc.forward_kinematics(["b"], frames=slice(1, 3)), pos[1:3, 2:])


@pytest.mark.parametrize(
    ("asf", "amc", "message"),
    [
        (TINY_ASF, TINY_AMC.replace("a 90", "a 90 1"), "line 8: bone 'a' needs 1 values, got 2"),
        (TINY_ASF, TINY_AMC.replace("a 90", "q 90"), "line 8: unknown bone 'q'"),
        (TINY_ASF, TINY_AMC.replace("a 90\n", ""), "frame 2 lacks bones ['a']"),
        (TINY_ASF, TINY_AMC.replace("a 90", "a x"), "line 8: not a number"),
        (TINY_ASF, TINY_AMC.replace("a 90", "b 90"), "bone 'b' has no dof"),
        (TINY_ASF, "root 1 2 3 0 0 0", "before the first frame number"),
        (TINY_ASF.replace("    a b\n", "    a c\n"), "", "unknown bone 'c'"),
        (TINY_ASF.replace("dof rx", "dof rx l"), "", "unsupported dof ['l']"),
        (TINY_ASF.replace("length 2", "length two"), "", "line 17: length: not a number"),
        (TINY_ASF.replace("    a b\n", ""), "", "not reachable from the root"),
        ("garbage", "", "not an ASF file"),
    ],
)
def test_malformed_files_raise_asferror(asf: str, amc: str, message: str) -> None:
    """Each names its file and reason, and survives pickling (the dataset builder's worker
    processes): ``ASFError(file, reason)`` passed ``args`` its one message, and unpickling
    it was a ``TypeError``."""
    with pytest.raises(ASFError) as info:
        parse_amc(amc, parse_asf(asf, "x.asf"), "x.amc")
    assert message in str(info.value)
    assert info.value.file in ("x.asf", "x.amc")
    back = pickle.loads(pickle.dumps(info.value))
    assert type(back) is ASFError and str(back) == str(info.value)
    assert (back.file, back.reason, back.args) == (
        info.value.file,
        info.value.reason,
        info.value.args,
    )


def test_real_cmu_walk(more_mocap: Path) -> None:
    """Subject 07 walking: FK bone lengths equal the ASF's, the figure stands upright at a
    plausible height, and after canonicalisation left is +X and the toes point +Z."""
    sk = read_asf(more_mocap / f"{_KAY}/07-walk.asf")
    amc = read_amc(more_mocap / f"{_KAY}/07_05-walk.amc", sk)
    assert amc.num_frames == 517
    pos = amc.forward_kinematics()
    for j, bone in enumerate(sk.bones[1:], start=1):
        length = np.linalg.norm(pos[:, j] - pos[:, bone.parent], axis=-1)
        np.testing.assert_allclose(length, bone.length, rtol=1e-9, err_msg=bone.name)
    s = sk.metres_per_unit
    y = {n: pos[:, sk.index(n), 1] * s for n in ("root", "head", "ltoes", "rtoes")}
    assert 0.85 < y["root"].mean() < 1.0  # pelvis of a walking adult, metres
    assert (y["head"] > y["root"] + 0.5).all()
    # The floor is y = 0: the lower toe touches it (the first 7 frames have the right toe
    # 6 cm below it, a glitch of the capture, hence a percentile).
    assert -0.02 < np.percentile(np.minimum(y["ltoes"], y["rtoes"]), 10) < 0.05

    m = load_map(MAPS / "cmu_asf.toml")
    rel = f"{_KAY}/07_05-walk.amc"
    canon = canonicalise(joint_positions(amc, m.joints_for(rel)) * s)
    j = JOINT_INDEX
    assert (canon[:, j["left_hip"], 0] > 0.03).all()
    assert (canon[:, j["left_shoulder"], 0] > canon[:, j["right_shoulder"], 0]).all()
    toes = np.r_[canon[:, j["left_foot"], 2] - canon[:, j["left_ankle"], 2]]
    assert (toes > 0).mean() > 0.95
    # Bones of the map (a collar part-way along the clavicle) are rigid too.
    assert np.ptp(bone_lengths(canon), axis=0).max() < 0.01


def test_convention_matches_cmus_bvh_conversion(
    more_mocap: Path, mocap_dir: Path, tmp_path: Path
) -> None:
    """135_06 (martial arts) is also in cmu-dance as martial/06.bvh, converted by others to
    another skeleton: the directions of the thigh, shin and upper arm must agree frame by
    frame. (Composing the Euler angles the other way round puts them 16-84 degrees apart.)"""
    tar = shutil.which("tar")
    if tar is None:
        pytest.skip("the 'tar' command is needed")
    out = tmp_path
    member = "train_data_bvh/martial/06.bvh"
    subprocess.run(untar(tar, mocap_dir / "cmu-dance.tar.xz", out, [member]), check=True)
    bvh = read_bvh(out / member)
    sk = read_asf(more_mocap / f"{_KAY}/135-martialArts.asf")
    amc = read_amc(more_mocap / f"{_KAY}/135_06-martialArts.amc", sk)
    assert bvh.num_frames == amc.num_frames + 1  # the BVH adds a rest frame
    pairs = [
        (("lhipjoint", "lfemur"), ("lThigh", "lShin")),
        (("lfemur", "ltibia"), ("lShin", "lFoot")),
        (("rfemur", "rtibia"), ("rShin", "rFoot")),
        (("lclavicle", "lhumerus"), ("lShldr", "lForeArm")),
        (("rclavicle", "rhumerus"), ("rShldr", "rForeArm")),
    ]

    def directions(p: Any, names: list[str], segs: list[tuple[str, str]]) -> Any:
        d = np.stack([p[:, names.index(b)] - p[:, names.index(a)] for a, b in segs], axis=1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    a_names = sorted({n for (a, _) in pairs for n in a})
    b_names = sorted({n for (_, b) in pairs for n in b})
    da = directions(amc.forward_kinematics(a_names), a_names, [a for a, _ in pairs])
    db = directions(bvh.forward_kinematics(b_names)[1:], b_names, [b for _, b in pairs])
    angle = np.degrees(np.arccos(np.clip((da * db).sum(-1), -1.0, 1.0)))
    assert np.median(angle, axis=0).max() < 9.0, np.median(angle, axis=0)
    assert np.percentile(angle, 90) < 15.0
