"""BVH reader, forward kinematics and joint maps (hand-computed and real clips)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.bvh import BVHError, parse_bvh, read_bvh
from core.geometry import canonicalise
from core.skeleton import JOINT_INDEX, bone_lengths
from trainer.data.maps import MapError, load_map, load_maps

MAPS = Path(__file__).resolve().parents[2] / "trainer" / "maps"

# Root: 6 channels (position + Z X Y rotation), child 10 up, end site 5 up the child.
TINY = """HIERARCHY
ROOT root
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT child
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 4
Frame Time: 0.0333333
1 2 3 0 0 0 0 0 0
1 2 3 90 0 0 0 90 0
0 0 0 90 90 0 0 0 0
0 0 0 0 0 0 0 0 90
"""


def test_fk_matches_hand_computed_poses(tmp_path: Path) -> None:
    path = tmp_path / "tiny.bvh"
    path.write_text(TINY)
    bvh = read_bvh(path)
    assert bvh.joint_names == ("root", "child", "child_end")
    assert bvh.num_frames == 4
    assert bvh.num_channels == 9
    assert bvh.fps == pytest.approx(30.0, rel=1e-5)
    pos = bvh.forward_kinematics()
    expected = np.array(
        [
            # rest: root at its position channels, child 10 up, end 5 further up.
            [[1, 2, 3], [1, 12, 3], [1, 17, 3]],
            # root Rz(90) turns the child offset (0,10,0) to (-10,0,0); the child's Rx(90)
            # turns the end offset (0,5,0) to (0,0,5), and Rz(90) leaves +Z alone.
            [[1, 2, 3], [-9, 2, 3], [-9, 2, 8]],
            # intrinsic Z then X: R = Rz(90) @ Rx(90); Rx takes (0,10,0) to (0,0,10), Rz keeps
            # it. (The extrinsic reading, Rx @ Rz, would give (-10, 0, 0).)
            [[0, 0, 0], [0, 0, 10], [0, 0, 15]],
            # a child yaw does not move its own end site along its Y axis.
            [[0, 0, 0], [0, 10, 0], [0, 15, 0]],
        ],
        dtype=float,
    )
    np.testing.assert_allclose(pos, expected, atol=1e-9)
    # Subsets and frame selection give the same numbers.
    np.testing.assert_allclose(
        bvh.forward_kinematics(["child_end"], frames=slice(1, 3)), expected[1:3, 2:3], atol=1e-9
    )


def test_position_channels_replace_offsets_and_any_channel_order() -> None:
    text = """HIERARCHY
