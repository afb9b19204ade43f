"""How often a body is called side-swapped (docs/characters.md, "left and right";
``core.sides``): on every frame of the dataset, and on real files read as the BVH route
reads them, as they are and with every joint named for the other side.

1. ``--dataset`` (``data/poses.npz``: five studios' bodies, the right way round), by source:
   frames whose own score is below the line (a rest that says nothing, 0: Bandai-Namco's
   splayed feet), and frames whose swapped image would not be (missed).
2. The character tests' files (``tests.character_files.FILES``, out of ``--mocap``), every
   ``--step``-th frame through ``bench.characters.file_character`` (the route's reading,
   rest pose included): the frames with a ``sides_warning``, as they are and swapped.

    python scripts/figures/sides.py [--dataset data/poses.npz] [--mocap ../shared/mocap]
                                    [--step 5]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from core.sides import SWAPPED_BELOW, facing_score  # noqa: E402


def dataset_rows(path: Path) -> list[str]:
    data = np.load(path)
    sources = data["clip_source"][data["clip"]]
    rows = ["| source | frames | called swapped alone | swapped image missed (rest 0) |",
            "|---|---|---|---|"]  # fmt: skip
    for source in np.unique(sources):
        own = facing_score(data["positions"][sources == source].astype(np.float64))
        rows.append(f"| {source} | {len(own):,} | {int((own < SWAPPED_BELOW).sum())} | "
                    f"{int((-own >= SWAPPED_BELOW).sum())} |")  # fmt: skip
    return rows


def file_rows(mocap: Path, step: int) -> list[str]:
    from bench.characters import file_character
    from service.character_bvh import read_request_bvh
    from tests.character_files import FILES, extract_bvh, swapped_file

    rows = ["| file | frames read | warned as it is | warned swapped |", "|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in extract_bvh(mocap, Path(tmp)).items():
            units = FILES[name][2]
            root = "add" if name.startswith("reactidle") else "replace"
            counts = []
            for text in (path.read_text(), swapped_file(path.read_text())):
                bvh = read_request_bvh(text)
                frames = range(0, bvh.num_frames, step)
                counts.append(sum(
                    file_character(bvh, text, i, units, root)[0].sides_warning is not None
                    for i in frames))  # fmt: skip
            rows.append(f"| {name} | {len(frames)} | {counts[0]} | {counts[1]} |")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dataset", type=Path, default=ROOT / "data/poses.npz")
    parser.add_argument("--mocap", type=Path, default=ROOT.parent / "shared/mocap")
    parser.add_argument("--step", type=int, default=5)
    args = parser.parse_args()
    print("\n".join(dataset_rows(args.dataset)))
    print()
    print("\n".join(file_rows(args.mocap, args.step)))


if __name__ == "__main__":
    main()
