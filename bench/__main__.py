"""`python -m bench`: accuracy (bench.accuracy) + held-out bodies (bench.heldout) +
in-process speed + HTTP load -> <out>/report.md, results.json and PNG plots.
See docs/benchmarks.md."""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from rich.console import Console

console = Console(stderr=True)


def run(
    models: Annotated[Path, typer.Option(help="Models folder (manifest.json).")] = Path("models"),
    dataset: Annotated[Path, typer.Option(help="Dataset file.")] = Path("data/poses.npz"),
    out: Annotated[Path, typer.Option(help="Report folder.")] = Path("reports"),
    quick: Annotated[bool, typer.Option(help="A handful of items (smoke run).")] = False,
    seed: Annotated[int, typer.Option(help="Seed of every sample.")] = 0,
    skip_accuracy: Annotated[bool, typer.Option(help="No B1-B5 accuracy part.")] = False,
    skip_heldout: Annotated[bool, typer.Option(help="No held-out bodies part.")] = False,
    skip_speed: Annotated[bool, typer.Option(help="No in-process speed part.")] = False,
    skip_http: Annotated[bool, typer.Option(help="No HTTP load part.")] = False,
) -> Path:
    """Run the benchmark and write the report."""
    from bench import accuracy, heldout, http_load, plots, speed
    from bench.edits import (
        FIVE,
        LIMBS5,
        edits_from_pairs,
        joint_idx,
        sample_pairs,
        test_split,
    )
    from bench.report import render_report, write_json
    from service.engine import Engine
    from trainer.data.dataset import load_dataset

    if not (models / "manifest.json").is_file():
        raise typer.BadParameter(f"no manifest.json in {models}", param_hint="--models")
    if not dataset.is_file():
        raise typer.BadParameter(
            f"no dataset at {dataset} (build it: pose-trainer dataset)", param_hint="--dataset"
        )
    out.mkdir(parents=True, exist_ok=True)
    cfg = dataclasses.replace(accuracy.QUICK if quick else accuracy.EvalConfig(), seed=seed)
    t_start = time.perf_counter()
    results: dict[str, Any] = {}
    plot_files: dict[str, str] = {}
    # read once, for every part (the accuracy part read it again: 131 MB, ~3 s); not at
    # all when only the accuracy part runs
    data = None if skip_heldout and skip_speed and skip_http else load_dataset(dataset)
    if not skip_accuracy:
        console.log(f"accuracy with {models}")
        acc = accuracy.evaluate_accuracy(models, dataset, cfg, data)
        results = acc.results
        plot_files.update(plots.accuracy_plots(acc, out))
    else:
        results["machine_start"] = accuracy.machine()
    seconds = dict(results.get("seconds", {}))
    engine = Engine(models, threads=1)

    if data is None:
        pass  # (only the accuracy part)
    elif not skip_heldout and not data.split_mask("holdout").any():
        results["heldout_skipped"] = f"{dataset} has no 'holdout' split (no held-out bodies)"
        console.log(f"held-out bodies skipped: {results['heldout_skipped']}")
    elif not skip_heldout:
        t0 = time.perf_counter()
        console.log("held-out bodies")
        h_cfg = dataclasses.replace(heldout.QUICK if quick else heldout.HeldoutConfig(), seed=seed)
        held = heldout.run_heldout(engine, data, h_cfg, log=console.log)
        results["heldout"] = held.to_json()
        plots.plot_heldout(held, out / "heldout.png")
        plot_files["heldout"] = "heldout.png"
        seconds["heldout"] = round(time.perf_counter() - t0, 1)
        t0 = time.perf_counter()
        console.log("held-out bodies, starts where they were captured")
        c_cfg = dataclasses.replace(h_cfg, captured=True)
        results["captured"] = heldout.run_heldout(engine, data, c_cfg, log=console.log).to_json()
        seconds["captured"] = round(time.perf_counter() - t0, 1)

    edit_sets: dict[int, tuple[str, Any]] = {}
    if data is not None and not (skip_speed and skip_http):
        # speed and HTTP: the same kind of B1 edits (own seed), 1, 2 and 5 targets
        test = test_split(data)
        n_edits = 64 if quick else 1024
        a, b = sample_pairs(test, n_edits, np.random.default_rng(seed + 100))
        target_sets = {
            1: ("left_wrist", ("left_wrist",)),
            2: ("left_wrist+right_wrist", ("left_wrist", "right_wrist")),
            5: (FIVE, ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")),
        }
        edit_sets = {
            k: (name, edits_from_pairs(test, a, b, [joint_idx(j)] * len(a)))
            for k, (name, j) in target_sets.items()
        }
        # five targets no trained set covers whole: composed of five single-joint solvers
        composed = ("+".join(LIMBS5), edits_from_pairs(test, a, b, [joint_idx(LIMBS5)] * len(a)))
    if not skip_speed:
        t0 = time.perf_counter()
        console.log("in-process latency")
        lat = speed.latency(
            engine, edit_sets, calls=40 if quick else 2000, warmup=5 if quick else 50
        )
        console.log("in-process throughput")
        thr = speed.throughput(
            engine,
            edit_sets[2][1],
            sizes=(1, 4, 16) if quick else (1, 4, 16, 64, 256, 1024, 4096),
            fabrik_sizes=(1, 16) if quick else (1, 16, 256),
            min_seconds=0.05 if quick else 0.5,
            min_items=64 if quick else 4096,
        )
        console.log("issue 14: compiled solve vs compiled and numpy FABRIK, batch rate")
        i14 = speed.issue14(
            engine,
            {k: edit_sets[k] for k in (1, 2, 5)},
            composed={5: composed},
            calls=40 if quick else 2000,
            warmup=5 if quick else 50,
            batch=64 if quick else 4096,
            batch_rounds=2 if quick else 5,
        )
        results["speed"] = {
            **lat,
            "throughput": thr,
            "throughput_set": "both wrists (2 targets), B1 edits",
            "issue14": i14,
        }
        for row in i14["latency"] + i14["composed"]:
            console.log(
                f"  issue 14, {row['targets']} targets ({row['set']}):"
                f" neural {row['neural']['p50_ms']:.3f} ms,"
                f" FABRIK compiled {row['fabrik_compiled']['p50_ms']:.3f} ms"
                f" (kernel {row['fabrik_kernel']['p50_ms']:.4f}),"
                f" FABRIK numpy {row['fabrik_numpy']['p50_ms']:.3f} ms;"
                f" neural at passes=1 {row['neural_passes1']['p50_ms']:.3f} ms"
            )
        for label, rate in i14["batch_poses_per_s"].items():
            console.log(f"  issue 14, batch {i14['batch']} via {label}: {rate:,.0f} poses/s")
        for row in lat["latency"]:
            console.log(f"  {row['targets']} targets {row['method']}: p50 {row['p50_ms']:.3f} ms")
        seconds["speed"] = round(time.perf_counter() - t0, 1)
        plots.plot_latency(results["speed"], out / "latency.png")
        plot_files["latency"] = "latency.png"
        write_json(results, out / "results.json")  # a checkpoint before the HTTP part

    if not skip_http:
        t0 = time.perf_counter()
        console.log("HTTP load against pose-service on loopback")
        try:
            results["http"] = http_load.run_http(
                models,
                edit_sets[2][1],
                solve_set="both wrists (2 targets), neural + bone pass",
                requests=60 if quick else 3000,
                seconds=5.0 if quick else 15.0,
                batch_size=32 if quick else 1024,
                batches=2 if quick else 12,
                warmup=10 if quick else 200,
                paced=20 if quick else 400,
                log=out / "server.log" if quick else None,
            )
        except RuntimeError as exc:  # report what was measured, and why HTTP was not
            console.log(f"HTTP part failed: {exc}")
            results["http_error"] = str(exc)
        for row in results.get("http", {}).get("solve", []):
            console.log(
                f"  c={row['concurrency']}: p50 {row['p50_ms']:.2f} ms, {row['rps']:.0f} req/s"
            )
        if results.get("http"):
            h = results["http"]
            console.log(
                f"  c=1 at passes=1: p50 {h['solve_passes1']['p50_ms']:.2f} ms;"
                f" batch: {h['batch']['poses_per_s']:.0f} poses/s (item list),"
                f" columnar {h['batch_columnar']['poses_per_s']:.0f},"
                f" columnar at passes=1 {h['batch_columnar_passes1']['poses_per_s']:.0f},"
                f" columnar packed {h['batch_columnar_packed']['poses_per_s']:.0f}"
            )
        seconds["http"] = round(time.perf_counter() - t0, 1)
    if "speed" in results:
        plots.plot_throughput(results["speed"], results.get("http"), out / "throughput.png")
        plot_files["throughput"] = "throughput.png"

    seconds["bench_total"] = round(time.perf_counter() - t_start, 1)
    results["seconds"] = seconds
    results["machine_end"] = accuracy.machine()
    results["generated"] = time.strftime("%Y-%m-%d %H:%M:%S %Z")
    results["command"] = "python -m bench " + " ".join(sys.argv[1:])
    results.setdefault("models", {"dir": str(models), "version": engine.version})
    write_json(results, out / "results.json")
    report = out / "report.md"
    report.write_text(render_report(results, plot_files, "Marionette benchmark report"))
    console.log(f"wrote {report} in {seconds['bench_total']:.0f} s")
    if "http_error" in results:
        raise SystemExit(f"HTTP part failed: {results['http_error']}")
    return report


def main() -> None:
    typer.run(run)


if __name__ == "__main__":
    main()
