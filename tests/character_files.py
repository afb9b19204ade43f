"""Real BVH files of several studios for the character tests, and an independent reader.

``extract_bvh`` pulls a few named files out of the mocap archives (``../shared/mocap``) into
a temp folder; :class:`RefBVH` is a small BVH reader with its own forward kinematics (scipy
Euler rotations), written apart from ``core.bvh`` so that it checks it.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.conftest import untar

_ADA = "animateddrawings_fair_bvh.tar.xz"
_AD = "animateddrawings_fair_bvh/facebookresearch+AnimatedDrawings@74ee7f0/examples/bvh"
#: name -> (archive, member, units to state (None: inferred), frame to edit)
FILES: dict[str, tuple[str, str, str | float | None, int]] = {
    "fair1-child-inches-zup": (_ADA, f"{_AD}/fair1/dab.bvh", "in", 120),
    "cmu-asf-bvh": (_ADA, f"{_AD}/cmu1/jumping_jacks.bvh", 0.0564444, 40),
    "cmu-daz-salsa": ("cmu-dance.tar.xz", "train_data_bvh/salsa/01.bvh", None, 300),
    "bandai": (
        "bandai-namco-research-motiondataset.tar.xz",
        "dataset/Bandai-Namco-Research-Motiondataset-1/data/dataset-1_walk_normal_001.bvh",
        None,
        30,
    ),
    "reactidle-6ch": (
        "reactidle_bvh.tar.xz",
        "reactidle_bvh/Enekoassets+ReActIdle@90b0ac7/acted/001_acted.bvh",
        None,
        500,
    ),
}


def extract_bvh(mocap: Path, out: Path) -> dict[str, Path]:
    """Extract every file of :data:`FILES` (skips the test if an archive or tar is missing)."""
    tar = shutil.which("tar")
    if tar is None:
        pytest.skip("the 'tar' command is needed to extract test files")
    by_archive: dict[str, list[str]] = {}
    for archive, member, _, _ in FILES.values():
        if not (mocap / archive).is_file():
            pytest.skip(f"mocap archive {archive} not found in {mocap}")
        by_archive.setdefault(archive, []).append(member)
    procs = [  # the archives in parallel
        subprocess.Popen(untar(tar, mocap / archive, out, members))
        for archive, members in by_archive.items()
    ]
    failed = [proc.args for proc in procs if proc.wait() != 0]  # (every one waited for)
    assert not failed, f"tar failed: {failed}"
    return {name: out / member for name, (_, member, _, _) in FILES.items()}


@dataclass
class RefJoint:
    name: str
    parent: int
    offset: np.ndarray
    channels: list[str]
    start: int


class RefBVH:
    """Independent reader: hierarchy, channels, End Sites (``<joint>_end``), motion rows."""

    def __init__(self, text: str) -> None:
        head, _, motion = text.partition("MOTION")
        toks = head.split()
        self.joints: list[RefJoint] = []
        stack: list[int] = []
        col = 0
        i = 1  # after HIERARCHY
        pending: tuple[str, int] | None = None
        while i < len(toks):
            t = toks[i]
            if t in ("ROOT", "JOINT"):
                pending = (toks[i + 1], stack[-1] if stack else -1)
                i += 2
            elif t == "End":
                parent = stack[-1]
                pending = (self.joints[parent].name + "_end", parent)
                i += 2
            elif t == "{":
                assert pending is not None
                self.joints.append(RefJoint(pending[0], pending[1], np.zeros(3), [], col))
                stack.append(len(self.joints) - 1)
                i += 1
            elif t == "}":
                stack.pop()
                i += 1
            elif t == "OFFSET":
                self.joints[stack[-1]].offset = np.array([float(v) for v in toks[i + 1 : i + 4]])
                i += 4
            elif t == "CHANNELS":
                n = int(toks[i + 1])
                self.joints[stack[-1]].channels = toks[i + 2 : i + 2 + n]
                self.joints[stack[-1]].start = col
                col += n
                i += 2 + n
            else:
                raise AssertionError(f"unexpected token {t!r}")
        lines = motion.strip().splitlines()
        self.frames = int(lines[0].split(":")[1])
        self.frame_time = float(lines[1].split(":")[1])
        self.rows = [ln for ln in lines[2:] if ln.strip()]
        self.index = {j.name: k for k, j in enumerate(self.joints)}

    def positions(self, frame: int) -> dict[str, np.ndarray]:
        """World positions of every joint (and End Site) of one frame, file units."""
        row = [float(v) for v in self.rows[frame].split()]
        rot: list[np.ndarray] = []
        pos: list[np.ndarray] = []
        for j in self.joints:
            t = j.offset.copy()
            seq, angles = "", []
            for k, ch in enumerate(j.channels):
                v = row[j.start + k]
                if ch.lower().endswith("position"):
                    t["xyz".index(ch[0].lower())] = v
                else:
                    seq += ch[0].upper()
                    angles.append(v)
            r = Rotation.from_euler(seq, angles, degrees=True).as_matrix() if seq else np.eye(3)
            if j.parent < 0:
                rot.append(r)
                pos.append(t)
            else:
                pos.append(pos[j.parent] + rot[j.parent] @ t)
                rot.append(rot[j.parent] @ r)
        return {j.name: p for j, p in zip(self.joints, pos, strict=True)}


def big_file(path: Path, size: int, skip: int = 0) -> str:
    """The BVH file at ``path`` with its frames repeated (from its frame ``skip``) until it
    holds ``size`` bytes (the editor's tests of big files)."""
    head, motion = path.read_text().split("MOTION\n", 1)
    lines = motion.split("\n")
    rows = [row for row in lines[2:] if row.strip()]
    out: list[str] = []
    total = len(head)
    while total < size:
        out.append(rows[(len(out) + skip) % len(rows)])
        total += len(out[-1]) + 1
    return f"{head}MOTION\nFrames: {len(out)}\n{lines[1]}\n" + "\n".join(out) + "\n"


#: a joint's side the other way (:func:`other_side`)
_WORD = re.compile(r"Left|Right|left|right")
_PAIRS = {"Left": "Right", "Right": "Left", "left": "right", "right": "left"}
_SIDE = {"L": "R", "R": "L", "l": "r", "r": "l"}


def other_side(name: str) -> str:
    """``name`` with its side the other way: LeftHand, lShldr, LHipJoint, lhand, Hand_L,
    hand.L (the files' schemes); a centre joint as it is."""
    if _WORD.search(name):
        return _WORD.sub(lambda m: _PAIRS[m.group()], name)
    if m := re.fullmatch(r"([lLrR])([A-Z].*|hand)", name):
        return _SIDE[m.group(1)] + m.group(2)
    if m := re.fullmatch(r"(.*[._])([LR])(_end)?", name):  # (an End Site's label: _end)
        return m.group(1) + _SIDE[m.group(2)] + (m.group(3) or "")
    return name


def other_label(label: str) -> str:
    """A joint map's label (a joint, an End Site, "0.25 of A->B") with each name in it
    :func:`other_side`."""
    return re.sub(r"[\w.]+", lambda m: other_side(m[0]), label)


def swapped_file(text: str) -> str:
    """A BVH file with every joint named for the other side; its numbers as they are."""
    return re.sub(r"(?m)^(\s*(?:ROOT|JOINT)\s+)(\S+)", lambda m: m[1] + other_side(m[2]), text)
