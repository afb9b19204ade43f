"""``python -m bench.bvh_route``: a row per file, the route's steps timed on a real file."""

from __future__ import annotations

from pathlib import Path

from bench.bvh_route import app
from tests.bench.tables import table_of


def test_a_row_per_file_with_each_step_timed(bvh_files: dict[str, Path], models_dir: Path) -> None:
    args = [str(bvh_files["bandai"]), "--models", str(models_dir), "--calls", "1"]
    header, (row,) = table_of(app, args)
    assert header.startswith("| file | MB | frames | read whole | read the frame")
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[0] == bvh_files["bandai"].name and cells[2] == "195"
    times = [float(c) for c in cells[3:]]
    assert all(t > 0 for t in times) and len(times) == 5
