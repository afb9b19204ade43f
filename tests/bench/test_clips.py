"""``python -m bench.clips``: a real clip cleaned frame by frame, and how much the answers
jump and flip between frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.clips import SETS, app, clip_points, flips
from core.skeleton import JOINT_INDEX
from tests.bench.tables import table_of


def test_a_flip_is_a_bent_limb_turned_to_its_other_side(bvh_files: dict[str, Path]) -> None:
    poses = clip_points(bvh_files["bandai"], None, "replace", 30)
    assert poses.shape == (30, 21, 3) and not flips(poses).any()  # a real walk: none
    top, mid, end = (JOINT_INDEX[n] for n in ("left_shoulder", "left_elbow", "left_wrist"))
    turned = np.repeat(poses[:1], 3, axis=0)
    axis = turned[0, end] - turned[0, top]
    axis /= np.linalg.norm(axis)
    foot = turned[0, top] + 0.5 * (turned[0, end] - turned[0, top])
    across = np.cross(axis, [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    for size, want in ((0.08, [1, 1]), (0.04, [0, 0])):  # bent 8 cm: a flip; 4 cm: too little
        turned[:, mid] = foot + size * across * np.asarray([1.0, -1.0, 1.0])[:, None]
        assert flips(turned).tolist() == want
    turned[1, mid] = foot + 0.08 * (0.5 * across + 0.866 * np.cross(axis, across))  # 60 degrees
    turned[[0, 2], mid] = foot + 0.08 * across
    assert flips(turned).tolist() == [0, 0]


def test_a_row_per_set_with_each_method(bvh_files: dict[str, Path], models_dir: Path) -> None:
    args = [str(bvh_files["bandai"]), "--models", str(models_dir), "--frames", "40"]
    header, rows = table_of(app, args)
    assert header.startswith("| set | frame steps | motion p99 / max mm | clip flips | FABRIK:")
    assert len(rows) == len(SETS)
    for row, (name, _, _) in zip(rows, SETS, strict=True):
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert cells[:2] == [name, "39"] and cells[3] == "0"
        for cell in cells[4:]:
            step, jumps, flipped, miss, far = (float(x) for x in cell.split("/"))
            assert 0.0 < step < 1000.0 and 0 <= jumps <= 39 and 0 <= flipped <= 4 * 39
            assert 0.0 <= miss < 1000.0 and 0 <= far <= 40


def test_files_and_settings_it_cannot_use_are_one_line_errors(
    bvh_files: dict[str, Path], models_dir: Path, tmp_path: Path
) -> None:
    """No traceback: a file missing, a folder, not BVH, one frame; a setting out of range."""
    from typer.testing import CliRunner

    text = bvh_files["bandai"].read_text()
    head, _, motion = text.partition("MOTION")
    lines = motion.strip().splitlines()
    (tmp_path / "one.bvh").write_text(f"{head}MOTION\nFrames: 1\n{lines[1]}\n{lines[2]}\n")
    (tmp_path / "junk.bvh").write_text("not a bvh\n")
    cases = {
        str(tmp_path / "nosuch.bvh"): "does not exist",
        str(tmp_path): "is a directory",
        str(tmp_path / "junk.bvh"): "not a BVH file",
        str(tmp_path / "one.bvh"): "1 frame; a clip needs 2 or more",
    }

    def said(output: str) -> str:  # the message without rich's box and line breaks
        return " ".join(output.translate({ord(c): " " for c in "│╭╮╰╯─"}).split())

    for arg, says in cases.items():
        got = CliRunner().invoke(app, [arg, "--models", str(models_dir)])
        assert got.exit_code == 2 and says in said(got.output), got.output
        assert "Traceback" not in got.output
    bad = CliRunner().invoke(
        app, [str(bvh_files["bandai"]), "--models", str(models_dir), "--serving", "bend_side=2"]
    )
    assert bad.exit_code == 2
    assert "bend_side: Input should be less than or equal to 1" in said(bad.output)
