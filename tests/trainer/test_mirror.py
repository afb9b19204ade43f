"""`pose-trainer mirror`: a model folder's mirror graphs, written from its fused graphs
(``trainer.mirror``), on the shipped models."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from core.manifest import ManifestError, Serving, load_manifest, model_version, write_manifest
from trainer.cli import app


@pytest.fixture
def without(models_dir: Path, tmp_path: Path) -> Path:
    """A copy of the shipped models as exported before mirror graphs existed: no mirror
    files, no mirror entries, the version of the files it has."""
    out = tmp_path / "models"
    shutil.copytree(models_dir, out, ignore=shutil.ignore_patterns("mirror_*"))
    manifest = load_manifest(models_dir, verify=False)
    kept = [m for m in manifest.models if m.kind != "mirror"]
    write_manifest(out, manifest.model_copy(
        update={"models": kept, "version": model_version(kept, manifest.serving)}
    ))  # fmt: skip
    return out


def test_mirror_writes_the_shipped_graphs_bit_for_bit(models_dir: Path, without: Path) -> None:
    """From the fused graphs alone the command writes the shipped mirror graphs byte for
    byte, one per solver set (every shipped set's mirror image has a solver), and the
    manifest of the shipped version; run again, nothing changes."""
    shipped = load_manifest(models_dir)
    before = load_manifest(without)
    assert not before.mirrors() and before.version != shipped.version
    result = CliRunner().invoke(app, ["mirror", "--models", str(without)])
    assert result.exit_code == 0, result.output
    assert f"15 mirror graphs; version {shipped.version}" in result.output
    after = load_manifest(without, verify=True)
    assert after.version == shipped.version
    assert set(after.mirrors()) == set(after.solvers()) == set(shipped.mirrors())
    for key, entry in shipped.mirrors().items():
        assert (without / entry.file).read_bytes() == (models_dir / entry.file).read_bytes(), key
    assert (
        f"| mirror:left_wrist | {after.mirrors()['left_wrist'].parameters:,} |"
        in (without / "README.md").read_text()
    )
    again = CliRunner().invoke(app, ["mirror", "--models", str(without)])
    assert again.exit_code == 0 and load_manifest(without).version == shipped.version


def test_a_setting_added_after_a_manifest_was_written_keeps_its_version(
    models_dir: Path, without: Path
) -> None:
    """A serving setting the manifest does not name (added to the service after the models
    were exported) is served at its default and is not part of the version: the mirror
    pass keeps the file's serving block as written. Once the file names it, it counts."""
    raw = json.loads((without / "manifest.json").read_text())
    newest = list(Serving.model_fields)[-1]
    del raw["serving"][newest]
    (without / "manifest.json").write_text(json.dumps(raw))
    older = load_manifest(without, verify=False)
    assert getattr(older.serving, newest) == Serving.model_fields[newest].default
    assert model_version(older.models, older.serving) != model_version(
        older.models, Serving.model_validate(older.serving.model_dump())
    )
    result = CliRunner().invoke(app, ["mirror", "--models", str(without)])
    assert result.exit_code == 0, result.output
    written = json.loads((without / "manifest.json").read_text())
    assert newest not in written["serving"]
    assert written["serving"] == raw["serving"]
    after = load_manifest(without)
    assert after.version == model_version(after.models, after.serving)


def test_a_tampered_fused_graph_is_refused_by_name(without: Path) -> None:
    target = without / "fused_left_wrist.onnx"
    data = bytearray(target.read_bytes())
    data[len(data) // 2] ^= 0xFF
    target.write_bytes(bytes(data))
    result = CliRunner().invoke(app, ["mirror", "--models", str(without)])
    assert result.exit_code == 1
    assert "fused_left_wrist.onnx" in result.output and "sha256" in result.output
    assert not list(without.glob("mirror_*"))


def test_a_mirror_entry_needs_both_fused_graphs(models_dir: Path, tmp_path: Path) -> None:
    """The manifest refuses a mirror graph whose mirror set has no fused graph."""
    raw = json.loads((models_dir / "manifest.json").read_text())
    raw["models"] = [m for m in raw["models"] if m["name"] != "fused:right_wrist"]
    raw["models"] = [m for m in raw["models"] if m["name"] not in ("solver:right_wrist",)]
    out = tmp_path / "models"
    out.mkdir()
    (out / "manifest.json").write_text(json.dumps(raw))
    with pytest.raises(ManifestError, match="mirror graphs must be unique and each match"):
        load_manifest(out, verify=False)


def test_a_graph_that_does_not_answer_as_the_fused_graphs_is_refused(
    without: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every graph written is checked against the fused graphs before it is listed: one
    whose mean is off (a quarter, not a half) is refused by name and removed, and the
    manifest stays as it was."""
    import onnx.numpy_helper

    from trainer import mirror

    right = mirror.mirror_graph

    def off(*args: object, **kwargs: object) -> onnx.ModelProto:
        model = right(*args, **kwargs)  # type: ignore[arg-type]
        half = next(i for i in model.graph.initializer if i.name == "m_half")
        half.CopyFrom(onnx.numpy_helper.from_array(np.asarray(0.25, np.float32), "m_half"))
        return model

    monkeypatch.setattr(mirror, "mirror_graph", off)
    before = (without / "manifest.json").read_bytes()
    result = CliRunner().invoke(app, ["mirror", "--models", str(without)])
    assert result.exit_code == 1
    assert "not the fused graphs' mean, bit for bit" in result.output
    assert "mirror_head" in result.output  # the first set by name
    assert not list(without.glob("mirror_*"))
    assert (without / "manifest.json").read_bytes() == before
