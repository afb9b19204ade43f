#!/usr/bin/env python3
"""Export a few varied poses from the TEST split of the dataset for the editor's sample menu.

    .venv/bin/python scripts/export_sample_poses.py [--dataset data/poses.npz]
        [--out service/static/samples.json]

Each sample is one frame of one test clip, picked by a fixed rule (no randomness), so the
file is reproducible from the same dataset. Poses are canonical (pelvis floor projection at
the origin, facing +Z, left +X, +Y up, metres), which is already a sensible world placement
for the editor. Coordinates are rounded to 0.01 mm.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from core.skeleton import JOINT_INDEX, JOINT_NAMES  # noqa: E402
from trainer.data.dataset import PoseDataset, load_dataset  # noqa: E402

Poses = npt.NDArray[np.float32]
#: Picks one frame (index into the clip's frames) from a clip's poses ``(F, 21, 3)``.
Picker = Callable[[Poses], int]


def _y(name: str) -> Callable[[Poses], npt.NDArray[np.float32]]:
    return lambda p: p[:, JOINT_INDEX[name], 1]


def first(_: Poses) -> int:
    return 0


def middle(p: Poses) -> int:
    return len(p) // 2


def highest(name: str) -> Picker:
    return lambda p: int(np.argmax(_y(name)(p)))


def lowest(name: str) -> Picker:
    return lambda p: int(np.argmin(_y(name)(p)))


def most_forward(*names: str) -> Picker:
    idx = [JOINT_INDEX[n] for n in names]
    return lambda p: int(np.argmax(p[:, idx, 2].max(axis=1)))


def highest_foot(p: Poses) -> int:
    feet = [JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"]]
    return int(np.argmax(p[:, feet, 1].max(axis=1)))


#: (label, clip-name prefix after "<source>/", picker). The first test clip (by name) whose
#: name starts with the prefix is used. The first sample is the editor's initial pose.
RULES: tuple[tuple[str, str, Picker], ...] = (
    ("stand", "bandai-namco/dataset-2_raise-up-both-hands_normal", first),
    ("walk", "bandai-namco/dataset-1_walk_", middle),
    ("raise left hand", "bandai-namco/dataset-2_raise-up-left-hand_normal", highest("left_wrist")),
    ("kick", "bandai-namco/dataset-1_kick_", highest_foot),
    ("punch", "bandai-namco/dataset-1_punch_", most_forward("left_wrist", "right_wrist")),
    ("bow", "bandai-namco/dataset-1_bow_", lowest("head")),
    ("salsa", "cmu-dance/salsa/", middle),
    ("martial arts", "cmu-dance/martial/", highest_foot),
)


def export(ds: PoseDataset) -> list[dict[str, object]]:
    test = ds.subset(ds.split_mask("test"))
    test_clips = sorted({int(c) for c in np.unique(test.clip)}, key=lambda c: ds.clip_name[c])
    samples: list[dict[str, object]] = []
    for label, prefix, pick in RULES:
        clip = next((c for c in test_clips if str(ds.clip_name[c]).startswith(prefix)), None)
        if clip is None:
            print(f"no test clip starts with {prefix!r}; skipping {label!r}", file=sys.stderr)
            continue
        rows = np.flatnonzero(test.clip == clip)
        rows = rows[np.argsort(test.frame[rows], kind="stable")]
        poses = test.positions[rows]
        i = pick(poses)
        pose = poses[i].astype(np.float64)
        samples.append(
            {
                "name": f"{ds.clip_source[clip]} {label}",
                "clip": str(ds.clip_name[clip]),
                "frame": int(test.frame[rows[i]]),
                "source": str(ds.clip_source[clip]),
                "pose": {
                    name: [round(float(v), 5) for v in pose[j]]
                    for j, name in enumerate(JOINT_NAMES)
                },
            }
        )
    return samples


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", type=Path, default=REPO / "data" / "poses.npz")
    ap.add_argument("--out", type=Path, default=REPO / "service" / "static" / "samples.json")
    args = ap.parse_args()
    ds = load_dataset(args.dataset)
    samples = export(ds)
    if not samples:
        sys.exit("no samples exported")
    doc = {
        "description": "Poses from the test split of data/poses.npz (canonical frame: metres, "
        "+Y up, facing +Z, left +X). Exported by scripts/export_sample_poses.py.",
        # the licences of the sources the samples come from (not of every source)
        "licences": {
            k: v
            for k, v in ds.meta.get("licences", {}).items()
            if k in {s["source"] for s in samples}
        },
        "samples": samples,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    # One line per sample keeps the file small and its diffs readable.
    lines = ",\n".join("    " + json.dumps(s, separators=(",", ":")) for s in samples)
    head = json.dumps({k: v for k, v in doc.items() if k != "samples"}, indent=2)[:-2]
    args.out.write_text(f'{head},\n  "samples": [\n{lines}\n  ]\n}}\n', encoding="utf-8")
    json.loads(args.out.read_text(encoding="utf-8"))  # well-formed
    print(f"wrote {len(samples)} samples to {args.out}")
    for s in samples:
        print(f"  {s['name']}: {s['clip']} frame {s['frame']}")


if __name__ == "__main__":
    main()
