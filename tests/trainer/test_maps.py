"""Joint maps (trainer/maps/*.toml): format, validation, and each map checked on real clips."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.bvh import read_bvh
from core.geometry import canonicalise
from core.skeleton import JOINT_INDEX, bone_lengths
from tests.conftest import _ASF, _FAIR, _KAY
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


# ------------------------------------------------------------------ the multi-body archives


def _reader(more_mocap: Path, m: Any, rel: str) -> Any:
    from trainer.data.asf import read_amc, read_asf
    from trainer.data.sources import _all_files, pair_skeleton

    if m.reader == "asf":
        sk = read_asf(more_mocap / pair_skeleton(m, rel, _all_files(more_mocap)))
        return read_amc(more_mocap / rel, sk), sk.metres_per_unit
    return read_bvh(more_mocap / rel), None


def _world(more_mocap: Path, m: Any, rel: str) -> np.ndarray[Any, Any]:
    """World metres, +Y up, as the builder makes them (before resampling and canonicalising)."""
    from trainer.data.build import ClipJob, read_world

    skeleton = None
    if m.reader == "asf":
        from trainer.data.sources import _all_files, pair_skeleton

        skeleton = str(more_mocap / pair_skeleton(m, rel, _all_files(more_mocap)))
    job = ClipJob(str(more_mocap / rel), rel, f"{m.source}:{rel}", m, skeleton)
    return read_world(job)[0]


def test_every_new_map_maps_all_21_joints_on_its_real_files(more_mocap: Path) -> None:
    from tests.conftest import MORE_MOCAP

    maps = {m.source: m for m in load_maps(MAPS)}
    archives = {m.archive: m for m in maps.values()}
    for archive, members in MORE_MOCAP.items():
        m = archives[archive]
        clips = [r for r in members if m.selects(r)]
        assert clips, archive
        for rel in clips:
            joints = m.joints_for(rel)
            assert len(joints) == 21
            clip, _ = _reader(more_mocap, m, rel)
            missing = {n for j in joints for n in j.names} - set(clip.joint_names)
            assert not missing, (rel, missing)
            world = _world(more_mocap, m, rel)
            assert world.shape[1:] == (21, 3) and np.isfinite(world).all()
    # The edited duplicate is not a clip; the others are.
    asf = maps["cmu-asf"]
    assert not asf.selects(f"{_ASF}/124_02 - Copy.amc")
    assert asf.selects(f"{_ASF}/124_02.amc")


def test_cmu_asf_pairs_each_amc_with_its_subjects_asf(more_mocap: Path) -> None:
    from trainer.data.sources import _all_files, pair_skeleton

    m = load_map(MAPS / "cmu_asf.toml")
    files = _all_files(more_mocap)
    assert pair_skeleton(m, f"{_KAY}/07_05-walk.amc", files) == f"{_KAY}/07-walk.asf"
    assert pair_skeleton(m, f"{_ASF}/10_01.amc", files) == f"{_ASF}/10.asf"  # not 124.asf
    with pytest.raises(MapError, match="match no file"):
        pair_skeleton(m, f"{_ASF}/64_01.amc", files)
    info = m.clip_info(f"{_KAY}/07_05-walk.amc")
    assert (info.name, info.content, info.actor) == ("cmu-asf/07_05", "walk", "07")
    assert m.fps_for(f"{_ASF}/10_01.amc", 0.0) == 120.0  # AMC has no rate: CMU's 120 Hz
    assert m.is_holdout(f"{_ASF}/124_02.amc") and not m.is_holdout(f"{_ASF}/10_01.amc")
    # metres = ASF units x 0.0254 / 0.45: a thigh of 0.39-0.45 m (README).
    sk = _reader(more_mocap, m, f"{_ASF}/16_01.amc")[0].skeleton
    assert 0.39 < sk.bone_lengths()["lfemur"] * sk.metres_per_unit < 0.45


def test_fair_child_is_inches_z_up_and_child_sized(more_mocap: Path) -> None:
    """fair1 (inches, +Z up) comes out in metres, +Y up, facing +Z with left at +X, a child's
    height; cmu1/jumping_jacks (ASF units, +Y up, other names) through its override."""
    m = load_map(MAPS / "fair.toml")
    j = JOINT_INDEX
    for rel, fps, lo, hi in [
        (f"{_FAIR}/fair1/dab.bvh", 30.0, 0.85, 1.2),
        (f"{_FAIR}/fair1/wave_hello.bvh", 120.0, 0.75, 1.1),
        (f"{_FAIR}/cmu1/jumping_jacks.bvh", 30.0, 1.35, 1.7),
    ]:
        assert m.fps_for(rel, 0.0) == fps
        pos = canonicalise(_world(more_mocap, m, rel))
        head = pos[:, j["head"], 1] - pos[:, [j["left_foot"], j["right_foot"]], 1].min(axis=1)
        assert lo < np.median(head) < hi, (rel, np.median(head))  # head joint above the toes
        assert (pos[:, j["left_hip"], 0] > 0).all()
        assert _toes_forward(pos) > 0.9, rel
    info = m.clip_info(f"{_FAIR}/fair1/wave_hello.bvh")
    assert (info.source, info.actor) == ("fair", "fair1-b")
    assert m.clip_info(f"{_FAIR}/cmu1/jumping_jacks.bvh").actor == "cmu1"
    assert m.is_holdout(f"{_FAIR}/fair1/dab.bvh")


def test_reactidle_floor_spine2_and_collars(more_mocap: Path) -> None:
    m = load_map(MAPS / "reactidle.toml")
    rel = "reactidle_bvh/Enekoassets+ReActIdle@90b0ac7/genuine/002_genuine.bvh"
    world = _world(more_mocap, m, rel)
    j = JOINT_INDEX
    # root_position = "add": the toes on the floor, the pelvis at a standing height
    # (person 002 is among the smallest: thigh 0.33 m).
    lowest = world[:, :, 1].min(axis=1)
    assert np.abs(lowest).max() < 0.05
    assert 0.65 < world[:, j["pelvis"], 1].mean() < 1.05
    # spine2 is 35 % of the way from spine1 to the neck; collars off the midline.
    spine2 = world[:, j["spine1"]] + 0.35 * (world[:, j["neck"]] - world[:, j["spine1"]])
    np.testing.assert_allclose(world[:, j["spine2"]], spine2, atol=1e-9)
    canon = canonicalise(world)
    assert (canon[:, j["left_collar"], 0] > 0).all() and (canon[:, j["right_collar"], 0] < 0).all()
    assert np.median(canon[:, j["left_collar"], 0] - canon[:, j["right_collar"], 0]) > 0.06
    assert _toes_forward(canon) > 0.95
    info = m.clip_info(rel)
    assert (info.name, info.content, info.style, info.actor) == (
        "reactidle/genuine/002",
        "idle",
        "genuine",
        "002",
    )


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace("at = 0.25", "at = 1.5", 1), "0 <= at <= 1"),
        (lambda t: t.replace('"thorax", "lclavicle"', '"thorax"', 1), "part-way joint"),
        (lambda t: t.replace('content = "walk"', 'colour = "walk"'), "unknown keys ['colour']"),
        (lambda t: t.replace('reader = "asf"', 'reader = "bvh"'), "'skeleton' is only for"),
        (
            lambda t: t.replace('reader = "asf"', 'reader = "bvh"').replace("skeleton =", "#"),
            "unit 'asf' needs reader",
        ),
        (lambda t: t.replace('reader = "asf"', 'reader = "c3d"'), "'reader' must be one of"),
        (lambda t: t.replace("format = 2", "format = 1"), "rename [[fps_override]]"),
        (lambda t: t.replace("skeleton = [", "# skeleton = ["), "needs skeleton"),
        (lambda t: t.replace("fps = 120", "fps = -1"), "fps must be > 0, got -1"),
        # tomllib reads 1e999 as inf: it was a frame rate, and a unit of infinite metres
        (lambda t: t.replace("fps = 120", "fps = 1e999"), "fps must be a finite number, got 1e999"),
        (lambda t: t.replace("fps = 120", "fps = nan"), "fps must be a finite number, got nan"),
        (
            lambda t: t.replace('unit = "asf"', "unit = 1e999"),
            "metres per unit (a finite number > 0), got 1e999",
        ),
        (lambda t: t.replace('split = "train"', 'split = "holdout"'), "split must be one of"),
        # a studio audit (2026-12-07): the value received, the key meant
        (
            lambda t: t.replace('up_axis = "+Y"', 'up_axis = "-Z"'),
            "'up_axis' must be one of ['+Y', '+Z'], got '-Z'",
        ),
        (
            lambda t: t.replace('up_axis = "+Y"', 'up_axis = "+z"'),
            "got '+z'; did you mean '+Z'?",
        ),
        (
            lambda t: t.replace('up_axis = "+Y"', 'up_axis = "+Y"\nframe_rate = 60'),
            "unknown keys ['frame_rate']; known: ['archive', 'description', 'exclude', "
            "'format', 'holdout', 'include', 'joints', 'licence', 'metadata', 'override', "
            "'reader', 'root_position', 'skeleton', 'source', 'swap_sides', 'unit', 'up_axis']; "
            "'frame_rate': did you mean 'fps'? it is set per file, in an [[override]] (for "
            'every file: glob = "**", fps = ...)',
        ),
        (
            lambda t: t.replace("licence =", "license ="),
            "unknown keys ['license']; known: ['archive', 'description', 'exclude', 'format', "
            "'holdout', 'include', 'joints', 'licence', 'metadata', 'override', 'reader', "
            "'root_position', 'skeleton', 'source', 'swap_sides', 'unit', 'up_axis']; "
            "'license': did you mean 'licence'?",
        ),
    ],
)
def test_bad_new_map_keys_are_named(tmp_path: Path, edit: Any, message: str) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(edit((MAPS / "cmu_asf.toml").read_text()))
    with pytest.raises(MapError) as info:
        load_map(bad)
    assert message in str(info.value)
    assert str(bad) in str(info.value)


def test_maps_are_read_from_a_folder_or_one_file(tmp_path: Path) -> None:
    """``--maps`` given a map file said "no *.toml joint maps found": one file is its map."""
    one = sorted(MAPS.glob("*.toml"))[0]
    assert [m.source for m in load_maps(one)] == [load_map(one).source]
    with pytest.raises(MapError, match="no such folder"):
        load_maps(tmp_path / "missing")
    with pytest.raises(MapError, match=r"no \*\.toml joint maps found"):
        load_maps(tmp_path)


def test_the_service_maps_each_source_to_the_points_its_training_map_makes(
    bvh_files: dict[str, Path],
) -> None:
    """One definition of each canonical point: a real file of every BVH source, mapped by
    the service's automatic map (``core.characters_maps``), gives the points its training
    map (trainer/maps/*.toml) builds the dataset from. It did not for ReActIdle: the service
    put its chest half-way up the one spine bone, the map (and the training bodies) 0.35
    of the way; 3.5 cm apart."""
    from core.bvh_write import pose_of, skeleton_of
    from core.characters import forward_kinematics
    from core.characters_maps import resolve_map
    from tests.character_files import FILES
    from trainer.data.maps import joint_positions

    maps = load_maps(MAPS)
    sources = set()
    for name, (_, member, _, frame) in FILES.items():
        (mocap_map,) = [m for m in maps if m.selects(member)]
        sources.add(mocap_map.source)
        clip = read_bvh(bvh_files[name])
        wanted = joint_positions(clip, mocap_map.joints_for(member), np.array([frame]))[0]
        skel = skeleton_of(clip)
        served = resolve_map(skel).points(*forward_kinematics(skel, pose_of(clip, frame)))
        metres = (wanted - served) * mocap_map.scale_for(member)
        np.testing.assert_allclose(metres, 0.0, rtol=0, atol=1e-9, err_msg=name)
    assert sources == {"bandai-namco", "cmu-dance", "fair", "reactidle"}  # cmu-asf: ASF/AMC


def test_a_template_field_not_a_pattern_group_is_a_map_error(tmp_path: Path) -> None:
    """`actor = "{actr}"` skipped every file at build time ("... actor = '{actr}': 'actr'");
    now the map is refused when read, naming the field and the pattern's groups. A map
    without `format` said "format = None"."""
    bad = tmp_path / "bad.toml"
    text = (MAPS / "reactidle.toml").read_text()
    bad.write_text(text.replace('actor = "{person}"', 'actor = "{persn}"'))
    with pytest.raises(MapError) as info:
        load_map(bad)
    assert str(info.value) == (
        f"{bad}: [metadata] actor = '{{persn}}': {{persn}} is not a group of the [metadata] "
        "pattern; its groups are ['style', 'person', 'source', 'dir']; did you mean 'person'?"
    )
    fair = (MAPS / "fair.toml").read_text()
    bad.write_text(fair.replace('actor = "fair1-a"', 'actor = "{folder}-{clp}"'))
    with pytest.raises(MapError, match=r"\[\[override\]\] #3 actor = '\{folder\}-\{clp\}'"):
        load_map(bad)
    bad.write_text(text.replace("format = 2\n", ""))
    with pytest.raises(MapError) as info:
        load_map(bad)
    assert str(info.value) == f"{bad}: missing `format = 2` (the map format's version)"


def test_two_canonical_joints_from_one_source_joint_is_a_map_error(tmp_path: Path) -> None:
    """``right_wrist = "Hand_L"`` (a copy-paste slip) was accepted: the build kept a
    dataset whose right wrist sat on the left hand (5/6 of the frames dropped as
    ``bone_length``, no warning); ``spine2 = "Spine"`` kept a zero-length bone."""
    text = (MAPS / "bandai_namco.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace('right_wrist = "Hand_R"', 'right_wrist = "Hand_L"'))
    with pytest.raises(MapError) as info:
        load_map(bad)
    assert str(info.value) == (
        f"{bad}: [joints] right_wrist = 'Hand_L' is also left_wrist's source joint: "
        "each canonical joint needs a source joint of its own"
    )
    bad.write_text(text.replace('spine2 = "Chest"', 'spine2 = "Spine"'))
    with pytest.raises(MapError, match=r"\[joints\] spine2 = 'Spine' is also spine1's"):
        load_map(bad)
    # an override's joints, merged with the map's, are checked the same way
    over = '[[override]]\nglob = "**/x*.bvh"\njoints.neck = "Head"\n\n[metadata]'
    bad.write_text(text.replace("[metadata]", over, 1))
    with pytest.raises(MapError, match=r"\[\[override\]\] #1 joints.neck = 'Head' is also head's"):
        load_map(bad)
    # a swap of two joints in an override is fine: each still has a source of its own
    swap = over.replace("\n\n[metadata]", '\njoints.head = "Neck"\n\n[metadata]')
    bad.write_text(text.replace("[metadata]", swap, 1))
    load_map(bad)


def test_an_asf_map_without_a_frame_rate_is_warned_of(tmp_path: Path) -> None:
    """AMC files carry no frame rate: a map that sets none for them has them read at
    CMU's 120 Hz, now said (a studio audit, 2026-12-07: a studio's own AMC was read at 120
    without a word); the shipped CMU map sets it, and a BVH map has nothing to set."""
    from trainer.data.checks import amc_rate_warning

    shipped = Path(__file__).resolve().parents[2] / "trainer/maps/cmu_asf.toml"
    files = ["subjects/07/07_01.amc", "subjects/07/07.asf"]
    assert amc_rate_warning(load_map(shipped), files) is None
    text = shipped.read_text().replace('[[override]]\nglob = "**"\nfps = 120\n', "")
    assert text != shipped.read_text()
    (tmp_path / "studio.toml").write_text(text)
    said = amc_rate_warning(load_map(tmp_path / "studio.toml"), files)
    assert said is not None and "1 AMC file(s) read at 120 Hz" in said, said
    assert "subjects/07/07_01.amc" in said and "[[override]]" in said
    bvh = load_map(Path(__file__).resolve().parents[2] / "trainer/maps/fair.toml")
    assert amc_rate_warning(bvh, ["a.bvh"]) is None
