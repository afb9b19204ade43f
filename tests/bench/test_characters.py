"""``python -m bench.characters``: a user's own file edited towards a later frame of itself,
scored against that frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from bench.characters import SETS, app, frame_pairs, score_file
from service.engine import Engine
from tests.bench.tables import table_of


def test_frame_pairs_are_a_fifth_to_one_second_apart() -> None:
    pairs = frame_pairs(200, 30.0, 50, np.random.default_rng(0))
    gaps = np.array([j - i for i, j in pairs])
    assert len(pairs) == 50 and gaps.min() >= 6 and gaps.max() <= 30
    assert all(0 <= i < j < 200 for i, j in pairs)
    assert frame_pairs(5, 30.0, 10, np.random.default_rng(0)) == []  # shorter than 0.2 s


def test_a_row_per_set_scored_against_the_later_frame(
    bvh_files: dict[str, Path], models_dir: Path
) -> None:
    """Then the mean over the rows, per set and over every set, the figures the README and
    docs/characters.md quote (they were averaged by hand before)."""
    args = [str(bvh_files["bandai"]), "--models", str(models_dir), "--edits", "3"]
    header, rows = table_of(app, args)
    assert header.startswith("| file | set | edits | start | FABRIK | soft | exact |")
    assert len(rows) == len(SETS)
    scores = []
    for row, (name, _) in zip(rows, SETS, strict=True):
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert cells[:3] == [bvh_files["bandai"].name, name, "3"]
        start, fabrik, soft, exact, soft_c, exact_c = map(float, cells[3:9])
        scores.append((fabrik, exact))
        assert float(cells[9].split("/")[1]) <= 0.1  # exact reach: within 1 mm (in cm)
        if name == "5 end eff.":  # a walk: five joints where they went say most of it
            assert max(fabrik, soft, exact, soft_c, exact_c) < start / 3
    output = CliRunner().invoke(app, args).output
    *_, means = output.partition("Mean over the rows")
    cells = [[c.strip() for c in ln.strip("|").split("|")] for ln in means.splitlines()[4:]]
    assert [c[:3] for c in cells] == [["1 given", n, "1"] for n, _ in SETS] + [
        ["1 given", "all sets", str(len(SETS))]
    ]
    fabrik, exact = float(cells[-1][4]), float(cells[-1][6])
    assert np.isclose(fabrik, np.mean([f for f, _ in scores]), atol=0.006)
    assert np.isclose(exact, np.mean([e for _, e in scores]), atol=0.006)
    assert cells[-1][-1] == f"{sum(e < f for f, e in scores)}/{len(SETS)}"


def test_a_file_shorter_than_a_fifth_of_a_second_gives_no_row(
    bvh_files: dict[str, Path], models_dir: Path, tmp_path: Path
) -> None:
    text = bvh_files["bandai"].read_text()
    head, _, motion = text.partition("MOTION")
    lines = motion.strip().splitlines()  # "Frames: N", "Frame Time: t", then the frames
    short = tmp_path / "short.bvh"
    short.write_text(f"{head}MOTION\nFrames: 3\n{lines[1]}\n" + "\n".join(lines[2:5]) + "\n")
    assert score_file(Engine(models_dir), short, 5, 0) == {}


def test_files_whose_root_channels_are_a_displacement_are_scored_as_such(
    bvh_files: dict[str, Path], models_dir: Path
) -> None:
    """ReActIdle's root channels are a displacement from its OFFSET: the default files
    score them with ``root_position: "add"``, and a file given takes ``--root-position``."""
    from bench.characters import DEFAULT_FILES

    roots = {member.split("/")[-2]: root for _, member, _, root in DEFAULT_FILES}
    assert roots["acted"] == roots["genuine"] == "add" and roots["fair1"] == "replace"
    path = bvh_files["reactidle-6ch"]
    scored = {
        root: table_of(
            app, [str(path), "--models", str(models_dir), "--edits", "2", "--root-position", root]
        )[1]
        for root in ("replace", "add")
    }
    assert len(scored["add"]) == len(SETS)
    assert scored["add"] != scored["replace"]  # the floor the networks are told of moved
