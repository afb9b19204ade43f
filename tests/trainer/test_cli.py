"""`pose-trainer` (trainer/cli.py): what its options write where."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from trainer.cli import app


def test_a_quick_run_exports_into_its_run_dir_not_the_configs_models(
    small_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``train --quick`` ("a seconds-long smoke run") kept the config's ``out_dir``, so a
    studio's smoke run replaced the models its config names (``models/``, the shipped
    ones, with the default config) by a few epochs' worth; it now exports into
    ``<run dir>/models`` (``runs/quick/models``) unless ``--out`` says otherwise."""
    monkeypatch.chdir(tmp_path)
    studio = tmp_path / "models-studio"
    studio.mkdir()
    (studio / "manifest.json").write_text('{"version": "the studio\'s real models"}\n')
    cfg = tmp_path / "my.toml"
    cfg.write_text(
        f'dataset = "{small_dataset}"\nout_dir = "models-studio"\nthreads = 1\n'
        '[solver]\nsets = [["left_wrist"]]\nlong_sets = []\n'
        '[completion]\nhidden = [32]\nschemes = [["pelvis", "neck", "left_wrist", '
        '"right_wrist", "left_ankle", "right_ankle"]]\n'
    )
    r = CliRunner().invoke(app, ["train", "--quick", "--config", str(cfg)])
    assert r.exit_code == 0, r.output
    assert json.loads((studio / "manifest.json").read_text()) == {
        "version": "the studio's real models"
    }
    quick = tmp_path / "runs" / "quick"
    assert (quick / "autoencoder.pt").is_file()
    assert json.loads((quick / "models" / "manifest.json").read_text())["models"]


