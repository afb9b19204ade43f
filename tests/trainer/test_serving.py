"""`pose-trainer serving`: a trained model folder's serving block set from a config."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from core.manifest import load_manifest
from service.engine import Engine
from trainer.cli import app
from trainer.config import load_config
from trainer.serving import set_serving

DEFAULT = Path(__file__).resolve().parents[2] / "trainer" / "configs" / "default.toml"


@pytest.fixture
def models(models_dir: Path, tmp_path: Path) -> Path:
    out = tmp_path / "models"
    shutil.copytree(models_dir, out)
    return out


def test_a_serving_only_setting_changes_the_version_and_the_answers_setting(
    models: Path,
) -> None:
    """Flipping keep_elbows (the losses never saw it) gives a verified manifest of a new
    version that the engine serves with the new setting and records the change; the same
    block gives the same version again (the version hashes the files and the block)."""
    before = load_manifest(models)
    flip = not before.serving.keep_elbows
    cfg = load_config(DEFAULT, {"solver": {"keep_elbows": flip}})
    original = load_config(DEFAULT, {"solver": {"keep_elbows": not flip}})
    set_serving(original, models)  # the shipped block as the default config states it
    start = load_manifest(models)
    after, changed = set_serving(cfg, models)
    assert changed == {"keep_elbows": {"from": not flip, "to": flip}}
    assert after.version != start.version and after == load_manifest(models, verify=True)
    assert after.provenance.serving_changes[-1]["from"] == start.version
    assert after.provenance.config["solver"]["keep_elbows"] is flip
    assert [m.sha256 for m in after.models] == [m.sha256 for m in before.models]
    assert Engine(models).serving.keep_elbows is flip
    card = (models / "README.md").read_text()
    assert f"manifest {after.version}" in card and f"`keep_elbows` {flip}," in card
    assert f"(from {start.version}): `keep_elbows` {not flip} → {flip}." in card
    assert set_serving(cfg, models)[1] == {}  # already so: nothing written
    back, _ = set_serving(original, models)
    assert back.serving == start.serving and back.version != after.version
    again, _ = set_serving(cfg, models)
    changes = len(start.provenance.serving_changes)
    assert again.version == after.version and len(again.provenance.serving_changes) == changes + 3


def test_a_setting_the_losses_saw_is_refused_and_nothing_written(models: Path) -> None:
    manifest = load_manifest(models)
    assert manifest.provenance.config["solver"]["ends_loss"]  # the shipped recipe
    text = (models / "manifest.json").read_text()
    flipped = {"keep_ends": not manifest.serving.keep_ends}
    with pytest.raises(ValueError, match="retrain to change them: keep_ends"):
        set_serving(load_config(DEFAULT, {"solver": flipped}), models)
    assert (models / "manifest.json").read_text() == text


def test_the_command_reports_the_change_or_the_refusal(models: Path, tmp_path: Path) -> None:
    cfg = tmp_path / "serving.toml"
    manifest = json.loads((models / "manifest.json").read_text())
    turns = manifest["serving"]["turn_yaws"] * 2
    cfg.write_text(f'extends = "{DEFAULT}"\n[solver]\nturn_yaws = {turns}\n')
    ok = CliRunner().invoke(app, ["serving", "--config", str(cfg), "--models", str(models)])
    assert ok.exit_code == 0, ok.output
    assert f"turn_yaws {turns // 2} -> {turns}" in ok.output
    assert load_manifest(models).serving.turn_yaws == turns
    cfg.write_text(f'extends = "{DEFAULT}"\n[solver]\ndelta = false\n')
    bad = CliRunner().invoke(app, ["serving", "--config", str(cfg), "--models", str(models)])
    assert bad.exit_code == 1 and "delta True -> False" in bad.output
    for args, says in (
        (["--config", str(tmp_path / "none.toml"), "--models", str(models)], "none.toml"),
        (["--config", str(cfg), "--models", str(tmp_path / "empty")], "manifest.json: missing"),
    ):
        got = CliRunner().invoke(app, ["serving", *args])
        assert got.exit_code == 1 and says in got.output and "Traceback" not in got.output


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("carry = 1e999", "solver.carry: Input should be a finite number, got 1e999"),
        ("turn_margin = nan", "solver.turn_margin: Input should be a finite number, got nan"),
        (
            "keep_pelvis = 1.5",
            "solver.keep_pelvis: Input should be less than or equal to 1, got 1.5",
        ),
        (
            "turn_plausibility = -inf",
            "solver.turn_plausibility: Input should be a finite number, got -inf",
        ),
    ],
)
def test_the_command_refuses_a_serving_value_not_finite_or_in_range(
    models: Path, tmp_path: Path, line: str, says: str
) -> None:
    """A serving value is finite and in its bounds (``core.manifest.Serving``, whose fields
    the config's are): refused naming the key and the value as the file writes it (was
    "Input should be less than or equal to 1", the value not said), nothing written."""
    cfg = tmp_path / "serving.toml"
    cfg.write_text(f'extends = "{DEFAULT}"\n[solver]\n{line}\n')
    text = (models / "manifest.json").read_text()
    bad = CliRunner().invoke(app, ["serving", "--config", str(cfg), "--models", str(models)])
    assert bad.exit_code == 1 and "Traceback" not in bad.output, bad.output
    assert says in bad.output.replace("\n", ""), bad.output
    assert (models / "manifest.json").read_text() == text


def test_settings_that_need_retraining_are_named_as_not_applied(
    models: Path, tmp_path: Path
) -> None:
    """A studio audit (D12): ``pose-trainer serving --config`` with training settings
    changed (``autoencoder.epochs``, ``solver.hidden``) applied the serving ones and ignored
    those without a word, as if they had taken effect. A warning now names each, with the
    models' own value; the serving change is made as before."""
    cfg = tmp_path / "mixed.toml"
    cfg.write_text(
        f'extends = "{DEFAULT}"\nrun_dir = "elsewhere"\n[autoencoder]\nepochs = 50\n'
        "[solver]\nhidden = [10]\ncarry = 0.5\n"
    )
    trained = load_manifest(models).provenance.config
    r = CliRunner().invoke(app, ["serving", "--config", str(cfg), "--models", str(models)])
    assert r.exit_code == 0, r.output
    text = " ".join(r.output.split())
    assert (
        f"warning: {cfg}: settings that need retraining, not applied: autoencoder.epochs 50 "
        f"(the models': {trained['autoencoder']['epochs']}); solver.hidden [10] (the models': "
        f"{trained['solver']['hidden']})"
    ) in text, r.output
    assert "solver.carry" not in text and "run_dir" not in text  # applied; a path
    assert load_manifest(models).serving.carry == 0.5
    r = CliRunner().invoke(app, ["serving", "--config", str(DEFAULT), "--models", str(models)])
    assert r.exit_code == 0 and "warning" not in r.output, r.output
