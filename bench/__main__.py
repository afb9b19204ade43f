"""`python -m bench`: accuracy (trainer.evaluate) + in-process speed + HTTP load ->
<out>/report.md, results.json and PNG plots. See docs/benchmarks.md."""

from __future__ import annotations

import os

# one thread everywhere, before numpy / onnxruntime are imported
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402


def _log(msg: str) -> None:
    print(f"[bench {time.strftime('%H:%M:%S')}] {msg}", flush=True)


def run(argv: list[str] | None = None) -> Path:
    from bench import http_load, plots, speed
    from service.engine import Engine
    from trainer.data.dataset import load_dataset
    from trainer.evaluate import (
        FIVE,
        QUICK,
        EvalConfig,
        _idx,
        accuracy_plots,
        edits_from_pairs,
        evaluate_accuracy,
        machine,
        render_report,
        sample_pairs,
        test_split,
        write_json,
    )

    ap = argparse.ArgumentParser(prog="python -m bench", description=__doc__)
    ap.add_argument("--models", type=Path, default=Path("models"), help="models directory")
    ap.add_argument("--dataset", type=Path, default=Path("data/poses.npz"))
    ap.add_argument("--out", type=Path, default=Path("reports"))
    ap.add_argument("--quick", action="store_true", help="a handful of items (smoke run)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-accuracy", action="store_true")
    ap.add_argument("--skip-http", action="store_true")
    args = ap.parse_args(argv)
    if not (args.models / "manifest.json").is_file():
        ap.error(f"no manifest.json in {args.models}")
    if not args.dataset.is_file():
        ap.error(f"no dataset at {args.dataset} (build it: pose-trainer dataset)")
    args.out.mkdir(parents=True, exist_ok=True)
    cfg = dataclasses.replace(QUICK if args.quick else EvalConfig(), seed=args.seed)
    t_start = time.perf_counter()
    results: dict[str, Any] = {}
    plot_files: dict[str, str] = {}
    if not args.skip_accuracy:
        _log(f"accuracy with {args.models}")
        acc = evaluate_accuracy(args.models, args.dataset, cfg)
        results = acc.results
        plot_files.update(accuracy_plots(acc, args.out))
    else:
        results["machine_start"] = machine()
    seconds = dict(results.get("seconds", {}))

    # speed: the same kind of B1 edits (own seed), 1, 2 and 5 targets
    t0 = time.perf_counter()
    engine = Engine(args.models, threads=1)
    test = test_split(load_dataset(args.dataset))
    n_edits = 64 if args.quick else 1024
    a, b = sample_pairs(test, n_edits, np.random.default_rng(args.seed + 100))
    target_sets = {
        1: ("left_wrist", ("left_wrist",)),
        2: ("left_wrist+right_wrist", ("left_wrist", "right_wrist")),
        5: (FIVE, ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")),
    }
    edit_sets = {
        k: (name, edits_from_pairs(test, a, b, [_idx(j)] * len(a)))
        for k, (name, j) in target_sets.items()
    }
    _log("in-process latency")
    lat = speed.latency(
        engine, edit_sets, calls=40 if args.quick else 2000, warmup=5 if args.quick else 50
    )
    _log("in-process throughput")
    sizes = (1, 4, 16) if args.quick else (1, 4, 16, 64, 256, 1024, 4096)
    thr = speed.throughput(
        engine,
        edit_sets[2][1],
        sizes=sizes,
        fabrik_sizes=(1, 16) if args.quick else (1, 16, 256),
        min_seconds=0.05 if args.quick else 0.5,
        min_items=64 if args.quick else 4096,
    )
    results["speed"] = {
        **lat,
        "throughput": thr,
        "throughput_set": "both wrists (2 targets), B1 edits",
    }
    for row in lat["latency"]:
        _log(f"  {row['targets']} targets {row['method']}: p50 {row['p50_ms']:.3f} ms")
    seconds["speed"] = round(time.perf_counter() - t0, 1)
    if "speed" in results:
        plots.plot_latency(results["speed"], args.out / "latency.png")
        plot_files["latency"] = "latency.png"

    write_json(results, args.out / "results.json")  # a checkpoint before the HTTP part
    if not args.skip_http:
        t0 = time.perf_counter()
        _log("HTTP load against pose-service on loopback")
        try:
            results["http"] = http_load.run_http(
                args.models,
                edit_sets[2][1],
                solve_set="both wrists (2 targets), neural + bone pass",
                requests=60 if args.quick else 3000,
                seconds=5.0 if args.quick else 15.0,
                batch_size=32 if args.quick else 1024,
                batches=2 if args.quick else 12,
                warmup=10 if args.quick else 200,
                log=args.out / "server.log" if args.quick else None,
            )
        except RuntimeError as exc:  # report what was measured, and why HTTP was not
            _log(f"HTTP part failed: {exc}")
            results["http_error"] = str(exc)
        for row in results.get("http", {}).get("solve", []):
            _log(f"  c={row['concurrency']}: p50 {row['p50_ms']:.2f} ms, {row['rps']:.0f} req/s")
        if results.get("http"):
            _log(f"  batch: {results['http']['batch']['poses_per_s']:.0f} poses/s")
        seconds["http"] = round(time.perf_counter() - t0, 1)
    plots.plot_throughput(results["speed"], results.get("http"), args.out / "throughput.png")
    plot_files["throughput"] = "throughput.png"

    seconds["bench_total"] = round(time.perf_counter() - t_start, 1)
    results["seconds"] = seconds
    results["machine_end"] = machine()
    results["generated"] = time.strftime("%Y-%m-%d %H:%M:%S %Z")
    results["command"] = "python -m bench " + " ".join(sys.argv[1:] if argv is None else argv)
    results.setdefault("models", {"dir": str(args.models), "version": engine.version})
    write_json(results, args.out / "results.json")
    report = Path(args.out) / "report.md"
    report.write_text(render_report(results, plot_files, "Marionette benchmark report"))
    _log(f"wrote {report} in {seconds['bench_total']:.0f} s")
    if "http_error" in results:
        raise SystemExit(f"HTTP part failed: {results['http_error']}")
    return report


if __name__ == "__main__":
    run()
