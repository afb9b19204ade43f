"""The benchmark's plots (matplotlib, Agg): accuracy (reach, MPJPE distributions, sample
poses, composition ablation, drag paths), held-out bodies, and speed (latency, throughput)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from bench.accuracy import Accuracy
from bench.edits import COMPOSED5, FIVE, METHOD_LABEL, METHODS, short
from trainer.data.dataset import FPS

F64 = npt.NDArray[np.floating[Any]]
Json = dict[str, Any]

METHOD_COLOUR: dict[str, str] = {
    "identity": "#9e9e9e",
    "fabrik": "#ff7f0e",
    "neural_raw": "#aec7e8",
    "neural_bone": "#1f77b4",
    "neural_exact": "#2ca02c",
    "neural_bone_no_turn": "#9467bd",  # B4: the same, turn search off
    "rest_fabrik": "#ff7f0e",  # B2 baseline
    "neural": "#1f77b4",  # B2 completion
    "completion": "#1f77b4",  # held-out 6-point completion
}


def pyplot() -> Any:
    """matplotlib.pyplot with the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_reach(results: Json, path: Path) -> None:
    """Mean reach error (log scale) by method and target set, B1 then B3."""
    plt = pyplot()
    groups = [("B1", k) for k in results.get("B1", {})] + [("B3", k) for k in results.get("B3", {})]
    fig, ax = plt.subplots(figsize=(max(8.0, 0.75 * len(groups) + 2), 4.8))
    width = 0.8 / len(METHODS)
    for m, method in enumerate(METHODS):
        vals = [results[b][k][method]["reach_mean"] or np.nan for b, k in groups]
        xs = np.arange(len(groups)) + (m - (len(METHODS) - 1) / 2) * width
        ax.bar(
            xs,
            np.maximum(vals, 1e-4),
            width,
            label=METHOD_LABEL[method],
            color=METHOD_COLOUR[method],
        )
    ax.set_yscale("log")
    ax.set_ylim(bottom=1e-3)
    ax.axhline(1.0, color="k", lw=0.6, ls=":")
    ax.set_xticks(np.arange(len(groups)))
    ax.set_xticklabels([f"{b} {short(k)}" for b, k in groups], rotation=50, ha="right", fontsize=8)
    ax.set_ylabel("mean reach error (cm, log; floor 0.001)")
    ax.set_title("Reach error by method and target set (TEST split; dotted: 1 cm)", pad=28)
    ax.legend(fontsize=8, ncol=5, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    ax.grid(axis="y", which="both", alpha=0.25)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_mpjpe(mpjpe: dict[str, dict[str, F64]], path: Path) -> None:
    """Per-item MPJPE (all joints) distributions for a selection of sets."""
    plt = pyplot()
    wanted = [
        k
        for k in mpjpe
        if k.startswith("B1 ")
        and k.split(" ", 1)[1]
        in ("left_wrist", "head", "left_ankle", "left_wrist+right_wrist", FIVE)
    ]
    wanted += [k for k in mpjpe if k.startswith("B3 ")][-2:]
    wanted += [k for k in mpjpe if k.startswith("B2 ")]
    cols = 4
    rows = max(1, -(-len(wanted) // cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.0 * cols, 3.3 * rows), squeeze=False)
    for ax, key in zip(axes.flat, wanted, strict=False):
        methods = list(mpjpe[key])
        data = [v[np.isfinite(v)] for v in mpjpe[key].values()]
        box = ax.boxplot(data, showfliers=False, patch_artist=True, widths=0.6)
        for patch, m in zip(box["boxes"], methods, strict=True):
            patch.set_facecolor(METHOD_COLOUR.get(m, "#cccccc"))
        for med in box["medians"]:
            med.set_color("k")
        ax.set_xticks(range(1, len(methods) + 1))
        ax.set_xticklabels(
            [METHOD_LABEL.get(m, m) for m in methods], rotation=25, ha="right", fontsize=7
        )
        ax.set_title(short(key), fontsize=9)
        ax.set_ylabel("MPJPE to real pose (cm)", fontsize=8)
        ax.grid(axis="y", alpha=0.25)
    for ax in list(axes.flat)[len(wanted) :]:
        ax.axis("off")
    fig.suptitle("MPJPE distributions (all joints; boxes: quartiles, whiskers 1.5 IQR)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _stick(ax: Any, pose: F64, colour: str, lw: float = 1.6, ls: str = "-") -> None:
    from core.skeleton import BONES

    for child, parent in BONES:
        ax.plot(
            [pose[parent, 0], pose[child, 0]],
            [pose[parent, 1], pose[child, 1]],
            color=colour,
            lw=lw,
            ls=ls,
            solid_capstyle="round",
        )


def plot_samples(samples: list[Json], path: Path) -> None:
    """Like the paper's Figure 3: start + targets, FABRIK, neural, the real pose."""
    plt = pyplot()
    titles = ("start pose + targets", "FABRIK", "neural + bone pass", "real target pose")
    fig, axes = plt.subplots(len(samples), 4, figsize=(10, 3.0 * len(samples)), squeeze=False)
    for r, s in enumerate(samples):
        poses = (s["start"], s["fabrik"], s["neural"], s["goal"])
        colours = ("#555555", METHOD_COLOUR["fabrik"], METHOD_COLOUR["neural_bone"], "#2ca02c")
        everything = np.concatenate([p for p in poses if p is not None] + [s["targets"]])
        lo, hi = everything.min(axis=0), everything.max(axis=0)
        cx, span = (lo[0] + hi[0]) / 2, max(hi[0] - lo[0], hi[1] - lo[1]) / 2 + 0.1
        cy = (lo[1] + hi[1]) / 2
        for c, ax in enumerate(axes[r]):
            ax.set_aspect("equal")
            ax.set_xlim(cx - span, cx + span)
            ax.set_ylim(cy - span, cy + span)
            ax.set_xticks([])
            ax.set_yticks([])
            ax.axhline(0.0, color="#bbbbbb", lw=0.6)
            if poses[c] is None:
                continue
            if c in (1, 2):
                _stick(ax, s["start"], "#cccccc", lw=1.0)
            _stick(ax, poses[c], colours[c])
            ax.scatter(
                s["targets"][:, 0],
                s["targets"][:, 1],
                marker="x",
                s=60,
                c="#d62728",
                zorder=5,
                linewidths=2,
            )
            if r == 0:
                ax.set_title(titles[c], fontsize=10)
        axes[r, 0].set_ylabel(short(s["name"]), fontsize=9)
    fig.suptitle(
        "Sample TEST edits, front view (x right, y up); red x: targets, grey: start pose",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_ablation(results: Json, path: Path) -> None:
    plt = pyplot()
    abl = results.get("ablation", {})
    labels = list(abl)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
    cols = [(f"B1 {COMPOSED5}", "neural_bone"), ("B3 2+ joints", "neural_bone")]
    width = 0.8 / len(cols)
    x = np.arange(len(labels))
    for i, (key, method) in enumerate(cols):
        reach = [abl[s][f"{key}|{method}"]["reach_mean"] for s in labels]
        mp = [abl[s][f"{key}|{method}"]["mpjpe"] for s in labels]
        name = f"{key} ({METHOD_LABEL[method]})"
        axes[0].bar(x + i * width, reach, width, label=name)
        axes[1].bar(x + i * width, mp, width, label=name)
    axes[0].set_ylabel("mean reach error (cm)")
    axes[1].set_ylabel("MPJPE to real pose (cm)")
    for ax in axes:
        ax.set_xticks(x + width / 2, labels, rotation=20, ha="right", fontsize=7)
        ax.grid(alpha=0.3, axis="y")
    axes[1].legend(fontsize=7)
    fig.suptitle("Composition strategies for target sets no single solver covers")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_paths(paths: Json, path: Path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(
        1, max(1, len(paths)), figsize=(5 * max(1, len(paths)), 3.6), squeeze=False
    )
    for ax, (name, curves) in zip(axes[0], paths.items(), strict=False):
        for method, curve in curves.items():
            ax.plot(
                np.arange(len(curve)) / FPS,
                curve,
                label=METHOD_LABEL[method],
                color=METHOD_COLOUR[method],
            )
        ax.set_title(f"B4 drag path: {short(name)}", fontsize=10)
        ax.set_xlabel("time along the path (s)")
        ax.set_ylabel("untargeted joints: error to real frame (cm)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def accuracy_plots(acc: Accuracy, out_dir: Path) -> dict[str, str]:
    """Write the accuracy PNGs; returns {key: file name}."""
    out_dir.mkdir(parents=True, exist_ok=True)
    plots = {
        "reach": "reach_error.png",
        "mpjpe": "mpjpe_distributions.png",
        "samples": "sample_poses.png",
        "ablation": "composition_ablation.png",
        "paths": "drag_paths.png",
    }
    plot_reach(acc.results, out_dir / plots["reach"])
    plot_mpjpe(acc.mpjpe, out_dir / plots["mpjpe"])
    if acc.samples:
        plot_samples(acc.samples, out_dir / plots["samples"])
    else:
        del plots["samples"]
    plot_ablation(acc.results, out_dir / plots["ablation"])
    if acc.paths:
        plot_paths(acc.paths, out_dir / plots["paths"])
    else:
        del plots["paths"]
    return plots


def plot_latency(speed: Json, path: Path) -> None:
    plt = pyplot()
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
    plt = pyplot()
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


def plot_heldout(heldout: Any, path: Path) -> None:
    """Per set MPJPE bars (start / FABRIK / neural soft / neural exact), one panel per
    family (``heldout``: a :class:`bench.heldout.HeldoutResults`)."""
    from bench.heldout import COMPLETION
    from bench.heldout import METHODS as HELD

    plt = pyplot()
    families = heldout.families
    names = list(families[0].sets) if families else []
    fig, axes = plt.subplots(
        len(families), 1, figsize=(max(9.0, 0.6 * len(names) + 2), 2.7 * len(families)),
        squeeze=False, sharex=True,
    )  # fmt: skip
    width = 0.8 / len(HELD)
    for ax, fam in zip(axes[:, 0], families, strict=True):
        for k, method in enumerate(HELD):
            vals = []
            for name in names:
                block = fam.sets.get(name, {})
                m = "completion" if name == COMPLETION and method == "neural_bone" else method
                vals.append(block[m].mpjpe if m in block else np.nan)
            xs = np.arange(len(names)) + (k - (len(HELD) - 1) / 2) * width
            ax.bar(xs, vals, width, color=METHOD_COLOUR[method], label=METHOD_LABEL[method])
        ax.set_ylabel("MPJPE (cm)", fontsize=8)
        ax.set_title(fam.name, fontsize=9, loc="left")
        ax.grid(axis="y", alpha=0.25)
    axes[-1, 0].set_xticks(np.arange(len(names)))
    axes[-1, 0].set_xticklabels([short(n) for n in names], rotation=45, ha="right", fontsize=8)
    axes[0, 0].legend(fontsize=8, ncol=4, loc="lower center", bbox_to_anchor=(0.5, 1.12))
    fig.suptitle(
        "World-space edits: MPJPE to the real target pose by set and method "
        "(6-point completion: soft bar = Engine.complete)",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