def test_plot_data_draws_beside_its_dataset_by_default(small_dataset: Path, tmp_path: Path) -> None:
    """``plot-data --dataset data/studio.npz`` (docs/data.md: a studio checks its figures)
    wrote ``docs/img/data_poses.png``, the shipped data's figure in the repository; it now
    writes beside the dataset (``data/studio.png``)."""
    docs_png = Path(__file__).resolve().parents[2] / "docs" / "img" / "data_poses.png"
    before = docs_png.read_bytes()
    studio = tmp_path / "studio.npz"
    studio.write_bytes(small_dataset.read_bytes())
    args = ["plot-data", "--dataset", str(studio), "--per-source", "2"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
    assert (tmp_path / "studio.png").stat().st_size > 0
    assert f"wrote {tmp_path / 'studio.png'}" in r.output.replace("\n", "")
    assert docs_png.read_bytes() == before


def test_an_out_dir_that_is_a_file_or_a_link_is_refused_before_training(
    small_dataset: Path, tmp_path: Path
) -> None:
    """A studio audit (D2): ``out_dir`` / ``--out`` naming an existing file had the file
    renamed to a hidden ``.name.old-<pid>`` and replaced by the models folder; a symbolic
    link to a models folder was likewise left behind, renamed, and replaced by a real folder
    (the deployment it pointed to stale). Both are refused in one line naming the path,
    before any stage trains."""
    notes = tmp_path / "notes.txt"
    notes.write_text("studio notes: DO NOT DELETE\n")
    real = tmp_path / "models-v3"
    real.mkdir()
    (real / "manifest.json").write_text('{"version": "v3"}\n')
    link = tmp_path / "current"
    link.symlink_to(real)
    for out, what in ((notes, "a file, not a folder"), (link, "a symbolic link")):
        run = tmp_path / f"run-{out.name}"
        args = ["train", "--dataset", str(small_dataset), "--run-dir", str(run), "--out", str(out)]
        r = CliRunner().invoke(app, args)
        assert r.exit_code == 1 and "Traceback" not in r.output, r.output
        assert str(out) in r.output.replace("\n", "") and what in r.output, r.output
        assert not run.exists()  # nothing trained
    assert notes.read_text() == "studio notes: DO NOT DELETE\n"
    assert link.is_symlink() and (link / "manifest.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["current", "models-v3", "notes.txt"]


def test_a_run_dir_in_the_out_dir_is_refused_before_training(
    small_dataset: Path, tmp_path: Path
) -> None:
    """A studio audit (D3): ``run_dir`` equal to, or inside, ``out_dir`` passed the check
    before training, trained every stage, then the export died with a traceback (the folder
    it replaces whole held the checkpoints). Refused up front, naming both; ``out_dir``
    inside ``run_dir`` (``--quick``'s ``runs/quick/models``) stays allowed."""
    for run, out in ((tmp_path / "same", tmp_path / "same"), (tmp_path / "nest" / "run",
                     tmp_path / "nest")):  # fmt: skip
        args = ["train", "--dataset", str(small_dataset), "--run-dir", str(run), "--out", str(out)]
        r = CliRunner().invoke(app, args)
        text = r.output.replace("\n", "")
        assert r.exit_code == 1 and "Traceback" not in r.output, r.output
        assert f"the run dir {run}" in text and "separate folders" in text, r.output
        assert not out.exists() and not run.exists()


def test_a_damaged_checkpoint_is_named_with_what_to_do(small_dataset: Path, tmp_path: Path) -> None:
    """A studio audit (D14): a checkpoint cut short (a full disk, a run dir copied from
    another machine) ended training in torch's traceback ("failed finding central
    directory"). Now one line naming the file and what to do; nothing exported."""
    run, out = tmp_path / "run", tmp_path / "models"
    run.mkdir()
    (run / "autoencoder.pt").write_bytes(b"PK\x03\x04" + bytes(996))  # a zip cut short
    args = ["train", "--dataset", str(small_dataset), "--run-dir", str(run), "--out", str(out)]
    r = CliRunner().invoke(app, args)
    text = r.output.replace("\n", "")
    assert r.exit_code == 1 and isinstance(r.exception, SystemExit), r.output
    assert "Traceback" not in r.output, r.output
    assert f"error: {run / 'autoencoder.pt'}: not a readable checkpoint (" in text, r.output
    assert "delete it (its stage trains anew) or train with --fresh" in text, r.output
    why = text.split("not a readable checkpoint (", 1)[1].split("); delete it", 1)[0]
    assert why.endswith((".", "…")), why  # (torch's was cut mid-sentence: "...file is")
    assert not out.exists()


def test_whole_sentences_cuts_a_reason_after_a_sentence() -> None:
    from trainer.stages import whole_sentences

    torch_says = (
        "PytorchStreamReader failed reading zip archive: failed finding central directory. "
        "This is an internal miniz error. If you are seeing this error, there is a high "
        "likelihood that your checkpoint file is corrupted. This can happen if the "
        "checkpoint was not saved properly.\nsecond line"
    )
    assert whole_sentences(torch_says) == (
        "PytorchStreamReader failed reading zip archive: failed finding central directory. "
        "This is an internal miniz error."
    )
    assert whole_sentences("short reason") == "short reason"
    cut = whole_sentences("word " * 60)
    assert len(cut) <= 200 and cut.endswith(" word…"), cut


def test_an_interrupted_training_says_how_to_resume(small_dataset: Path, tmp_path: Path) -> None:
    """A studio audit (2026-12-07): Ctrl-C (SIGINT) during training exited 130 without a
    word. It now says it was interrupted and that re-running resumes (each stage
    checkpoints every epoch), exit 130; the checkpoint is there."""
    import os
    import signal
    import subprocess
    import sys
    import time

    run, out = tmp_path / "run", tmp_path / "models"
    cmd = [sys.executable, "-m", "trainer.cli", "train", "--quick", "--dataset",
           str(small_dataset), "--run-dir", str(run), "--out", str(out)]  # fmt: skip
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "200"}
    # A suite started in the background (`make test &`, nohup) ignores SIGINT, and a child
    # inherits that through exec: CPython then installs no KeyboardInterrupt handler and
    # the training ran on to the end, exit 0 (seen 2026-12-08). The child gets SIGINT's
    # default, as from a terminal.
    ignored = signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    if ignored:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
    try:
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
            cwd=Path(__file__).resolve().parents[2],
        )  # fmt: skip
    finally:
        if ignored:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
    assert proc.stderr is not None
    deadline = time.monotonic() + 120
    said = []
    for line in proc.stderr:  # two epochs said: the first one's checkpoint written
        said.append(line)
        if sum(" epoch " in s for s in said) >= 2 or time.monotonic() > deadline:
            break
    proc.send_signal(signal.SIGINT)
    rest, err = proc.communicate(timeout=120)
    err = "".join(said) + err
    assert proc.returncode == 130, (rest, err)
    assert "interrupted; re-run the same command to resume" in err, err
    assert str(run) in " ".join(err.split()), err
    assert "Traceback" not in err, err
    assert list(run.glob("*.pt")), list(run.iterdir())


