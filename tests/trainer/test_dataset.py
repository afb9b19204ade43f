"""Dataset builder, file format, loader, splits and the CLI (real clips)."""

from __future__ import annotations

import json
import pickle
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.bvh import read_bvh
from core.geometry import canonicalise, yaw_matrix
from core.skeleton import JOINT_INDEX, NUM_JOINTS, bone_lengths
from trainer.data.build import (
    DROP_REASONS,
    assign_splits,
    build_dataset,
    drop_reasons,
    interpolate_positions,
    resample_indices,
)
from trainer.data.dataset import KEYS, SPLITS, DatasetError, load_dataset
from trainer.data.maps import load_map

MAPS = Path(__file__).resolve().parents[2] / "trainer" / "maps"


def test_small_dataset_format(small_dataset: Path) -> None:
    with np.load(small_dataset, allow_pickle=False) as npz:
        assert sorted(npz.files) == sorted(KEYS)
    ds = load_dataset(small_dataset)
    assert ds.positions.dtype == np.float32
    assert ds.positions.shape == (len(ds), NUM_JOINTS, 3)
    assert ds.clip.dtype == np.int32
    assert ds.frame.dtype == np.int32
    assert ds.num_clips == 11  # 7 Bandai + 4 CMU; standard.bvh is not a clip
    assert "cmu-dance/salsa/01" in ds.clip_name.tolist()
    assert "bandai-namco/dataset-2_walk_active_001" in ds.clip_name.tolist()
    assert not any("standard" in n for n in ds.clip_name.tolist())
    assert set(ds.clip_source.tolist()) == {"bandai-namco", "cmu-dance"}
    meta = ds.meta
    assert meta["format_version"] == 2
    assert meta["fps"] == 30
    assert meta["seed"] == 0
    assert set(meta["dropped_frames"]) == set(DROP_REASONS)
    assert {m["source"] for m in meta["maps"]} == {"bandai-namco", "cmu-dance"}
    assert all(a["kind"] == "folder" for a in meta["archives"])
    # a folder source is hashed by its files (the manifest named it with the sha256 "None")
    assert all(a["files"] > 0 and len(a["files_sha256"]) == 64 for a in meta["archives"])
    bones = meta["mean_bone_lengths_m"]["bandai-namco"]
    assert 0.3 < bones["left_knee"] < 0.5  # thigh, metres
    assert meta["build_seconds"] > 0
    # Canonical frame: pelvis above the origin, upright.
    pelvis = ds.positions[:, JOINT_INDEX["pelvis"]]
    np.testing.assert_allclose(pelvis[:, [0, 2]], 0.0, atol=1e-5)
    assert (ds.positions[:, JOINT_INDEX["head"], 1] > pelvis[:, 1]).mean() > 0.99


def test_world_poses_keep_root_motion_and_facing(small_dataset: Path) -> None:
    """world() puts every frame back where it was recorded: canonicalising it gives the
    stored pose again, and a clip's pelvis moves continuously (no jump back to the origin)."""
    ds = load_dataset(small_dataset)
    world = ds.world()
    np.testing.assert_allclose(canonicalise(world), ds.positions, atol=1e-5)
    np.testing.assert_allclose(world[:, JOINT_INDEX["pelvis"], 1], ds.positions[:, 0, 1], atol=1e-6)
    same = np.flatnonzero((ds.clip[1:] == ds.clip[:-1]) & (np.diff(ds.frame) == 1))
    step = np.linalg.norm(world[same + 1, 0] - world[same, 0], axis=-1)
    assert step.max() < 0.2  # metres per 1/30 s
    travelled = [np.ptp(world[ds.clip == c, 0, 0]) for c in range(ds.num_clips)]
    assert max(travelled) > 1.0  # someone walks: root motion is kept
    assert np.ptp(ds.yaw) > 3.0  # and turns: facing is kept


def test_bone_lengths_constant_within_a_bandai_clip(small_dataset: Path) -> None:
    ds = load_dataset(small_dataset)
    for c in np.flatnonzero(ds.clip_source == "bandai-namco"):
        lengths = bone_lengths(ds.positions[ds.clip == c])
        assert np.ptp(lengths, axis=0).max() < 1e-4, ds.clip_name[c]


