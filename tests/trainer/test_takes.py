"""Plausibility per take (one file): a take in another unit or up axis than its source's
other takes (trainer.data.checks), warned by the build and refused by training (real
clips)."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from trainer.cli import app
from trainer.data.build import build_dataset
from trainer.data.checks import TAKE_FILES, implausible, implausible_takes, sanity_warnings
from trainer.data.dataset import DatasetError, PoseDataset, load_dataset

MAPS = Path(__file__).resolve().parents[2] / "trainer" / "maps"
_REACTIDLE = "reactidle_bvh/Enekoassets+ReActIdle@90b0ac7/genuine"
#: A studio's map of its takes (one folder, no actor: the audit's map, `actor = ""`).
TAKES_MAP = """format = 2
source = "studio"
licence = "internal use only"
archive = "studio.tar.gz"
unit = "m"
root_position = "add"
include = ["takes/*.bvh"]

[metadata]
pattern = '^takes/(?P<content>[a-z]+)_(?P<take>[0-9]+)[.]bvh$'
name = "studio/{content}_{take}"
content = "{content}"
actor = ""

"""
INCHES = 1 / 0.0254  # a take exported in inches, read as metres


def rescaled_bvh(text: str, factor: float) -> str:
    """The BVH ``text`` written in another unit: every OFFSET and position channel times
    ``factor`` (the rotations as they are)."""
    position: list[bool] = []  # per motion column: a position channel
    lines, motion = [], False
    for line in text.splitlines():
        words = line.split()
        if words[:1] == ["MOTION"]:
            motion = True
        elif not motion and words[:1] == ["OFFSET"]:
            indent = line[: len(line) - len(line.lstrip())]
            line = indent + "OFFSET " + " ".join(f"{float(w) * factor:.6f}" for w in words[1:])
        elif not motion and words[:1] == ["CHANNELS"]:
            position += [w.lower().endswith("position") for w in words[2:]]
        elif motion and len(words) == len(position):
            line = " ".join(
                f"{float(w) * factor:.6f}" if pos else w
                for w, pos in zip(words, position, strict=True)
            )
        lines.append(line)
    return "\n".join(lines) + "\n"


def _takes(more_mocap: Path, tmp_path: Path, factor: float) -> Path:
    """``tmp_path/mocap/studio/takes/idle_0{1,2,3}.bvh``: two real ReActIdle takes and the
    first again, written in another unit (``factor``); the map in ``tmp_path/maps``."""
    takes = tmp_path / "mocap" / "studio" / "takes"
    takes.mkdir(parents=True)
    real = [more_mocap / _REACTIDLE / f"{p}_genuine.bvh" for p in ("002", "003")]
    shutil.copy(real[0], takes / "idle_01.bvh")
    shutil.copy(real[1], takes / "idle_02.bvh")
    (takes / "idle_03.bvh").write_text(rescaled_bvh(real[0].read_text(), factor))
    joints = (MAPS / "reactidle.toml").read_text().split("[joints]")[1]
    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "studio.toml").write_text(TAKES_MAP + "[joints]" + joints)
    return maps


def test_one_take_in_inches_is_named_by_its_file_and_training_refuses_it(
    more_mocap: Path, tmp_path: Path
) -> None:
    """A studio audit (2026-12-07): one take of a studio's 16 exported in inches (pelvis at
    35.8 m) built without a word, the checks looking at the source's medians only, and the
    models trained on it served bodies 4x too big (reference thigh 1.53 m, not 0.36 m).
    The build now warns of that take, naming its file and the likely key; training refuses
    the dataset naming it, before any stage."""
    maps = _takes(more_mocap, tmp_path, INCHES)
    out = tmp_path / "studio.npz"
    report = build_dataset(tmp_path / "mocap", out, maps_dir=maps, workers=1, progress=False)
    ds = report.dataset
    assert ds.num_clips == 3 and sorted(set(ds.clip_split.tolist())) == ["test", "train", "val"]
    said = [w for w in report.meta["warnings"] if "idle_03" in w]
    assert len(said) == 1, report.meta["warnings"]
    (warning,) = said
    assert warning.startswith(
        "studio:takes/idle_03.bvh (clip 'studio/idle_03'): median thigh length 1"
    ), warning
    assert "is the `unit` right?" in warning and "glob = 'takes/idle_03.bvh'" in warning
    assert not any("idle_01" in w or "idle_02" in w for w in report.meta["warnings"])
    assert report.meta[TAKE_FILES] == {"studio/idle_03": "studio:takes/idle_03.bvh"}
    assert load_dataset(out).meta["warnings"] == report.meta["warnings"]

    run, models = tmp_path / "run", tmp_path / "models"
    args = ["train", "--dataset", str(out), "--run-dir", str(run), "--out", str(models)]
    r = CliRunner().invoke(app, args)
    text = " ".join(r.output.split())
    assert r.exit_code == 1 and "Traceback" not in r.output, r.output
    assert f"error: {out}: its poses are implausible for a human body" in text, r.output
    assert "studio:takes/idle_03.bvh (clip 'studio/idle_03'): median thigh length" in text
    assert "--accept-implausible" in text
    assert not run.exists() and not models.exists()  # nothing trained


def _scaled_clips(ds: PoseDataset, clips: list[int], factor: float) -> PoseDataset:
    positions = ds.positions.copy()
    sel = np.isin(ds.clip, clips)
    positions[sel] *= np.float32(factor)
    return dataclasses.replace(ds, positions=positions)


def test_two_takes_in_cm_are_both_named_and_the_refusal_s_claim_holds(
    small_dataset: Path, tmp_path: Path
) -> None:
    """Two takes of one actor x 100 (cm read as metres): the build said nothing, and training
    refused on the train split's mean bone lengths claiming "the dataset summary warned of
    it". Both takes are now warned of by name, and the refusal names them."""
    ds = load_dataset(small_dataset)
    bandai = [c for c in range(ds.num_clips) if ds.clip_source[c] == "bandai-namco"]
    train = [c for c in bandai if ds.clip_split[c] == "train"][:2]
    assert len(train) == 2 and len({str(ds.clip_actor[c]) for c in train}) == 1
    cm = _scaled_clips(ds, train, 100.0)
    names = [str(ds.clip_name[c]) for c in train]
    warnings = sanity_warnings(cm)
    for name in names:
        (w,) = [w for w in warnings if repr(name) in w]
        assert w.startswith(f"bandai-namco, clip {name!r}: median thigh length 3"), w
        assert "is the `unit` right?" in w
    assert implausible_takes(cm) == sorted(train)
    odd = implausible(cm)
    assert len(odd) == 2 and all(any(repr(n) in w for w in odd) for n in names), odd

    bad = tmp_path / "cm.npz"
    np.savez(bad, **{**cm.arrays(), "positions": cm.positions})
    run = tmp_path / "run"
    args = ["train", "--dataset", str(bad), "--run-dir", str(run), "--out", str(tmp_path / "m")]
    r = CliRunner().invoke(app, args)
    text = " ".join(r.output.split())
    assert r.exit_code == 1 and "Traceback" not in r.output, r.output
    assert all(f"clip {n!r}: median thigh length" in text for n in names), r.output
    assert not run.exists()
    from trainer.config import load_config
    from trainer.train import load_splits

    with pytest.raises(DatasetError, match="implausible"):
        load_splits(load_config(None, {"dataset": str(bad)}))