def test_a_dataset_of_implausible_bodies_is_refused_unless_accepted(
    small_dataset: Path, tmp_path: Path
) -> None:
    """A studio audit (D4): a map with ``unit = "cm"`` for files in metres (bodies 1/100 of
    their size, the builder warning "is the `unit` right?") or ``up_axis = "+Z"`` on Y-up
    files (figures lying down) trained and exported with exit 0; the service then answered
    nonsense. Training now refuses such a dataset in one line naming the source and the
    likely key, before any stage, unless ``--accept-implausible`` says the poses are right."""
    import numpy as np

    from trainer.config import load_config
    from trainer.train import load_splits

    with np.load(small_dataset, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    source = str(arrays["clip_source"][0])
    lying = arrays["positions"][..., [0, 2, 1]] * np.array([1.0, 1.0, -1.0], np.float32)
    for name, positions, says in (
        ("cm.npz", arrays["positions"] * np.float32(0.01), "is the `unit` right?"),
        ("lying.npz", lying, "is the `up_axis` right?"),
    ):
        bad = tmp_path / name
        np.savez(bad, **{**arrays, "positions": positions.astype(np.float32)})
        run = tmp_path / f"run-{name}"
        args = ["train", "--dataset", str(bad), "--run-dir", str(run), "--out", str(tmp_path / "m")]
        r = CliRunner().invoke(app, args)
        text = r.output.replace("\n", "")
        assert r.exit_code == 1 and "Traceback" not in r.output, r.output
        assert f"error: {bad}: its poses are implausible for a human body" in text, r.output
        assert f"{source}: median" in text and says in text, r.output
        assert "--accept-implausible" in text, r.output
        assert not run.exists() and not (tmp_path / "m").exists()
    # accepted: trains (here the splits load; 1/100 bodies also fail the 1 mm bone check)
    over = {"dataset": str(tmp_path / "lying.npz"), "accept_implausible": True}
    assert len(load_splits(load_config(None, over)).train.positions) > 0
    assert len(load_splits(load_config(None, {"dataset": str(small_dataset)})).val.positions)


def test_a_studio_model_card_names_its_own_paths_and_sources() -> None:
    """A studio audit (D11): the model card of a studio's own models told its reader to
    build into ``data/poses.npz`` and train with ``trainer/configs/default.toml`` (whose
    ``out_dir`` is the shipped ``models/``), ended its licence line "See the model card"
    inside the model card, and described the shipped data's actions as the models' limits.
    It now gives the run's own dataset, run and models paths and its maps folder, and names
    the sources trained on. (The shipped manifest, its provenance made a studio's.)"""
    from core.manifest import load_manifest
    from trainer.model_card import render

    shipped = load_manifest(Path(__file__).resolve().parents[2] / "models")
    prov = shipped.provenance
    config = {**prov.config, "dataset": "data/studio.npz", "run_dir": "runs/studio",
              "out_dir": "models-studio"}  # fmt: skip
    dataset = {**prov.dataset, "licences": {"studio": "internal use only"},
               "source_frames": {"studio": 27735}, "resampled_frames": {"studio": 34663},
               "holdout": {}, "maps": [{"file": "studio.toml",
                                        "source": "studio", "sha256": "0" * 64}]}  # fmt: skip
    data = [{"name": "studio/", "sha256": "1" * 64, "kind": "folder", "files": "10"}]
    studio = shipped.model_copy(update={
        "licence": "these weights inherit the terms of the motion capture they were trained "
        "on (studio: internal use only). See the model card (README.md).",
        "provenance": prov.model_copy(update={"config": config, "dataset": dataset, "data": data}),
    })  # fmt: skip
    card = render(studio)
    recipe = (
        "pose-trainer dataset --mocap <the folder holding studio/> --maps <the folder "
        "holding studio.toml> --out data/studio.npz\npose-trainer train --config <its config> "
        "--dataset data/studio.npz --run-dir runs/studio --out models-studio\n"
    )
    assert recipe in card, card
    assert "--out data/poses.npz" not in card and "default.toml" not in card
    assert "See the model card" not in card
    assert "(studio: internal use only).** Weights" in card.replace("\n", " ")
    assert "everyday actions" not in card
    assert "listed above (`studio`) and nothing else" in card.replace("\n  ", " ")
    shipped_card = render(shipped)  # the shipped models' own: their paths, the shipped maps
    assert "pose-trainer dataset --mocap <the folder holding bandai-namco-research" in shipped_card
    assert "--out data/poses.npz\npose-trainer train" in shipped_card
    assert "--maps" not in shipped_card.split("```")[1]
    assert "(`bandai-namco`, `cmu-asf`, `cmu-dance`) and" in shipped_card  # not those held out


def test_the_export_does_not_say_that_torchvision_is_missing(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """A studio audit (D12): torch's exporter printed 4 "torchvision is not installed.
    Skipping torchvision::..." lines per network, 140 of a quick run's 324 lines; the
    trainer never uses torchvision. Those lines are dropped; the export's other warnings
    are not touched."""
    import torch

    from trainer.export import _export

    module = torch.nn.Sequential(torch.nn.Linear(6, 4), torch.nn.SELU())
    _export(module, (torch.randn(3, 6),), ["pose"], "latent", tmp_path / "m.onnx", 18)
    assert (tmp_path / "m.onnx").stat().st_size > 0
    assert "torchvision" not in capfd.readouterr().err


def test_weights_of_sets_not_trained_are_named_in_one_line(
    small_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    """A studio audit (D12): a config that extends ``default.toml`` and trains fewer solver
    sets printed one warning per inherited ``solver.other_weights`` / ``stay_weights`` /
    ``stay_frames`` key (five, of keys the studio never wrote). Now one line names them."""
    import trainer.train as train
    from trainer.config import load_config

    class Stop(Exception):
        pass

    def stop(*_: object) -> None:
        raise Stop

    monkeypatch.setattr(train, "train_autoencoder", stop)  # (the warnings come before it)
    default = Path(__file__).resolve().parents[2] / "trainer" / "configs" / "default.toml"
    over = {"dataset": str(small_dataset), "run_dir": str(tmp_path / "run"),
            "solver": {"sets": [["head"]]}}  # fmt: skip
    cfg = load_config(default, over)
    unused = cfg.solver.unused_weights()
    assert len(unused) > 1
    with pytest.raises(Stop):
        train.train_all(cfg)
    out = capsys.readouterr().err  # (trainer.stages.console: stderr)
    text = " ".join(out.split())
    assert out.count("no set of solver.sets") == 1, out
    assert ", ".join(f"solver.{k}" for k in unused) + ": no set of solver.sets, ignored" in text


def _refused(args: list[str], option: str, path: Path) -> str:
    """``pose-trainer <args>``: exit 2 and one line naming ``option`` and ``path``."""
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 2 and "Traceback" not in r.output, r.output
    (line,) = [line for line in r.output.splitlines() if line.startswith("error:")]
    assert line.startswith(f"error: invalid value for {option}: {path}: "), r.output
    return line


def test_an_unwritable_out_or_run_dir_is_refused_before_training(
    small_dataset: Path, tmp_path: Path
) -> None:
    """A studio audit (2026-12-07): ``train --out /proc/models-x`` trained every stage, then
    died with a traceback (FileNotFoundError on its ``.partial`` folder), exit 1; likewise
    ``--run-dir /proc/runs``. Each is now checked before any work (a file is made and
    removed where it goes): one line naming the option, exit 2. (Tests run as root: a path
    under a regular file is one no one can write.)"""
    afile = tmp_path / "afile"
    afile.write_text("not a folder\n")
    run, out = tmp_path / "run", tmp_path / "models"
    base = ["train", "--dataset", str(small_dataset)]
    line = _refused([*base, "--run-dir", str(run), "--out", str(afile / "out")], "--out",
                    afile / "out")  # fmt: skip
    assert line.endswith(f"{afile} is a file"), line
    assert not run.exists()  # nothing trained
    _refused([*base, "--run-dir", str(afile / "runs"), "--out", str(out)], "--run-dir",
             afile / "runs")  # fmt: skip
    _refused([*base, "--run-dir", str(afile / "a" / "runs"), "--out", str(out)], "--run-dir",
             afile / "a" / "runs")  # fmt: skip
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # no probe file left


def test_an_unwritable_dataset_out_is_refused_before_the_build(
    mocap_clips: Any, tmp_path: Path
) -> None:
    """``dataset --out /proc/x.npz`` built the whole dataset, then failed to write it."""
    afile = tmp_path / "afile"
    afile.write_text("not a folder\n")
    out = afile / "data" / "x.npz"
    args = ["dataset", "--mocap", str(mocap_clips.root), "--out", str(out)]
    line = _refused(args, "--out", out)
    assert line.endswith(f"{afile} is a file, so {afile / 'data'} cannot be made"), line


def test_a_dataset_out_that_is_another_file_or_in_the_mocap_is_refused(
    mocap_clips: Any, small_dataset: Path, models_dir: Path, tmp_path: Path
) -> None:
    """A studio audit (2026-12-07): ``dataset --out models/manifest.json`` overwrote the
    manifest with a zip, without a word; ``--out <mocap>/x.npz`` wrote into the folder the
    build reads (its digest changed next build). Both are refused before the build, naming
    the path, the file left as it was; a dataset file there is rebuilt (``make dataset``)."""
    import shutil

    victim = tmp_path / "manifest.json"
    shutil.copy(models_dir / "manifest.json", victim)
    before = victim.read_bytes()
    args = ["dataset", "--mocap", str(mocap_clips.root), "--out", str(victim)]
    line = _refused(args, "--out", victim)
    assert "exists and is not a dataset file `pose-trainer dataset` wrote" in line, line
    assert victim.read_bytes() == before

    inside = mocap_clips.root / "poses.npz"
    args = ["dataset", "--mocap", str(mocap_clips.root), "--out", str(inside)]
    line = _refused(args, "--out", inside)
    assert f"is inside the mocap folder {mocap_clips.root}" in line, line
    assert not inside.exists()

    again = tmp_path / "poses.npz"
    shutil.copy(small_dataset, again)
    args = ["dataset", "--mocap", str(mocap_clips.root), "--out", str(again), "--workers", "1"]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 0, r.output
