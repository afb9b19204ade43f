"""The benchmark on a handful of items (`--quick`) against the models: the report,
results and plots are written and the metrics are finite and sane. No timing is asserted
(only that timings were measured)."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from bench.accuracy import QUICK

REPO_ROOT = Path(__file__).resolve().parents[2]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def models_dir() -> Path:
    env = os.environ.get("MARIONETTE_MODELS")
    path = Path(env) if env else REPO_ROOT / "models"
    if not (path / "manifest.json").is_file():
        pytest.skip(f"no trained models in {path} (manifest.json missing)")
    return path


def _walk_numbers(obj: Any, where: str = "") -> list[tuple[str, float]]:
    if isinstance(obj, bool) or obj is None or isinstance(obj, str):
        return []
    if isinstance(obj, int | float):
        return [(where, float(obj))]
    if isinstance(obj, dict):
        return [n for k, v in obj.items() for n in _walk_numbers(v, f"{where}.{k}")]
    if isinstance(obj, list):
        return [n for i, v in enumerate(obj) for n in _walk_numbers(v, f"{where}[{i}]")]
    return []


def _check_plots(out: Path, report: str) -> None:
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report)
    assert images, "the report references no plot"
    for name in images:
        png = out / name
        assert png.is_file(), f"{name} referenced but not written"
        assert png.read_bytes()[:8] == PNG_MAGIC
        assert png.stat().st_size > 5000


def test_quick_bench_writes_a_sane_report(
    models_dir: Path, bench_dataset: Path, tmp_path: Path
) -> None:
    out = tmp_path / "reports"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "bench",
            "--quick",
            "--models",
            str(models_dir),
            "--dataset",
            str(bench_dataset),
            "--out",
            str(out),
        ],
        cwd=REPO_ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    report = (out / "report.md").read_text()
    results = json.loads((out / "results.json").read_text())
    for section in (
        "## Goals",
        "### B1",
        "### B2",
        "### B3",
        "### B4",
        "### B5",
        "### Determinism",
        "### Composition ablation",
        "## Held-out bodies",
        "### Goals on held-out bodies (issue 11)",
        "### Held-out bodies beside the in-studio test split",
        "### In-process latency",
        "### HTTP",
    ):
        assert section in report
    assert re.search(r"\*\*(met|not met)\*\*", report)
    for plot in (
        "reach_error.png",
        "mpjpe_distributions.png",
        "sample_poses.png",
        "latency.png",
        "throughput.png",
        "heldout.png",
    ):
        assert f"]({plot})" in report
    _check_plots(out, report)

    for where, value in _walk_numbers(results):
        if where.endswith("reach_p95") or where.endswith("loadavg"):
            continue
        assert math.isfinite(value), f"{where} = {value}"

    b1 = results["B1"]
    for name, block in b1.items():
        ident = block["identity"]
        assert ident["drift"] == 0.0, name
        assert ident["bone_max"] < 1e-6, name
        for method in ("fabrik", "neural_bone", "neural_exact"):
            s = block[method]
            assert s["finite"] == 100.0, (name, method)
            assert s["bone_max"] <= 1e-5, (name, method, s["bone_max"])
            assert 0.0 <= s["reach_mean"] < 200.0
            assert 0.0 < s["mpjpe"] < 200.0
        # the raw decoder output does not keep bone lengths; the bone pass does
        assert block["neural_raw"]["bone_max"] > block["neural_bone"]["bone_max"]
    for case, block in results["B5"].items():
        for method in ("fabrik", "neural_bone", "neural_exact"):
            assert block[method]["finite"] == 100.0, (case, method)
    for method in ("fabrik", "neural_bone", "neural_exact"):
        assert results["determinism"][method]["repeat_bitwise_equal"], method
    assert set(results["ablation"]) == {label for label, _ in QUICK.strategies}
    # B4: the five-target drag also without the turn search (the shipped models search),
    # the left wrist alone never searches
    five, wrist = results["B4"]["5 end effectors"], results["B4"]["left_wrist"]
    assert "neural_bone_no_turn" not in wrist
    assert five["neural_bone_no_turn"]["bone_max"] <= 1e-5
    assert "neural + bone pass, no turn search" in report
    assert results["B2"]
    assert all(lvl["neural"]["mpjpe"] > 0 for lvl in results["B2"].values())

    families = [f["name"] for f in results["heldout"]["families"]]
    assert any(n.endswith(": all") for n in families)
    assert "test: asymmetric bodies" in families
    # the same edits with the starts where they were captured: a pelvis target there is
    # away from the start, and the engine takes the body across to it (pelvis_travel)
    cap = {f["name"]: f for f in results["captured"]["families"]}
    pelvis = cap["holdout: all"]["sets"]["pelvis"]
    assert pelvis["identity"]["reach_mean"] > 1.0 > pelvis["neural_bone"]["reach_mean"]
    assert "starts where they were captured" in report

    speed = results["speed"]
    assert {r["targets"] for r in speed["latency"]} == {1, 2, 5}
    assert all(r["p50_ms"] > 0 and r["p99_ms"] >= r["p50_ms"] for r in speed["latency"])
    assert all(r["poses_per_s"] > 0 for r in speed["throughput"])
    http = results["http"]
    assert [r["concurrency"] for r in http["solve"]] == [1, 8, 64]
    assert all(r["errors"] == 0 and r["requests"] > 0 for r in http["solve"])
    assert http["batch"]["errors"] == 0
    assert http["batch"]["poses_per_s"] > 0
    assert all(v > 0 for v in http["rss_kb"].values())
    # the default passes and passes=1 side by side (issue 14's goals judge the default)
    for row in (http["solve_passes1"], http["batch_columnar_passes1"]):
        assert row["errors"] == 0 and row["p50_ms"] > 0
    # the columnar form with packed columns (base64 float64) beside JSON numbers
    packed, numbers = http["batch_columnar_packed"], http["batch_columnar"]
    assert packed["errors"] == 0 and packed["poses_per_s"] > 0
    assert packed["request_bytes"] < 0.7 * numbers["request_bytes"]
    assert "packed columns (base64 float64)" in report
    # the same requests at a drag's pace: each sent a display frame after the last
    paced = http["solve_paced"]
    assert paced["errors"] == 0 and paced["requests"] == 20 and paced["compute_p50_ms"] > 0
    assert paced["seconds"] >= 19 / 60 and "at a drag's pace" in report
    i14 = speed["issue14"]
    assert all(r["neural_passes1"]["p50_ms"] > 0 for r in i14["latency"])
    # the shipped mirror graphs beside the numpy way around the fused graphs, 1-5 targets
    assert [r["targets"] for r in i14["latency"]] == [1, 2, 5]
    assert all(r["neural_numpy_mirror"]["p50_ms"] > 0 for r in i14["latency"])
    assert "neural 1-target soft solve p50 (left_wrist)" in report
    assert "without the mirror graphs" in report
    # both ankles pinned beside the plain edit, on the sets without an ankle
    assert [r["targets"] for r in i14["latency"] if "neural_pinned" in r] == [1, 2]
    assert "ms with both ankles pinned" in report
    assert i14["batch_poses_per_s"]["solve_arrays_passes1"] > 0
    assert i14["batch_poses_per_s"]["solve_arrays_2threads"] > 0
    # the networks alone on the 2-target batch: the ceiling the solve's passes divide
    assert i14["network_set"] == "left_wrist+right_wrist" and i14["network_rows_per_s"] > 0
    assert "the networks alone: the fused graph of left_wrist+right_wrist" in report
    assert "on 2 threads" in report
    assert "at passes=1" in report


def test_accuracy_only_run_writes_a_report_without_speed(
    models_dir: Path, bench_dataset: Path, tmp_path: Path
) -> None:
    """What `pose-trainer evaluate` did: accuracy only (python -m bench --skip-...)."""
    import typer
    from typer.testing import CliRunner

    from bench.__main__ import run

    app = typer.Typer()
    app.command()(run)
    out = tmp_path / "acc"
    result = CliRunner().invoke(
        app,
        [
            "--quick",
            "--skip-heldout",
            "--skip-speed",
            "--skip-http",
            "--models",
            str(models_dir),
            "--dataset",
            str(bench_dataset),
            "--out",
            str(out),
        ],
    )
    assert result.exit_code == 0, result.output
    report = (out / "report.md").read_text()
    assert "### B1" in report
    assert "Not measured in this run" in report
    assert "## Held-out bodies" not in report
    _check_plots(out, report)
    results = json.loads((out / "results.json").read_text())
    assert results["B1"]
    assert results["B3"]
    assert results["B5"]
    assert "speed" not in results and "heldout" not in results