def test_one_take_turned_z_up_is_named_with_the_up_axis(small_dataset: Path) -> None:
    """One take exported +Z up among +Y ones (lying on the floor) built without a word."""
    ds = load_dataset(small_dataset)
    c = int(np.flatnonzero(ds.clip_source == "cmu-dance")[0])
    positions = ds.positions.copy()
    sel = ds.clip == c
    positions[sel] = positions[sel][..., [0, 2, 1]] * np.float32([1, -1, 1])
    lying = dataclasses.replace(ds, positions=positions)
    name = str(ds.clip_name[c])
    (w,) = implausible(lying)
    assert w.startswith(f"cmu-dance, clip {name!r}: median head height over the pelvis"), w
    assert "is the `up_axis` right?" in w
    assert w in sanity_warnings(lying)


def test_the_clean_small_dataset_and_its_takes_give_no_warning(small_dataset: Path) -> None:
    ds = load_dataset(small_dataset)
    assert implausible_takes(ds) == []
    assert implausible(ds) == [] and sanity_warnings(ds) == []
    assert TAKE_FILES not in ds.meta


def test_bones_far_off_in_the_train_split_s_mean_alone_are_warned(small_dataset: Path) -> None:
    """Training refuses a train split whose mean bone lengths (its reference skeleton) are
    outside 1 mm - 2 m, "the dataset summary warned of it": frames far off their size in
    part of one take (no median of it moved) now get that warning from the build too."""
    ds = load_dataset(small_dataset)
    train = np.flatnonzero(ds.clip_split == "train")
    c = int(max(train, key=lambda c: int((ds.clip == c).sum())))
    frames = np.flatnonzero(ds.clip == c)
    positions = ds.positions.copy()
    positions[frames[: int(len(frames) * 0.45)]] *= np.float32(100)
    odd = dataclasses.replace(ds, positions=positions)
    assert implausible(odd) == []
    (w,) = sanity_warnings(odd)
    assert w.startswith("the train split's mean bone length is outside 1 mm - 2 m for "), w
    assert "training refuses this dataset" in w
    from trainer.data.checks import bad_bones
    from trainer.train import reference_lengths  # (training's own test agrees)

    assert bad_bones(reference_lengths(odd.subset(odd.split_mask("train"))))


def test_more_takes_than_named_are_counted_in_one_line(small_dataset: Path) -> None:
    from trainer.data.checks import TAKES_NAMED, _take_warnings

    ds = load_dataset(small_dataset)
    n = ds.num_clips
    assert n > TAKES_NAMED
    lines = _take_warnings(ds, "acme", [(c, "a problem") for c in range(n)])
    assert len(lines) == TAKES_NAMED + 1
    assert all(line.startswith("acme, clip ") for line in lines[:-1])
    rest = n - TAKES_NAMED
    assert lines[-1].startswith(f"acme: {rest} more takes implausible likewise: "), lines[-1]
    assert repr(str(ds.clip_name[TAKES_NAMED])) in lines[-1]
