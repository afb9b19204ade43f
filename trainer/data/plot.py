"""``pose-trainer plot-data``: random canonical poses of each source as stick figures."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from core.io import write_atomic
from core.skeleton import BONES, JOINT_NAMES
from trainer.data.dataset import load_dataset

LEFT_COLOUR = "#d62728"  # red
RIGHT_COLOUR = "#1f77b4"  # blue
CENTRE_COLOUR = "#333333"


def _colour(joint: int) -> str:
    name = JOINT_NAMES[joint]
    if name.startswith("left_"):
        return LEFT_COLOUR
    if name.startswith("right_"):
        return RIGHT_COLOUR
    return CENTRE_COLOUR


def plot_dataset(
    dataset: str | Path, out: str | Path, *, per_source: int = 12, seed: int = 0
) -> Path:
    """Draw ``per_source`` random poses of each source: a front view (looking at the
    character, which faces +Z: its left, +X, is on the right of the picture) and a side view
    (+Z to the right, so the character faces right). Written atomically as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ds = load_dataset(dataset)
    rng = np.random.default_rng(seed)
    sources = sorted(set(ds.clip_source.tolist()))
    fig, axes = plt.subplots(
        2 * len(sources),
        per_source,
        figsize=(1.3 * per_source, 1.75 * 2 * len(sources) + 0.4),
        squeeze=False,
    )
    for row, source in enumerate(sources):
        idx = np.flatnonzero(ds.source_mask(source))
        pick = np.sort(rng.choice(idx, size=min(per_source, len(idx)), replace=False))
        for col in range(per_source):
            front, side = axes[2 * row, col], axes[2 * row + 1, col]
            for ax in (front, side):
                ax.set_aspect("equal")
                ax.set_xticks([])
                ax.set_yticks([])
                ax.set_xlim(-0.95, 0.95)
                ax.set_ylim(-0.1, 2.05)
                ax.axhline(0.0, color="#bbbbbb", lw=0.6)
            if col >= len(pick):
                continue
            pose = ds.positions[pick[col]]
            for child, parent in BONES:
                colour = _colour(child)
                for ax, axis in ((front, 0), (side, 2)):
                    ax.plot(
                        [pose[parent, axis], pose[child, axis]],
                        [pose[parent, 1], pose[child, 1]],
                        color=colour,
                        lw=1.6,
                        solid_capstyle="round",
                    )
            for ax, axis in ((front, 0), (side, 2)):
                ax.scatter(pose[:, axis], pose[:, 1], s=3, c=[_colour(j) for j in range(21)])
            clip = int(ds.clip[pick[col]])
            name = str(ds.clip_name[clip]).split("/", 1)[-1].replace("dataset-", "d")
            name = name.replace("_", " ")
            front.set_title(f"{name} #{int(ds.frame[pick[col]])}", fontsize=4.5, wrap=True)
        axes[2 * row, 0].set_ylabel(f"{source}\nfront (x right)", fontsize=8)
        axes[2 * row + 1, 0].set_ylabel(f"{source}\nside (+z right)", fontsize=8)
    fig.suptitle(
        f"{Path(dataset).name}: random canonical poses (seed {seed}); "
        "left side red, right side blue, centre grey; front view: +X (left) on the right, "
        "side view: facing +Z = right",
        fontsize=9,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.97), h_pad=0.4, w_pad=0.2)
    out = Path(out)
    try:
        buf = io.BytesIO()
        fig.savefig(buf, dpi=110, format="png")
        write_atomic(out, buf.getvalue())
    finally:
        plt.close(fig)
    return out
