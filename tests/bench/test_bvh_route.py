"""``python -m bench.bvh_route``: a row per file, the route's steps timed on a real file."""

from __future__ import annotations

from pathlib import Path

from bench.bvh_route import app, reshaped
from tests.bench.tables import table_of


def test_a_row_per_file_with_each_step_timed(bvh_files: dict[str, Path], models_dir: Path) -> None:
    args = [str(bvh_files["bandai"]), "--models", str(models_dir), "--calls", "1"]
    header, (row,) = table_of(app, args)
    assert header.startswith("| file | MB | frames | read whole | read the frame")
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[0] == bvh_files["bandai"].name and cells[2] == "195"
    times = [float(c) for c in cells[3:]]
    assert all(t > 0 for t in times) and len(times) == 5


def test_a_file_reshaped_holds_the_same_frames_wrapped_and_repeated(
    bvh_files: dict[str, Path],
) -> None:
    """``--frames`` repeats a real file's frames, ``--wrap`` writes them K values a line with
    CRLF and a byte order mark: the reader gives back the same values, frame for frame."""
    from core.bvh import parse_bvh

    text = bvh_files["bandai"].read_text()
    bvh = parse_bvh(text)
    big = reshaped(text, frames=500, wrap=11)
    assert big.startswith("\ufeff") and "\r\n" in big and "\n" not in big.replace("\r\n", "")
    assert all(len(line.split()) <= 11 for line in big.split("MOTION")[1].splitlines()[3:])
    again = parse_bvh(big)
    assert again.num_frames == 500 and [j.name for j in again.joints] == [
        j.name for j in bvh.joints
    ]
    n = bvh.num_frames
    assert 2 * n <= 500, n  # (a whole second copy)
    assert (again.motion[:n] == bvh.motion).all() and (
        again.motion[n : 2 * n] == bvh.motion[: 500 - n]
    ).all()
    assert reshaped(text) == text
