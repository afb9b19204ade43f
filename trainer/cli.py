"""`pose-trainer`: build the dataset, train and export the pose models (the accuracy
benchmark is `python -m bench`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Optional

import typer

app = typer.Typer(
    name="pose-trainer",
    help="Marionette trainer: mocap -> canonical pose dataset -> models -> ONNX + manifest.",
    no_args_is_help=True,
    add_completion=False,
)


#: What an interrupted ``train`` / ``export`` says after "interrupted; " (Ctrl-C, SIGINT;
#: exit 130): every stage checkpoints each epoch (written whole: ``core.io.write_atomic``)
#: and resumes from there; the export writes a folder beside ``out_dir`` and renames it.
INTERRUPTED = (
    "re-run the same command to resume: each stage resumes from its last epoch's "
    "checkpoint in {run_dir} (--fresh starts every stage anew)"
)
#: ``--accept-implausible``'s help (``train``, ``export``).
ACCEPT_HELP = (
    "Train on a dataset whose poses look implausible for their map (a wrong `unit` or "
    "`up_axis`?), which is refused otherwise (config: accept_implausible)."
)


def _finite(value: float) -> float:
    """A float option's value, refused unless finite: click reads ``1e999`` as ``inf``, and
    its ranges let ``nan`` through (every comparison with it is false)."""
    if not math.isfinite(value):
        raise typer.BadParameter(f"{value} is not a finite number")
    return value


def _check_writable(folder: Path, option: str, path: Path) -> None:
    """Refuse, before any work, an output ``path`` (of ``option``) whose ``folder`` cannot
    be made or written: its nearest existing folder must be a folder in which a file can be
    made (one is made and removed). One line, exit 2 (a bad option's code); ``train --out
    /proc/models`` trained every stage, then failed on its ``.partial`` folder with a
    traceback, and ``dataset --out /proc/x.npz`` after the whole build."""
    import os
    import tempfile

    there = folder
    while not there.exists() and not there.is_symlink() and there != there.parent:
        there = there.parent
    why = None
    if not there.is_dir():
        why = f"{there} is {'a file' if there.is_file() else 'no folder'}" + (
            "" if there == folder else f", so {folder} cannot be made"
        )
    else:
        try:
            fd, probe = tempfile.mkstemp(dir=there, prefix=".marionette-probe-")
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            why = f"cannot write in {there} ({exc.strerror or exc})"
    if why is not None:
        typer.echo(f"error: invalid value for {option}: {path}: {why}", err=True)
        raise typer.Exit(2)


def _train_and_export(
    config: Path | None,
    quick: bool,
    fresh: bool,
    dataset: Path | None,
    out: Path | None,
    run_dir: Path | None,
    export: bool,
    accept_implausible: bool = False,
) -> None:
    import json
    import time

    from trainer.config import QUICK, load_config, recipe_warning

    overrides: dict[str, object] = dict(QUICK) if quick else {}
    if dataset is not None:
        overrides["dataset"] = str(dataset)
    if run_dir is not None:
        overrides["run_dir"] = str(run_dir)
    elif quick:
        overrides["run_dir"] = "runs/quick"
    if accept_implausible:
        overrides["accept_implausible"] = True
    if out is not None:
        overrides["out_dir"] = str(out)
    elif quick:  # a smoke run replaced the config's models (the shipped `models/`) whole
        overrides["out_dir"] = str(Path(str(overrides["run_dir"])) / "models")
    try:  # a config that cannot be read: one line, not a traceback (as `serving` says it)
        cfg = load_config(config, overrides)
    except (OSError, ValueError) as exc:  # missing file, TOML, a setting wrong (pydantic)
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    if (recipe := recipe_warning(config, cfg.out_dir)) is not None:
        typer.echo(f"warning: {recipe}", err=True)
    run_path, out_path = Path(cfg.run_dir), Path(cfg.out_dir)
    _check_writable(run_path, "--run-dir" if run_dir is not None else "run_dir", run_path)
    if export:  # (the export makes its folder beside out_dir, then renames it)
        _check_writable(out_path.parent, "--out" if out is not None else "out_dir", out_path)

    from rich.table import Table

    from trainer.stages import console
    from trainer.train import train_all

    if export:  # before the training: a folder the export would refuse (trainer.export)
        from trainer.export import check_replaceable

        try:
            check_replaceable(Path(cfg.out_dir), Path(cfg.run_dir))
        except FileExistsError as exc:  # one line: a path in a usage box was broken up
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(1) from None
    from trainer.data.dataset import DatasetError
    from trainer.stages import CheckpointError

    t0 = time.perf_counter()
    try:
        trained = train_all(cfg, fresh=fresh)
        if int(__import__("os").environ.get("RANK", "0")) != 0 or not export:
            return
        from trainer.export import evaluate, export_all

        metrics = evaluate(cfg, trained)
        manifest = export_all(cfg, trained, metrics)
    except (DatasetError, CheckpointError) as exc:  # missing, unreadable, a split empty
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    except KeyboardInterrupt:  # (exit 130 without a word: a studio audit, 2026-12-07)
        typer.echo(f"interrupted; {INTERRUPTED.format(run_dir=cfg.run_dir)}", err=True)
        raise typer.Exit(130) from None
    seconds = time.perf_counter() - t0
    table = Table(title=f"models in {cfg.out_dir} (manifest {manifest.version})")
    for col in ("model", "params", "bytes", "val", "test"):
        table.add_column(col, justify="right" if col != "model" else "left")
    for entry in manifest.models:
        vals = metrics.get(entry.name, {})

        def fmt(split: str, vals: dict[str, dict[str, float]] = vals) -> str:
            return ", ".join(f"{k} {v:.2f}" for k, v in vals.get(split, {}).items())

        table.add_row(entry.name, str(entry.parameters), str(entry.bytes), fmt("val"), fmt("test"))
    console.print(table)
    training = {k: round(s.seconds, 1) for k, s in trained.states.items()}
    console.print(f"training seconds per stage: {training}; wall {seconds:.1f}s")
    report = {"metrics": metrics, "training_seconds": training, "wall_seconds": seconds}
    Path(cfg.run_dir, "metrics.json").write_text(json.dumps(report, indent=2) + "\n")


@app.command()
def train(
    config: Annotated[Optional[Path], typer.Option(help="Training config (TOML).")] = None,  # noqa: UP045
    quick: Annotated[
        bool,
        typer.Option(
            help="Smoke run of every stage and the export (about a minute: the training a few "
            "seconds, the evaluation and export the rest): checkpoints in runs/quick, models "
            "in <run dir>/models (unless --run-dir / --out)."
        ),
    ] = False,
    fresh: Annotated[bool, typer.Option(help="Ignore checkpoints; start anew.")] = False,
    dataset: Annotated[Optional[Path], typer.Option(help="Override the dataset path.")] = None,  # noqa: UP045
    out: Annotated[Optional[Path], typer.Option(help="Override the models directory.")] = None,  # noqa: UP045
    run_dir: Annotated[Optional[Path], typer.Option(help="Checkpoint directory.")] = None,  # noqa: UP045
    export: Annotated[bool, typer.Option(help="Export ONNX + manifest at the end.")] = True,
    accept_implausible: Annotated[bool, typer.Option(help=ACCEPT_HELP)] = False,
) -> None:
    """Train the autoencoder, the solvers and the completion levels, then export.

    Resumes from the checkpoints in the run directory. Runs under
    `torchrun --nproc_per_node N` as DDP (gloo); rank 0 writes."""
    _train_and_export(config, quick, fresh, dataset, out, run_dir, export, accept_implausible)


@app.command("export")
def export_cmd(
    config: Annotated[Optional[Path], typer.Option(help="Training config (TOML).")] = None,  # noqa: UP045
    quick: Annotated[
        bool, typer.Option(help="The --quick run's checkpoints, into <run dir>/models.")
    ] = False,
    dataset: Annotated[Optional[Path], typer.Option(help="Override the dataset path.")] = None,  # noqa: UP045
    out: Annotated[Optional[Path], typer.Option(help="Override the models directory.")] = None,  # noqa: UP045
    run_dir: Annotated[Optional[Path], typer.Option(help="Checkpoint directory.")] = None,  # noqa: UP045
    accept_implausible: Annotated[bool, typer.Option(help=ACCEPT_HELP)] = False,
) -> None:
    """Evaluate and export finished checkpoints (trains whatever stage is unfinished)."""
    _train_and_export(config, quick, False, dataset, out, run_dir, True, accept_implausible)


@app.command()
def dataset(
    mocap: Annotated[
        Path, typer.Option(help="Folder with the mocap archives (or extracted folders).")
    ] = Path("../shared/mocap"),
    out: Annotated[Path, typer.Option(help="Output .npz file.")] = Path("data/poses.npz"),
    seed: Annotated[int, typer.Option(help="Seed of the train/val/test split.")] = 0,
    workers: Annotated[int, typer.Option(help="Worker processes.", min=1)] = 2,
    maps: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option(help="Folder of joint maps (*.toml); default: trainer/maps."),
    ] = None,
) -> None:
    """Build the canonical pose dataset (one .npz) from the mocap archives."""
    import sys

    from rich.console import Console

    from trainer.data.build import BuildError, build_dataset, out_problem, print_summary
    from trainer.data.maps import MapError

    console = Console() if sys.stdout.isatty() else Console(width=100)
    if out.is_dir():  # (it failed at the end of the build, with a traceback)
        raise typer.BadParameter(
            f"{out} is a folder: give the dataset file's name (e.g. {out / 'poses.npz'})",
            param_hint="--out",
        )
    if (problem := out_problem(out, mocap)) is not None:  # (overwritten, or in the mocap)
        typer.echo(f"error: invalid value for --out: {problem}", err=True)
        raise typer.Exit(2)
    _check_writable(out.parent, "--out", out)
    try:
        report = build_dataset(
            mocap, out, maps_dir=maps, seed=seed, workers=workers, log=console.print
        )
    except (BuildError, MapError) as exc:  # as text: "[[override]] #6" is no markup
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    print_summary(report, console)


@app.command("plot-data")
def plot_data(
    dataset: Annotated[Path, typer.Option(help="Dataset .npz.")] = Path("data/poses.npz"),
    out: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option(help="Output PNG; default: the dataset's path with .png (data/poses.png)."),
    ] = None,
    per_source: Annotated[int, typer.Option(help="Poses drawn per source.")] = 12,
    seed: Annotated[int, typer.Option(help="Seed of the pose draw.")] = 0,
) -> None:
    """Draw random canonical poses of each source as stick figures (PNG)."""
    from trainer.data.dataset import DatasetError
    from trainer.data.plot import plot_dataset

    # (the default was docs/img/data_poses.png: a studio's check of its own data replaced
    # the shipped data's figure in the repository)
    out = dataset.with_suffix(".png") if out is None else out
    try:
        path = plot_dataset(dataset, out, per_source=per_source, seed=seed)
    except DatasetError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"wrote {path}")


@app.command("bend-sides")
def bend_sides(
    dataset: Annotated[Path, typer.Option(help="Dataset .npz.")] = Path("data/poses.npz"),
    every: Annotated[int, typer.Option(min=1, help="Fit on every n-th pose.")] = 3,
    split: Annotated[str, typer.Option(help="The split whose poses to fit on.")] = "train",
    min_bend: Annotated[
        float,
        typer.Option(min=0.001, callback=_finite, help="Limbs bent less (m) are left out."),
    ] = 0.02,
) -> None:
    """Fit the side elbows and knees bend to on a split of the dataset (trainer.bend_sides;
    core.ends' tables, which serving.bend_side uses, are the train split's), beside core.ends'
    own tables on the same poses."""
    import numpy as np

    from core.ends import BEND_ELBOW, BEND_KNEE
    from trainer.bend_sides import agreement, fit_sides, lines_and_sides
    from trainer.data.dataset import DatasetError, load_dataset

    try:
        data = load_dataset(dataset)
        poses = data.positions[data.split_mask(split)][::every].astype(np.float64)
        for limb, shipped in (("elbow", BEND_ELBOW), ("knee", BEND_KNEE)):
            fit = fit_sides(poses, limb, min_bend)
            share, cosine = agreement(shipped, *lines_and_sides(poses, limb, min_bend))
            typer.echo(
                f"{limb}: {np.round(fit.w, 3).tolist()}\n  {fit.limbs} limbs; within 90 degrees "
                f"of their side: {fit.agree:.4f} (mean cosine {fit.cosine:.3f}); core.ends' "
                f"table: {share:.4f} ({cosine:.3f})"
            )
    except (DatasetError, ValueError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None


@app.command("serving")
def serving_cmd(
    config: Annotated[Path, typer.Option(help="Config whose serving settings to apply (TOML).")],
    models: Annotated[Path, typer.Option(help="Models directory.")] = Path("models"),
) -> None:
    """Set the models' serving block (manifest.json, new version) from a config's serving
    settings, without retraining; refuses a setting the losses were trained with."""
    from core.manifest import ManifestError
    from trainer.config import load_config
    from trainer.serving import not_applied, set_serving

    try:  # a config not found or not valid, models not found or tampered with, a refusal
        cfg = load_config(config)
        manifest, changed = set_serving(cfg, models)
    except (OSError, ValueError, ManifestError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    if ignored := not_applied(cfg, manifest):  # (they were ignored without a word)
        typer.echo(
            f"warning: {config}: settings that need retraining, not applied: " + "; ".join(ignored),
            err=True,
        )
    if not changed:
        typer.echo(f"{models}: serving already as in {config} ({manifest.version})")
        return
    listed = ", ".join(f"{k} {v['from']!r} -> {v['to']!r}" for k, v in changed.items())
    typer.echo(f"{models}: {listed}; version {manifest.version}")


@app.command("mirror")
def mirror_cmd(
    models: Annotated[Path, typer.Option(help="Models directory.")] = Path("models"),
) -> None:
    """Write the models' mirror graphs (``mirror_<key>.onnx``: an edit and its mirror image
    in one run, ``trainer.mirror``) from their fused graphs; manifest.json gets their
    entries and a new version. The networks and the answers stay as they were."""
    from core.manifest import ManifestError
    from trainer.mirror import add_mirror_graphs

    try:  # models not found or tampered with, or a graph that does not check out
        manifest = add_mirror_graphs(models)
    except (OSError, ValueError, RuntimeError, ManifestError) as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    typer.echo(f"{models}: {len(manifest.mirrors())} mirror graphs; version {manifest.version}")


@app.command("model-card")
def model_card(
    models: Annotated[Path, typer.Option(help="Models directory.")] = Path("models"),
) -> None:
    """Render models/README.md (the model card) from the manifest."""
    from core.manifest import load_manifest
    from trainer.model_card import write_model_card

    path = write_model_card(models, load_manifest(models, verify=True))
    typer.echo(f"wrote {path}")


def main() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":
    main()
