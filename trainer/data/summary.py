"""The summary ``pose-trainer dataset`` prints: clips and frames per source and split,
dropped frames and skipped files, mean bone lengths, then the skipped files and warnings."""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING, Any

import numpy as np
from rich.markup import escape

from core.skeleton import NUM_JOINTS
from trainer.data.build import BONE_NAMES, DROP_REASONS
from trainer.data.dataset import SPLITS

if TYPE_CHECKING:
    from trainer.data.build import BuildReport


def summary_tables(report: BuildReport) -> list[Any]:
    """Rich tables: clips/frames per source and split, drops, mean bone lengths."""
    from rich.table import Table

    ds, meta = report.dataset, report.meta
    sources = sorted(set(ds.clip_source.tolist()))
    counts = Table(title=f"{report.out}: clips / frames (30 fps) per source and split")
    counts.add_column("source")
    for s in SPLITS:
        counts.add_column(s, justify="right")
    counts.add_column("total", justify="right")
    frame_split = ds.clip_split[ds.clip]
    frame_source = ds.clip_source[ds.clip]
    for source in [*sources, "all"]:
        row = [source]
        csel = np.ones(ds.num_clips, bool) if source == "all" else ds.clip_source == source
        fsel = np.ones(len(ds), bool) if source == "all" else frame_source == source
        for split in SPLITS:
            nc = int((csel & (ds.clip_split == split)).sum())
            nf = int((fsel & (frame_split == split)).sum())
            row.append(f"{nc} / {nf:,}")
        row.append(f"{int(csel.sum())} / {int(fsel.sum()):,}")
        counts.add_row(*row)

    drops = Table(title="frames: source (native fps) -> 30 fps -> dropped -> kept")
    drops.add_column("source")
    for col in ("native", "at 30 fps", *DROP_REASONS, "kept", "files skipped"):
        drops.add_column(col, justify="right")
    skipped_by_source = Counter(f["file"].split(":", 1)[0] for f in meta["skipped_files"])
    for source in sorted(meta["dropped_frames_by_source"]):
        per = meta["dropped_frames_by_source"][source]
        drops.add_row(
            source,
            f"{meta['source_frames'].get(source, 0):,}",
            f"{meta['resampled_frames'].get(source, 0):,}",
            *[f"{per[r]:,}" for r in DROP_REASONS],
            f"{int((frame_source == source).sum()):,}",
            str(skipped_by_source.get(source, 0)),
        )

    bones = Table(title="mean bone lengths (m), bone named by its child joint")
    bones.add_column("bone")
    for source in sources:
        bones.add_column(source, justify="right")
    for b in BONE_NAMES:
        bones.add_row(b, *[f"{meta['mean_bone_lengths_m'][s][b]:.3f}" for s in sources])
    return [counts, drops, bones]


def print_summary(report: BuildReport, console: Any = None) -> None:
    from rich.console import Console

    console = console or Console()
    for table in summary_tables(report):
        console.print(table)
    meta = report.meta
    for item in meta["skipped_files"]:
        console.print(f"skipped: {escape(item['reason'])}")
    for warning in meta.get("warnings", []):
        console.print(f"[yellow]warning: {escape(warning)}")
    console.print(
        f"{meta['num_clips']} clips, {meta['num_frames']:,} poses ({NUM_JOINTS} joints) -> "
        f"{report.out} ({report.out.stat().st_size / 2**20:.1f} MiB) "
        f"in {meta['build_seconds']:.1f} s"
    )
