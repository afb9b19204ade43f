"""``trainer.config``: a config's numbers are finite, a bad one named with its key and the
value as the file writes it (``tomllib`` reads ``1e999`` as ``inf``)."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from trainer.cli import app
from trainer.config import load_config

DEFAULT = Path(__file__).resolve().parents[2] / "trainer" / "configs" / "default.toml"


def refused(tmp_path: Path, line: str, match: str) -> str:
    """The refusal of a config that extends the default with ``line``: it names the file."""
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(f'extends = "{DEFAULT}"\n{line}\n')
    with pytest.raises(ValueError, match=match) as info:
        load_config(cfg)
    assert str(info.value).startswith(f"{cfg}: "), info.value
    return str(info.value)


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("[autoencoder]\nlr = 1e999", "autoencoder.lr: Input should be a finite number, got 1e999"),
        (
            "[solver]\nbone_weight = nan",
            "solver.bone_weight: Input should be a finite number, got nan",
        ),
        (
            "[augment]\nbone_sigma = +inf",
            "augment.bone_sigma: Input should be a finite number, got +inf",
        ),
        (
            "[solver]\nother_weights = { arms = -1e400 }",
            "solver.other_weights.arms: Input should be a finite number, got -1e400",
        ),
        (
            "[solver]\nlong_other_weight = 1e999",
            "solver.long_other_weight: Input should be a finite",
        ),
        ("[completion]\nlr = 1E+999", "completion.lr: Input should be a finite number, got 1E+999"),
        ("[solver]\ncarry = 1.5", "solver.carry: Input should be less than or equal to 1, got 1.5"),
    ],
)
def test_a_number_that_is_not_finite_is_refused_naming_key_and_value(
    tmp_path: Path, line: str, says: str
) -> None:
    """``lr = 1e999`` loaded as ``lr = inf`` and trained (a rate with no bound above);
    ``nan`` passed every bound but the serving settings' own. Now the schema refuses it
    (``allow_inf_nan``), naming the file, the key and the value as the file writes it."""
    assert says in refused(tmp_path, line, r"Input should be")


@pytest.mark.parametrize(
    ("setting", "says"),
    [
        ("[autoencoder]\nlr = 1e999", "autoencoder.lr: Input should be a finite number, got 1e999"),
        ("max_eval_frames = 0", "max_eval_frames: Input should be"),
    ],
)
def test_train_refuses_a_bad_setting_in_one_line_and_trains_nothing(
    tmp_path: Path, setting: str, says: str
) -> None:
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(f'extends = "{DEFAULT}"\n{setting}\n')
    run, out = tmp_path / "run", tmp_path / "models"
    args = ["train", "--config", str(cfg), "--run-dir", str(run), "--out", str(out)]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 1 and "Traceback" not in r.output, r.output
    flat = r.output.replace("\n", "")
    assert f"{cfg}: {says}" in flat, flat
    assert not run.exists() and not out.exists()


def test_finite_numbers_are_read_as_before(tmp_path: Path) -> None:
    cfg = tmp_path / "ok.toml"
    cfg.write_text(f'extends = "{DEFAULT}"\n[autoencoder]\nlr = 2.5e-4\n[solver]\ncarry = 1e0\n')
    got = load_config(cfg)
    assert got.autoencoder.lr == 2.5e-4 and type(got.autoencoder.lr) is float
    assert got.solver.carry == 1.0


def test_a_solver_set_listed_twice_is_refused_when_the_config_is_read(tmp_path: Path) -> None:
    """A studio audit (D9): ``sets = [["head"], ["head"]]`` trained every stage, then the
    export died with a pydantic traceback ("model names must be unique"). Refused when the
    config is read, naming the set; the same joints in another order are the same set."""
    for sets, named in (
        ('[["head"], ["head"]]', "['head'] listed twice"),
        ('[["left_wrist", "right_wrist"], ["right_wrist", "left_wrist"]]',
         "['right_wrist', 'left_wrist'] listed twice"),
    ):  # fmt: skip
        cfg = tmp_path / "dup.toml"
        cfg.write_text(f'extends = "{DEFAULT}"\n[solver]\nsets = {sets}\n')
        with pytest.raises(ValueError, match="listed twice") as info:
            load_config(cfg)
        assert str(info.value).startswith(f"{cfg}: solver.sets: "), info.value
        assert named in str(info.value), info.value
    cfg.write_text(f'extends = "{DEFAULT}"\n[solver]\nlong_sets = [["head"], ["head"]]\n')
    with pytest.raises(ValueError, match=r"solver.long_sets: .*\['head'\] listed twice"):
        load_config(cfg)


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("opset = 5", "opset: Value error, the export writes ONNX opsets 18 to 25, got 5"),
        ("opset = 13", "opset: Value error, the export writes ONNX opsets 18 to 25, got 13"),
        ("opset = 99", "opset: Value error, the export writes ONNX opsets 18 to 25, got 99"),
        ("max_eval_frames = 0", "max_eval_frames: Input should be greater than or equal to 1"),
        ("max_eval_frames = -5", "max_eval_frames: Input should be greater than or equal to 1"),
        ("max_train_frames = 0", "max_train_frames: Input should be greater than or equal to 1"),
        ("max_train_frames = -1", "max_train_frames: Input should be greater than or equal to"),
    ],
)
def test_an_opset_or_frame_cap_the_run_cannot_use_is_refused_when_read(
    tmp_path: Path, line: str, says: str
) -> None:
    """A studio audit: ``opset = 5`` (D5) was accepted, the export printed ~35 tracebacks,
    exited 0 and the manifest said opset 5 of files of opset 18; ``max_eval_frames = 0``
    (D6) crashed at the first validation with a traceback, ``max_train_frames`` took 0 (one
    whole clip trained, unsaid) and negatives. Refused when the config is read, naming the
    key and the range."""
    cfg = tmp_path / "cfg.toml"
    assert says in refused(tmp_path, line, r"opset|frames")
    for ok in ("opset = 18", "opset = 25", "max_eval_frames = 1", "max_train_frames = 1"):
        cfg.write_text(f'extends = "{DEFAULT}"\n{ok}\n')
        load_config(cfg)


def test_a_run_without_the_shipped_recipe_says_so(tmp_path: Path) -> None:
    """A studio audit (D13): a config without ``extends`` (or no ``--config``) trained the
    fields' built-in defaults, the paper's recipe (35 settings from ``default.toml``'s, the
    shipped models'), without a word; with no ``--config`` it also exported into the
    shipped ``models/``. Both now say so (a warning: the run goes on)."""
    bare = tmp_path / "bare.toml"
    bare.write_text('dataset = "missing.npz"\n[autoencoder]\nepochs = 1\n')
    good = tmp_path / "good.toml"
    good.write_text(f'extends = "{DEFAULT}"\ndataset = "missing.npz"\n')
    run = tmp_path / "run"
    for args, says in (
        (["--config", str(bare)], f"warning: {bare} has no `extends`: the settings it leaves "
         "out take the built-in defaults of trainer/config.py (the paper's recipe)"),
        (["--dataset", "missing.npz"], "warning: no --config: training the built-in defaults "
         "of trainer/config.py (the paper's recipe, not trainer/configs/default.toml's, the "
         "shipped models'), exporting into models (the shipped models folder"),
        (["--config", str(good)], None),
        (["--config", str(DEFAULT), "--dataset", "missing.npz"], None),
    ):  # fmt: skip
        r = CliRunner().invoke(app, ["train", *args, "--run-dir", str(run)])
        assert r.exit_code == 1 and "missing.npz" in r.output, r.output  # (then: no dataset)
        text = " ".join(r.output.split())
        if says is None:
            assert "warning" not in text, r.output
        else:
            assert " ".join(says.split()) in text, r.output
    assert not run.exists()