ROOT a
{
  OFFSET 100 100 100
  CHANNELS 6 Yrotation Xposition Zposition Yposition Xrotation Zrotation
  JOINT b
  {
    OFFSET 50 50 50
    CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 1 0 0
    }
  }
}
MOTION
Frames: 1
Frame Time: 0.01
90 1 3 2 0 0 0 10 0 0 0 0
"""
    bvh = parse_bvh(text, "order.bvh")
    assert bvh.joints[0].rotation_order == "YXZ"
    pos = bvh.forward_kinematics()
    # root at (1, 2, 3) (offset replaced), rotated Ry(90): x -> -z, z -> x.
    # b's offset replaced by (0, 10, 0) -> unchanged by Ry; end (1,0,0) -> (0,0,-1).
    np.testing.assert_allclose(pos[0], [[1, 2, 3], [1, 12, 3], [1, 12, 2]], atol=1e-9)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda t: t.replace("MOTION", "MOTON"), "missing MOTION section"),
        (
            lambda t: t[: t.rindex("0 0 0 0 0 0 0 0 90")] + "0 0 0 0\n",
            "line 22: expected 9 values per frame, got 4",
        ),
        (lambda t: t.replace("Frames: 4", "Frames: 5"), "declares 5 frames, found 4"),
        (lambda t: t.replace("Frames: 4", "Frames: 3"), "more frame lines than the 3"),
        (
            lambda t: t.replace("1 2 3 90 0 0 0 90 0", "1 2 3 90 x 0 0 90 0"),
            "line 20: not a number",
        ),
        (lambda t: t.replace("CHANNELS 3 Zrotation", "CHANNELS 3 Wrotation"), "unknown channel"),
        (lambda t: t.replace("  }\n}\nMOTION", "MOTION"), "unexpected end of HIERARCHY"),
        (lambda t: "garbage\x00\x01 not a bvh at all", "not a BVH file"),
        (lambda t: t.replace("Frame Time: 0.0333333", "Frame Time: 0"), "bad Frame Time"),
    ],
)
def test_malformed_files_raise_bvherror_naming_file_and_reason(
    tmp_path: Path, mutate: Any, message: str
) -> None:
    path = tmp_path / "broken.bvh"
    path.write_text(mutate(TINY))
    with pytest.raises(BVHError) as info:
        read_bvh(path)
    assert message in str(info.value)
    assert str(path) in str(info.value)
    assert info.value.file == str(path)


def test_maps_load_and_validate(tmp_path: Path) -> None:
    maps = {m.source: m for m in load_maps(MAPS)}
    assert set(maps) == {"bandai-namco", "cmu-dance"}
    cmu = maps["cmu-dance"]
    assert cmu.scale == pytest.approx(0.01)
    assert cmu.selects("train_data_bvh/salsa/01.bvh")
    assert not cmu.selects("train_data_bvh/standard.bvh")
    assert cmu.fps_for("train_data_bvh/salsa/01.bvh", 120.0) == 60.0
    assert cmu.fps_for("train_data_bvh/martial/04.bvh", 120.0) == 120.0
    info = cmu.clip_info("train_data_bvh/salsa/01.bvh")
    assert (info.name, info.content, info.style) == ("cmu-dance/salsa/01", "salsa", "")
    bandai = maps["bandai-namco"]
    info = bandai.clip_info(
        "dataset/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk-turn-left_active_003.bvh"
    )
    assert info.name == "bandai-namco/dataset-2_walk-turn-left_active_003"
    assert (info.content, info.style, info.actor) == ("walk-turn-left", "active", "")

    bad = tmp_path / "bad.toml"
    text = (MAPS / "cmu_dance.toml").read_text()
    bad.write_text(text.replace('left_knee = "lShin"\n', ""))
    with pytest.raises(MapError, match="missing \\['left_knee'\\]"):
        load_map(bad)
    bad.write_text(text.replace('unit = "cm"', 'unit = "furlong"'))
    with pytest.raises(MapError, match="'unit'"):
        load_map(bad)


def _canonical(path: Path, map_file: Path, swap: bool = False) -> np.ndarray[Any, Any]:
    m = load_map(map_file)
    if swap:
        from dataclasses import replace

        m = replace(m, swap_sides=True)
    world = read_bvh(path).forward_kinematics(m.source_joints) * m.scale
    return np.asarray(canonicalise(world))


def _toes_forward(pos: np.ndarray[Any, Any]) -> float:
    """Fraction of (frame, side) where the toe is ahead (+Z) of the ankle."""
    j = JOINT_INDEX
    left = pos[:, j["left_foot"], 2] > pos[:, j["left_ankle"], 2]
    right = pos[:, j["right_foot"], 2] > pos[:, j["right_ankle"], 2]
    return float(np.concatenate([left, right]).mean())


def test_left_right_convention_of_both_sources(mocap_clips: Any) -> None:
    """After canonicalisation left is +X *by construction* (facing comes from left - right),
    so a swapped map shows up as a character facing -Z: toes behind the ankles. Check that
    the shipped maps face +Z and that swapping the sides is caught."""
    j = JOINT_INDEX
    cases = [
        (mocap_clips.bandai[2], MAPS / "bandai_namco.toml"),
        (mocap_clips.cmu[0], MAPS / "cmu_dance.toml"),
    ]
    for path, map_file in cases:
        pos = _canonical(path, map_file)
        assert (pos[:, j["left_hip"], 0] > 0).all(), path
        assert (pos[:, j["left_shoulder"], 0] > pos[:, j["right_shoulder"], 0]).mean() > 0.95
        assert _toes_forward(pos) > 0.8, f"{path}: toes point backwards: sides swapped?"
        swapped = _canonical(path, map_file, swap=True)
        assert _toes_forward(swapped) < 0.2, f"{path}: a swapped map went unnoticed"


def test_cmu_first_frame_is_a_t_pose_with_left_at_plus_x(mocap_clips: Any) -> None:
    pos = _canonical(mocap_clips.cmu[0], MAPS / "cmu_dance.toml")[0]
    j = JOINT_INDEX
    assert pos[j["left_wrist"], 0] > 0.5
    assert pos[j["right_wrist"], 0] < -0.5
    # arms horizontal: wrists at shoulder height
    assert abs(pos[j["left_wrist"], 1] - pos[j["left_shoulder"], 1]) < 0.1
    assert pos[j["head"], 1] > pos[j["pelvis"], 1] > pos[j["left_knee"], 1]


def test_real_bandai_clip(mocap_clips: Any) -> None:
    bvh = read_bvh(mocap_clips.bandai[0])
    assert bvh.fps == pytest.approx(30.0, rel=1e-3)
    assert bvh.num_channels == 22 * 6  # joint_Root + 21 joints, 6 channels each
    assert "Toes_L_end" in bvh.joint_names
    m = load_map(MAPS / "bandai_namco.toml")
    world = bvh.forward_kinematics(m.source_joints) * m.scale
    lengths = bone_lengths(world)
    # Bone lengths are constant within a clip (position channels equal the offsets).
    assert np.ptp(lengths, axis=0).max() < 1e-4
    assert 1.2 < world[:, JOINT_INDEX["head"], 1].mean() < 1.8  # head joint of an adult, m


def test_real_cmu_clip(mocap_clips: Any) -> None:
    bvh = read_bvh(mocap_clips.cmu[0])
    assert bvh.fps == pytest.approx(120.0, rel=1e-3)  # header (salsa is really 60)
    assert bvh.joints[0].rotation_order == "ZYX"
    assert bvh.joints[1].rotation_order == "ZXY"
    assert {"lFoot_end", "rFoot_end"} <= set(bvh.joint_names)
    m = load_map(MAPS / "cmu_dance.toml")
    lengths = bone_lengths(bvh.forward_kinematics(m.source_joints, frames=slice(0, None, 50)))
    assert np.ptp(lengths, axis=0).max() < 1e-6 * 100  # rotation-only joints: rigid bones


def test_docs_example_map_is_valid(tmp_path: Path) -> None:
    docs = (MAPS.parents[1] / "docs" / "data.md").read_text()
    example = docs.split("```toml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "studio_x.toml").write_text(example)
    m = load_map(tmp_path / "studio_x.toml")
    assert (m.scale, m.up_axis) == (0.001, "+Z")
    np.testing.assert_allclose(m.up_matrix @ [0.0, 0.0, 1.0], [0.0, 1.0, 0.0])  # Z-up -> Y-up
    assert m.selects("takes/anna/jump_01.bvh")
    assert not m.selects("takes/anna/tpose_01.bvh")
    assert m.fps_for("takes/old/jump_01.bvh", 120.0) == 50.0
    info = m.clip_info("takes/anna/jump_01.bvh")
    assert (info.name, info.content, info.actor) == ("studio-x/anna/jump_01", "jump", "anna")