def test_resampling_gives_30_fps(small_dataset: Path, mocap_clips: Any) -> None:
    ds = load_dataset(small_dataset)
    names = ds.clip_name.tolist()
    cases = [
        ("cmu-dance/salsa/01", "train_data_bvh/salsa/01.bvh", 2),  # 60 fps (header says 120)
        ("cmu-dance/martial/04", "train_data_bvh/martial/04.bvh", 4),  # 120 fps
        (
            "bandai-namco/dataset-2_walk_normal_001",
            "dataset/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh",
            1,
        ),
    ]
    for name, member, k in cases:
        n_source = read_bvh(mocap_clips.path(member)).num_frames
        frames = ds.frame[ds.clip == names.index(name)]
        assert len(frames) == -(-n_source // k), name  # ceil: frames 0, k, 2k, ...
        np.testing.assert_array_equal(frames, np.arange(len(frames)))
    # A 60 fps salsa clip lasts as long at 30 fps as at 60 fps: about 37 s for salsa/01.
    salsa = ds.frame[ds.clip == names.index("cmu-dance/salsa/01")]
    assert len(salsa) / 30 == pytest.approx(read_bvh(mocap_clips.cmu[0]).num_frames / 60, abs=0.1)


def test_non_integer_ratio_interpolates_linearly() -> None:
    assert resample_indices(121, 120.0) == (4, 31)
    assert resample_indices(5, 30.0) == (1, 5)
    k, n_out = resample_indices(6, 50.0)  # 0.1 s of 50 fps: t = 0, 1/30, 2/30, 3/30
    assert (k, n_out) == (0, 4)
    src = np.arange(6, dtype=float)[:, None, None] * np.ones((1, 2, 3))  # value = frame index
    out = interpolate_positions(src, 50.0)
    np.testing.assert_allclose(out[:, 0, 0], [0.0, 5 / 3, 10 / 3, 5.0])


def test_drop_rule() -> None:
    rng = np.random.default_rng(0)
    base = rng.normal(size=(1, NUM_JOINTS, 3)) * 0.3
    world = np.repeat(base, 10, axis=0) + np.linspace(0, 0.1, 10)[:, None, None]
    world[2, 3, 1] = np.nan  # non-finite
    world[5:] += np.array([2.0, 0.0, 0.0])  # teleport at frame 5 (then a steady shift)
    world[8, JOINT_INDEX["left_wrist"]] += 0.2  # stretched forearm
    codes = drop_reasons(world)
    names = ["keep", *DROP_REASONS]
    assert [names[c] for c in codes] == [
        "keep",
        "keep",
        "non_finite",
        "keep",
        "keep",
        "teleport",
        "keep",
        "keep",
        "bone_length",
        "keep",
    ]


def test_canonicalisation_invariant_to_yaw_and_translation(mocap_clips: Any) -> None:
    m = load_map(MAPS / "bandai_namco.toml")
    world = read_bvh(mocap_clips.bandai[2]).forward_kinematics(m.source_joints) * m.scale
    rng = np.random.default_rng(1)
    yaw = rng.uniform(-np.pi, np.pi, size=len(world))
    shift = rng.uniform(-5, 5, size=(len(world), 3))
    shift[:, 1] = 0.0  # horizontal: the floor stays at y = 0
    moved = np.einsum("fij,fkj->fki", yaw_matrix(yaw), world) + shift[:, None, :]
    np.testing.assert_allclose(canonicalise(moved), canonicalise(world), atol=1e-6)
    # ... but not to a vertical shift (the floor is y = 0).
    assert not np.allclose(canonicalise(world + np.array([0.0, 0.5, 0.0])), canonicalise(world))


def test_real_frames_have_left_at_plus_x_and_face_plus_z(small_dataset: Path) -> None:
    ds = load_dataset(small_dataset)
    j = JOINT_INDEX
    for source in ("bandai-namco", "cmu-dance"):
        pos = ds.positions[ds.source_mask(source)]
        assert (pos[:, j["left_hip"], 0] > 0).all(), source
        toes = np.concatenate(
            [
                pos[:, j["left_foot"], 2] > pos[:, j["left_ankle"], 2],
                pos[:, j["right_foot"], 2] > pos[:, j["right_ankle"], 2],
            ]
        )
        assert toes.mean() > 0.8, f"{source}: toes point backwards (swapped sides?)"


def test_splits_by_clip_stratified_and_seeded(small_dataset: Path) -> None:
    ds = load_dataset(small_dataset)
    masks = {s: ds.split_mask(s) for s in SPLITS}
    assert sum(m.sum() for m in masks.values()) == len(ds)
    clips = {s: set(ds.clip[m].tolist()) for s, m in masks.items()}
    assert not clips["train"] & clips["val"]
    assert not clips["train"] & clips["test"]
    assert not clips["val"] & clips["test"]
    assert all(clips[s] for s in ("train", "val", "test"))  # the fixture fills these
    # every source and content in test; in val where a stratum has >= 3 clips
    for source in set(ds.clip_source.tolist()):
        for content in set(ds.clip_content[ds.clip_source == source].tolist()):
            sel = (ds.clip_source == source) & (ds.clip_content == content)
            assert "test" in ds.clip_split[sel], (source, content)
            if sel.sum() >= 3:
                assert "val" in ds.clip_split[sel], (source, content)
    # reproducible from the seed, independent of clip order
    names, sources, contents = ds.clip_name, ds.clip_source, ds.clip_content
    again = assign_splits(names.tolist(), sources.tolist(), contents.tolist(), seed=0)
    np.testing.assert_array_equal(again, ds.clip_split)
    rev = np.arange(ds.num_clips)[::-1]
    shuffled = assign_splits(
        names[rev].tolist(), sources[rev].tolist(), contents[rev].tolist(), seed=0
    )
    np.testing.assert_array_equal(shuffled, ds.clip_split[rev])


def test_split_fractions_and_seed_dependence() -> None:
    names = [f"s/{c}/{i:03d}" for c in ("walk", "run", "bow") for i in range(100)]
    contents = [n.split("/")[1] for n in names]
    sources = ["s"] * len(names)
    a = assign_splits(names, sources, contents, seed=0)
    b = assign_splits(names, sources, contents, seed=0)
    c = assign_splits(names, sources, contents, seed=1)
    np.testing.assert_array_equal(a, b)
    assert (a != c).any()
    for content in ("walk", "run", "bow"):
        sel = np.array(contents) == content
        counts = {s: int((a[sel] == s).sum()) for s in SPLITS}
        assert counts == {"train": 90, "val": 5, "test": 5, "holdout": 0}
    tiny = assign_splits(["x/1", "y/1", "y/2"], ["s"] * 3, ["x", "y", "y"], seed=0)
    assert tiny[0] == "test"
    assert sorted(tiny[1:].tolist()) == ["test", "train"]


def test_subset_and_split_mask(small_dataset: Path) -> None:
    ds = load_dataset(small_dataset)
    test = ds.subset(ds.split_mask("test"))
    assert len(test) == int(ds.split_mask("test").sum())
    assert test.num_clips == ds.num_clips
    assert set(test.clip_split[test.clip].tolist()) == {"test"}
    with pytest.raises(ValueError, match="unknown split"):
        ds.split_mask("heldout")


def test_loader_rejects_bad_files(small_dataset: Path, tmp_path: Path) -> None:
    with np.load(small_dataset, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    with pytest.raises(DatasetError, match="no such dataset"):
        load_dataset(tmp_path / "missing.npz")
    # not a zip: a text file (numpy's reason was that it holds pickled data, to be loaded
    # unsafely), one array saved with np.save (a TypeError) (a studio audit, 2026-12-05)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with open(tmp_path / "array.npz", "wb") as f:
        np.save(f, arrays["positions"][:10])
    for junk in ("junk.npz", "array.npz"):
        with pytest.raises(DatasetError, match=f"{junk}: not a dataset file: a dataset is the"):
            load_dataset(tmp_path / junk)
    bad = dict(arrays)
    del bad["clip_actor"]
    np.savez(tmp_path / "missing_key.npz", **bad)
    with pytest.raises(DatasetError, match=r"missing \['clip_actor'\]"):
        load_dataset(tmp_path / "missing_key.npz")
    bad = dict(arrays, positions=arrays["positions"].astype(np.float64))
    np.savez(tmp_path / "dtype.npz", **bad)
    with pytest.raises(DatasetError, match="'positions' must be float32"):
        load_dataset(tmp_path / "dtype.npz")
    meta = json.loads(str(arrays["meta"]))
    bad = dict(arrays, meta=np.array(json.dumps(dict(meta, format_version=1))))
    np.savez(tmp_path / "version.npz", **bad)
    with pytest.raises(DatasetError, match="format_version"):
        load_dataset(tmp_path / "version.npz")


def test_broken_files_are_skipped_and_the_build_goes_on(mocap_clips: Any, tmp_path: Path) -> None:
    root = tmp_path / "mocap"
    data = root / "dataset/Bandai-Namco-Research-Motiondataset-1/data"
    data.mkdir(parents=True)
    good = mocap_clips.bandai[0]
    shutil.copy(good, data / good.name)
    text = good.read_text()
    (data / "dataset-1_walk_broken_001.bvh").write_text(text[: len(text) * 2 // 3])
    (data / "dataset-1_walk_garbage_001.bvh").write_bytes(b"\x00\x01garbage" * 100)
    report = build_dataset(root, tmp_path / "out.npz", workers=1, progress=False)
    skipped = {s["file"]: s["reason"] for s in report.meta["skipped_files"]}
    prefix = "bandai-namco:dataset/Bandai-Namco-Research-Motiondataset-1/data/"
    assert set(skipped) == {
        prefix + "dataset-1_walk_broken_001.bvh",
        prefix + "dataset-1_walk_garbage_001.bvh",
    }
    assert "expected 132 values per frame" in skipped[prefix + "dataset-1_walk_broken_001.bvh"]
    assert "dataset-1_walk_broken_001.bvh" in skipped[prefix + "dataset-1_walk_broken_001.bvh"]
    assert "not a BVH file" in skipped[prefix + "dataset-1_walk_garbage_001.bvh"]
    ds = load_dataset(tmp_path / "out.npz")
    assert ds.clip_name.tolist() == ["bandai-namco/dataset-1_walk_normal_001"]
    assert len(ds) == read_bvh(good).num_frames


def test_cli_dataset_and_plot(mocap_clips: Any, small_dataset: Path, tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from trainer.cli import app

    # a wide terminal: the refusals name a temp path, whose length varies (a pytest-xdist
    # worker's is longer) and which rich wrapped, mid-phrase, at 80 columns
    runner = CliRunner(env={"COLUMNS": "200"})
    png = tmp_path / "poses.png"
    result = runner.invoke(
        app, ["plot-data", "--dataset", str(small_dataset), "--out", str(png), "--per-source", "3"]
    )
    assert result.exit_code == 0, result.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    out = tmp_path / "cli.npz"
    result = runner.invoke(
        app, ["dataset", "--mocap", str(mocap_clips.root), "--out", str(out), "--seed", "3"]
    )
    assert result.exit_code == 0, result.output
    assert "bandai-namco" in result.output
    assert "mean bone lengths" in result.output
    ds = load_dataset(out)
    assert ds.meta["seed"] == 3
    assert ds.num_clips == 11
    result = runner.invoke(app, ["dataset", "--mocap", str(tmp_path / "nowhere")])
    assert result.exit_code == 1
    assert "not found" in result.output
    # --out a folder: refused before the build (it failed after it, a traceback)
    result = runner.invoke(
        app, ["dataset", "--mocap", str(mocap_clips.root), "--out", str(tmp_path)]
    )
    assert result.exit_code == 2 and "is a folder" in result.output, result.output
    assert "Traceback" not in result.output


def test_builder_reads_the_multi_body_archives_and_holds_out_what_the_maps_name(
    more_mocap: Path, mocap_dir: Path, tmp_path: Path
) -> None:
    """ASF/AMC, 6-channel BVH and inch/Z-up BVH in one build: the held-out clips (all of
    ReActIdle and AnimatedDrawings, CMU subjects 07 and 124 here) are in "holdout" and
    nothing else is; archive checksums are recorded; bodies are child- or adult-sized."""
    root = tmp_path / "mocap"
    for top in ("cmu_asfamc_subset", "reactidle_bvh", "animateddrawings_fair_bvh"):
        shutil.copytree(more_mocap / top, root / top)
    shutil.copy(mocap_dir / "SHA256SUMS", root / "SHA256SUMS")
    report = build_dataset(root, tmp_path / "p.npz", seed=0, workers=1, progress=False)
    ds = load_dataset(report.out)
    columns = (ds.clip_name, ds.clip_source, ds.clip_actor, ds.clip_split)
    table = {n: (s, a, sp) for n, s, a, sp in zip(*columns, strict=True)}
    held = {n for n, (_, _, sp) in table.items() if sp == "holdout"}
    assert held == {
        "cmu-asf/07_05",
        "cmu-asf/124_02",
        "reactidle/genuine/002",
        "reactidle/genuine/003",
        "fair/fair1/dab",
        "fair/fair1/wave_hello",
        "fair/cmu1/jumping_jacks",
    }
    assert "holdout" in SPLITS
    others = {n: t for n, t in table.items() if n not in held}
    assert set(others) == {"cmu-asf/10_01", "cmu-asf/16_01", "cmu-asf/16_05", "cmu-asf/135_06"}
    assert {t[2] for t in others.values()} <= {"train", "val", "test"}
    assert table["cmu-asf/135_06"][2] == "train"  # forced by the map (a cmu-dance take)
    assert table["cmu-asf/16_01"][1] == "16" and table["fair/fair1/wave_hello"][1] == "fair1-b"
    assert table["reactidle/genuine/002"][:2] == ("reactidle", "002")
    assert not any("Copy" in n for n in table)
    meta = ds.meta
    sums = {a["file"]: a["sha256"] for a in meta["archives"] if "sha256" in a}
    assert sums["cmu_asfamc_subset.tar.xz"].startswith("41e7874f")
    assert set(sums) == {
        "cmu_asfamc_subset.tar.xz",
        "reactidle_bvh.tar.xz",
        "animateddrawings_fair_bvh.tar.xz",
    }
    assert meta["holdout"]["reactidle"] == ["**"]
    assert sum(meta["dropped_frames"].values()) == 0
    # Bodies: a child's thigh, adults' thighs (metres), from the per-actor bone table.
    by_actor = meta["mean_bone_lengths_m_by_actor"]
    assert 0.25 < by_actor["fair"]["fair1-a"]["left_knee"] < 0.32
    assert 0.38 < by_actor["cmu-asf"]["16"]["left_knee"] < 0.45
    assert 0.3 < by_actor["reactidle"]["003"]["left_knee"] < 0.45
    # World poses are back on the floor, upright, at 30 fps.
    world = ds.world()
    assert np.abs(world[ds.source_mask("reactidle"), :, 1].min(axis=1)).max() < 0.05
    assert (ds.positions[:, JOINT_INDEX["head"], 1] > ds.positions[:, 0, 1]).all()


def test_the_licence_of_weights_is_their_data_s() -> None:
    """Every export was labelled with the shipped models' non-commercial licence, a
    studio's trained on its own data too."""
    from trainer.export import licence_of

    shipped = {
        "licences": {"bandai-namco": "CC BY-NC 4.0", "cmu-dance": "CMU terms", "fair": "MIT"},
        "holdout": {"fair": ["**"], "cmu-dance": ["**/07_*.amc"]},
    }
    text = licence_of(shipped)
    assert text.startswith("Non-commercial") and "bandai-namco: CC BY-NC 4.0" in text
    assert "cmu-dance: CMU terms" in text and "MIT" not in text  # fair: held out whole
    studio = licence_of({"licences": {"acme": "internal use only"}})
    assert "acme: internal use only" in studio and "CC BY-NC" not in studio
    assert not studio.startswith("Non-commercial")
    assert licence_of({}).startswith("not recorded")
    # a studio audit (2026-12-05): CC's own names of NC terms were missed, and a source
    # without a licence gave an empty term ("(studio-idle: )")
    for nc in ("Attribution-NonCommercial 4.0 International", "CC BY NC 4.0",
               "noncommercial research only", "CC-BY-NC-SA 4.0"):  # fmt: skip
        assert licence_of({"licences": {"acme": nc}}).startswith("Non-commercial: "), nc
    for free in ("CC BY 4.0", "MIT", "commercial use allowed"):
        assert not licence_of({"licences": {"acme": free}}).startswith("Non-commercial"), free
    assert "(acme: no licence given (its map names none))" in licence_of({"licences": {"acme": ""}})


def test_the_builder_warns_of_a_map_whose_units_up_axis_or_sides_look_wrong(
    small_dataset: Path,
) -> None:
    """Inches read as cm, +Z read as +Y and swapped sides built without a word (11 cm
    thighs, figures lying down, toes backwards): the summary now warns, per source."""
    import dataclasses

    from trainer.data.build import sanity_warnings

    ds = load_dataset(small_dataset)
    assert sanity_warnings(ds) == []
    small = dataclasses.replace(ds, positions=ds.positions * 0.39)
    assert any("thigh" in w and "unit" in w for w in sanity_warnings(small))
    lying = dataclasses.replace(ds, positions=ds.positions[..., [0, 2, 1]])
    assert any("head" in w and "up_axis" in w for w in sanity_warnings(lying))
    backwards = dataclasses.replace(ds, positions=ds.positions * np.array([-1, 1, -1], np.float32))
    assert any("swap_sides" in w for w in sanity_warnings(backwards))
    no_val = dataclasses.replace(
        ds, clip_split=np.where(ds.clip_split == "val", "test", ds.clip_split)
    )
    assert any("no val clips" in w for w in sanity_warnings(no_val))
    # without test clips training ran every stage, then failed in the evaluation
    no_test = dataclasses.replace(
        ds, clip_split=np.where(ds.clip_split == "test", "val", ds.clip_split)
    )
    assert "no test clips: training refuses this dataset (docs/data.md, splits)" in (
        sanity_warnings(no_test)
    )


# --------------------------------------------------------------------------- a studio's map
# Two real ReActIdle takes laid out as a studio's own folder (takes/<actor>/idle_01.bvh),
# read by a map written as docs/data.md tells a studio to, then broken one way at a time.

_REACTIDLE = "reactidle_bvh/Enekoassets+ReActIdle@90b0ac7/genuine"
STUDIO_MAP = """format = 2
source = "studio"
licence = "internal use only"
archive = "studio.tar.gz"
unit = "m"
root_position = "add"
include = ["takes/**/*.bvh"]

[metadata]
pattern = '^takes/(?P<actor>[^/]+)/(?P<content>[a-z]+)_(?P<take>[0-9]+)[.]bvh$'
name = "studio/{actor}/{content}_{take}"
content = "{content}"
actor = "{actor}"

"""


def _studio(more_mocap: Path, tmp_path: Path, edits: dict[str, str] | None = None) -> Path:
    """``tmp_path/mocap/studio/takes/p00{2,3}/idle_01.bvh`` and ``tmp_path/maps/studio.toml``
    (the ReActIdle joints); ``edits`` replace text of the map. Returns the maps folder."""
    for person in ("002", "003"):
        take = tmp_path / "mocap" / "studio" / "takes" / f"p{person}" / "idle_01.bvh"
        take.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(more_mocap / _REACTIDLE / f"{person}_genuine.bvh", take)
    joints = (MAPS / "reactidle.toml").read_text().split("[joints]")[1]
    text = STUDIO_MAP + "[joints]" + joints
    for old, new in (edits or {}).items():
        assert old in text, old
        text = text.replace(old, new, 1)
    maps = tmp_path / "maps"
    maps.mkdir(exist_ok=True)
    (maps / "studio.toml").write_text(text)
    return maps


def _build(tmp_path: Path, maps: Path | None) -> Any:
    out = tmp_path / "out.npz"
    return build_dataset(tmp_path / "mocap", out, maps_dir=maps, workers=1, progress=False)


def test_a_metadata_pattern_that_matches_no_file_fails_the_build(
    more_mocap: Path, tmp_path: Path
) -> None:
    """A studio audit (2026-12-05): a typo in the [metadata] pattern (``idel`` for
    ``idle``) skipped every file of the source one by one and the build exited 0 with the
    source gone (beside another map's clips). Like a joint name in none of its files, a
    MapError that names the map."""
    from trainer.data.maps import MapError

    typo = "(?P<content>[a-z]+)_(?P<take>[0-9]+)"
    maps = _studio(more_mocap, tmp_path, {typo: "(?P<content>idel)_(?P<take>[0-9]+)"})
    with pytest.raises(MapError) as info:
        _build(tmp_path, maps)
    said = str(info.value)
    assert said.startswith(f"map {maps / 'studio.toml'}: its [metadata] pattern matches none")
    assert "of its 2 files; the first: " in said


def test_what_the_poses_say_of_their_map_is_kept_in_the_dataset(
    more_mocap: Path, tmp_path: Path
) -> None:
    """A studio audit (2026-12-05): a map read in the wrong unit (4 mm thighs) was warned
    of in the summary only: ``meta["warnings"]`` (docs/data.md: "the build's warnings")
    held nothing of it, nor did the manifest trained from it. Now the dataset keeps it."""
    maps = _studio(more_mocap, tmp_path, {'unit = "m"': 'unit = "mm"'})
    report = _build(tmp_path, maps)
    said = [w for w in report.meta["warnings"] if "thigh" in w and "unit" in w]
    assert said, report.meta["warnings"]
    assert load_dataset(report.out).meta["warnings"] == report.meta["warnings"]


def test_a_joint_name_in_none_of_a_maps_files_fails_the_build(
    more_mocap: Path, tmp_path: Path
) -> None:
    """`forearm.l` for `forearm.L` skipped every file one by one; with an override's typo
    the build exited 0 with that body's data gone. Now a MapError naming the map, the key
    and the close name."""
    from typer.testing import CliRunner

    from trainer.cli import app
    from trainer.data.maps import MapError

    maps = _studio(more_mocap, tmp_path, {'left_elbow = "forearm.L"': 'left_elbow = "forearm.l"'})
    with pytest.raises(MapError) as info:
        _build(tmp_path, maps)
    assert str(info.value) == (
        f"map {maps / 'studio.toml'}: [joints] left_elbow = 'forearm.l' is in none of its "
        "2 files; did you mean 'forearm.L'?"
    )
    typo = '[[override]]\nglob = "takes/p003/*"\njoints.left_elbow = "forearm_L"\n\n[metadata]'
    maps = _studio(more_mocap, tmp_path, {"[metadata]": typo})
    args = ["dataset", "--mocap", str(tmp_path / "mocap"), "--maps", str(maps)]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "cli.npz")])
    assert result.exit_code == 1, result.output
    assert "[[override]] #1 joints.left_elbow = 'forearm_L' is in none of" in result.output
    assert "did you mean 'forearm.L'?" in result.output
    # each file's "skipped ... not in the file" line came first, one per file (a studio
    # audit, D12: ten lines before the one that says what is wrong): now the error alone
    assert "skipped" not in result.output, result.output


def test_a_joint_missing_from_some_files_skips_them_and_the_summary_counts_them(
    more_mocap: Path, tmp_path: Path
) -> None:
    maps = _studio(more_mocap, tmp_path)
    take = tmp_path / "mocap/studio/takes/p003/idle_01.bvh"
    take.write_text(take.read_text().replace("JOINT shin.L", "JOINT shin.Left", 1))
    report = _build(tmp_path, maps)
    assert report.dataset.clip_name.tolist() == ["studio/p002/idle_01"]
    assert f"map {maps / 'studio.toml'}: 1 of its 2 files skipped (1 lacking joints)" in (
        "\n".join(report.meta["warnings"])
    )
    assert report.meta["skipped_files"][0]["kind"] == "lacking joints"
    said: list[str] = []  # (the file's own line is still said where no name is a typo)
    build_dataset(tmp_path / "mocap", tmp_path / "log.npz", maps_dir=maps, workers=1,
                  progress=False, log=said.append)  # fmt: skip
    assert any("skipped studio:takes/p003/idle_01.bvh: joints ['shin.L']" in s for s in said)


def test_a_missing_joints_error_survives_pickling(more_mocap: Path, tmp_path: Path) -> None:
    """``MissingJoints(message, missing)`` passed ``args`` the message alone: unpickling it
    (a worker process's error, back in the builder) was a ``TypeError``."""
    from trainer.data.build import ClipJob, MissingJoints, read_world

    maps = _studio(more_mocap, tmp_path)
    take = tmp_path / "mocap/studio/takes/p003/idle_01.bvh"
    take.write_text(take.read_text().replace("JOINT shin.L", "JOINT shin.Left", 1))
    m = load_map(maps / "studio.toml")
    rel = "takes/p003/idle_01.bvh"
    with pytest.raises(MissingJoints) as info:
        read_world(ClipJob(str(take), rel, f"{m.source}:{rel}", m))
    err = info.value
    assert list(err.missing) == ["shin.L"] and "shin.L" in str(err), err.missing
    back = pickle.loads(pickle.dumps(err))
    assert type(back) is MissingJoints and str(back) == str(err) and back.args == err.args
    assert back.missing == err.missing and vars(back) == vars(err)


def test_include_globs_matching_nothing_name_the_map_the_globs_and_paths_held(
    more_mocap: Path, tmp_path: Path
) -> None:
    """An archive packed with its top folder: "no frames survived; see the skipped files
    above", and nothing above."""
    import tarfile

    from trainer.data.build import BuildError

    maps = _studio(more_mocap, tmp_path)
    folder = tmp_path / "mocap" / "studio"
    with tarfile.open(tmp_path / "mocap" / "studio.tar.gz", "w:gz") as tf:
        tf.add(folder, arcname="studio")
    shutil.rmtree(folder)
    with pytest.raises(BuildError) as info:
        _build(tmp_path, maps)
    text = str(info.value)
    assert text.startswith(
        f"map {maps / 'studio.toml'}: include ['takes/**/*.bvh'] matches no file in "
        "studio.tar.gz; it holds 2 files, e.g. studio/takes/p002/idle_01.bvh"
    )
    assert "top folder 'studio/'" in text and "'studio/takes/**/*.bvh'" in text


def test_a_bone_whose_source_joints_coincide_is_warned(more_mocap: Path, tmp_path: Path) -> None:
    """ReActIdle's ``spine`` sits on its ``pelvis``: a map with ``spine1 = "spine"`` built a
    dataset whose spine1 bone is 0 m long without a word (0.000 in the bone table), and
    training ran every stage on it to fail in the export (the manifest's reference bones
    must be in (0, 2) m)."""
    maps = _studio(more_mocap, tmp_path, {'spine1 = "spine.001"': 'spine1 = "spine"'})
    warnings = _build(tmp_path, maps).meta["warnings"]
    assert (
        "studio: median bone length outside 1 mm - 2 m: spine1 (pelvis -> spine1) 0.0000 m: the "
        "map's two source joints of such a bone coincide (or lie far apart); map one of them to "
        "another joint (training refuses such a bone)"
    ) in warnings, warnings


def test_files_left_out_only_for_letter_case_are_named(more_mocap: Path, tmp_path: Path) -> None:
    """A take exported as ``idle_01.BVH`` beside ``.bvh`` ones was left out of the dataset
    without a word (the include globs are case-sensitive); with every take ``.BVH`` the
    error listed them but did not say why ``*.bvh`` missed them."""
    from trainer.data.build import BuildError

    maps = _studio(more_mocap, tmp_path)
    takes = tmp_path / "mocap" / "studio" / "takes"
    (takes / "p003" / "idle_01.bvh").rename(takes / "p003" / "idle_01.BVH")
    built = _build(tmp_path, maps)
    assert list(built.dataset.clip_name) == ["studio/p002/idle_01"]
    assert (
        f"map {maps / 'studio.toml'}: 1 file(s) match include ['takes/**/*.bvh'] only ignoring "
        "letter case, e.g. 'takes/p003/idle_01.BVH': not read (globs are case-sensitive: add a "
        "glob for them)"
    ) in built.meta["warnings"]
    (takes / "p002" / "idle_01.bvh").rename(takes / "p002" / "idle_01.BVH")
    with pytest.raises(BuildError) as info:
        _build(tmp_path, maps)
    assert "; 2 of them match ignoring letter case (e.g. 'takes/p002/idle_01.BVH'): globs are " in (
        str(info.value)
    )


def test_a_zip_archive_is_refused_in_one_line(more_mocap: Path, tmp_path: Path) -> None:
    import zipfile

    from trainer.data.build import BuildError

    maps = _studio(more_mocap, tmp_path, {"studio.tar.gz": "studio.zip"})
    take = tmp_path / "mocap/studio/takes/p002/idle_01.bvh"
    with zipfile.ZipFile(tmp_path / "mocap" / "studio.zip", "w") as zf:
        zf.write(take, "takes/p002/idle_01.bvh")
    shutil.rmtree(tmp_path / "mocap" / "studio")
    with pytest.raises(BuildError, match="a zip archive") as info:
        _build(tmp_path, maps)
    assert "\n" not in str(info.value) and "tar archives (.tar, .tar.gz" in str(info.value)


def test_a_source_not_found_is_named_and_with_own_maps_an_error(
    more_mocap: Path, small_dataset: Path, tmp_path: Path
) -> None:
    """A second map whose archive is missing was one log line, then rc 0 without it."""
    from trainer.data.build import BuildError

    maps = _studio(more_mocap, tmp_path)
    text = (maps / "studio.toml").read_text()
    other = text.replace('"studio"', '"studio-b"').replace("studio.tar.gz", "studio-b.tar.xz")
    (maps / "studio_b.toml").write_text(other)
    with pytest.raises(BuildError) as info:
        _build(tmp_path, maps)
    assert (
        f"map {maps / 'studio_b.toml'}: source 'studio-b': no archive 'studio-b.tar.xz' nor "
        f"folder 'studio-b/' in {tmp_path / 'mocap'}"
    ) in str(info.value)
    assert str(maps / "studio_b.toml") in str(info.value)
    # a zip beside it is no archive the builder reads: the hint says so (a studio audit:
    # it offered the zip, whose map then failed on it)
    (tmp_path / "mocap" / "studio-b.zip").write_bytes(b"PK")
    with pytest.raises(BuildError) as info:
        _build(tmp_path, maps)
    assert (
        "did you mean 'studio-b.zip'? A zip is not read: repack it as .tar.xz or unzip it into "
        "'studio-b/'."
    ) in str(info.value)
    # The shipped maps: a source not found is a warning of the summary (the fixture's folder
    # holds only Bandai-Namco and CMU dance clips).
    warnings = load_dataset(small_dataset).meta["warnings"]
    assert any(
        w.startswith("not built: map ") and "no archive 'reactidle_bvh.tar.xz'" in w
        for w in warnings
    ), warnings


def test_unused_override_and_holdout_globs_and_a_missing_licence_are_warned(
    more_mocap: Path, tmp_path: Path
) -> None:
    override = '[[override]]\nglob = "takes/p03/*.bvh"\nsplit = "val"\n\n[metadata]'
    edits = {
        'licence = "internal use only"\n': "",
        'include = ["takes/**/*.bvh"]': 'include = ["takes/**/*.bvh"]\nholdout = ["takes/p2/**"]',
        "[metadata]": override,
    }
    maps = _studio(more_mocap, tmp_path, edits)
    warnings = _build(tmp_path, maps).meta["warnings"]
    path = maps / "studio.toml"
    assert (
        f"map {path}: [[override]] #1 glob 'takes/p03/*.bvh' matches none of its 2 selected "
        "files: its settings are unused"
    ) in "\n".join(warnings)
    assert f"map {path}: holdout glob 'takes/p2/**' matches none of its 2 selected" in (
        "\n".join(warnings)
    )
    assert any(w.startswith(f"map {path}: no `licence` for source 'studio'") for w in warnings)
    # a split asked for files the map holds out (the holdout wins) was silently unused (a
    # studio audit, 2026-12-05)
    edits = {
        'include = ["takes/**/*.bvh"]': 'include = ["takes/**/*.bvh"]\nholdout = ["takes/p002/**"]',
        "[metadata]": override.replace("takes/p03/", "takes/p00*/"),
    }
    warnings = _build(tmp_path, _studio(more_mocap, tmp_path, edits)).meta["warnings"]
    assert (
        f"map {path}: [[override]] #1 puts 1 file(s) in split 'val' that the map holds out "
        "(e.g. 'takes/p002/idle_01.bvh'): held out they stay"
    ) in warnings, warnings


def test_plausibility_is_checked_per_actor_and_on_the_floor(
    more_mocap: Path, small_dataset: Path, tmp_path: Path
) -> None:
    """An override giving one actor's files the wrong unit (3 mm thighs), and a map without
    `root_position = "add"` (figures sunk 0.7 m through the floor), built without a word."""
    import dataclasses

    from trainer.data.build import sanity_warnings

    override = '[[override]]\nglob = "takes/p003/*.bvh"\nunit = "cm"\n\n[metadata]'
    maps = _studio(more_mocap, tmp_path, {"[metadata]": override})
    (warning,) = sanity_warnings(_build(tmp_path, maps).dataset)[:1]
    assert warning.startswith("studio, actor 'p003': median thigh length 0.00")
    assert "`unit`" in warning
    maps = _studio(more_mocap, tmp_path, {'root_position = "add"\n': ""})
    (warning,) = [w for w in sanity_warnings(_build(tmp_path, maps).dataset) if "studio" in w]
    assert warning.startswith("studio: median lowest joint at y = -0.")
    assert 'root_position` right ("add"' in warning
    ds = load_dataset(small_dataset)
    sunk = dataclasses.replace(ds, positions=ds.positions - np.float32([0, 0.9, 0]))
    assert all("root_position" in w for w in sanity_warnings(sunk))


def test_a_wrong_unit_is_blamed_alone(small_dataset: Path) -> None:
    """Metres read as inches (x 39): the thigh blamed the unit, and the head the up axis
    and the toes the sides for the same source ("median the thigh is")."""
    import dataclasses

    from trainer.data.build import sanity_warnings

    ds = load_dataset(small_dataset)
    huge = dataclasses.replace(ds, positions=ds.positions * 39.37)
    warnings = sanity_warnings(huge)
    assert len(warnings) == 2, warnings  # one per source
    for w in warnings:
        assert "median thigh length" in w and "`unit`" in w, w
        assert "up_axis" not in w and "swap_sides" not in w and "median the" not in w


def test_a_clip_losing_many_frames_to_the_drop_rule_is_warned_with_its_bones(
    more_mocap: Path, tmp_path: Path
) -> None:
    """A map joining two source joints whose distance changes (here a slip: the left wrist
    on the right clavicle) lost 749 of a clip's 1,898 frames as ``bone_length`` with no
    warning: only the summary's drop counts, per source, said so. Now the clip, the count
    and the bone; a clip losing 5 % or less (p003: 10 frames) is not named."""
    maps = _studio(
        more_mocap, tmp_path, {'left_wrist = "forearm.L_end"': 'left_wrist = "shoulder.R"'}
    )
    built = _build(tmp_path, maps)
    assert built.meta["dropped_frames"]["bone_length"] == 759
    dropped = [w for w in built.meta["warnings"] if "frames dropped" in w]
    assert dropped == [
        "studio:takes/p002/idle_01.bvh: 749 of its 1898 frames dropped (749 bone_length; "
        "bones off their median length: left_wrist in 749); see the drop rule in docs/data.md"
    ]
