"""Speed plots: latency bars (neural vs FABRIK) and throughput vs batch size."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from trainer.evaluate import METHOD_COLOUR, METHOD_LABEL, _plt

Json = dict[str, Any]


def plot_latency(speed: Json, path: Path) -> None:
    plt = _plt()
    rows = speed["latency"]
    ks = sorted({r["targets"] for r in rows})
    methods = [
        m for m in ("neural_bone", "neural_exact", "fabrik") if any(r["method"] == m for r in rows)
    ]
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    width = 0.8 / len(methods)
    for i, m in enumerate(methods):
        sel = [next(r for r in rows if r["targets"] == k and r["method"] == m) for k in ks]
        p50 = np.asarray([r["p50_ms"] for r in sel])
        p99 = np.asarray([r["p99_ms"] for r in sel])
        xs = np.arange(len(ks)) + (i - (len(methods) - 1) / 2) * width
        ax.bar(xs, p50, width, color=METHOD_COLOUR[m], label=f"{METHOD_LABEL[m]} (p50)")
        ax.errorbar(
            xs, p50, yerr=[np.zeros_like(p50), p99 - p50], fmt="none", ecolor="k", capsize=3, lw=0.8
        )
        for x, v in zip(xs, p50, strict=True):
            ax.text(
                x,
                v * 0.9,
                f"{v:.2f}",
                ha="center",
                va="top",
                fontsize=7,
                color="white",
                fontweight="bold",
            )
    ax.set_xticks(np.arange(len(ks)))
    ax.set_xticklabels([f"{k} target{'s' if k > 1 else ''}" for k in ks])
    ax.set_ylabel("latency per solve (ms); whisker: p99")
    ax.set_yscale("log")
    ax.set_title("In-process latency, one thread: neural vs FABRIK")
    ax.legend(fontsize=8)
    ax.grid(axis="y", which="both", alpha=0.25)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_throughput(speed: Json, http: Json | None, path: Path) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    for m in ("neural_bone", "fabrik"):
        rows = [r for r in speed["throughput"] if r["method"] == m]
        if rows:
            ax.plot(
                [r["batch"] for r in rows],
                [r["poses_per_s"] for r in rows],
                marker="o",
                color=METHOD_COLOUR[m],
                label=f"in-process {METHOD_LABEL[m]}",
            )
    if http and http.get("batch"):
        b = http["batch"]
        ax.scatter(
            [b["batch_size"]],
            [b["poses_per_s"]],
            marker="*",
            s=160,
            color="#d62728",
            zorder=5,
            label="HTTP /v1/solve/batch",
        )
    ax.axhline(20000, color="k", ls=":", lw=0.8, label="goal: 20,000 poses/s (HTTP)")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("batch size (poses per call)")
    ax.set_ylabel("poses / s (one thread)")
    ax.set_title("Throughput vs batch size")
    ax.grid(which="both", alpha=0.25)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
