"""Joint maps (trainer/maps/*.toml): format, validation, and each map checked on real clips."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.bvh import read_bvh
from core.geometry import canonicalise
from core.skeleton import JOINT_INDEX, bone_lengths
from trainer.data.maps import MapError, load_map, load_maps

MAPS = Path(__file__).resolve().parents[2] / "trainer" / "maps"

def test_maps_load_and_validate(tmp_path: Path) -> None:
    maps = {m.source: m for m in load_maps(MAPS)}
    assert set(maps) == {"bandai-namco", "cmu-dance", "cmu-asf", "reactidle", "fair"}
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
