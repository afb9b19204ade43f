"""The pose dataset file (``data/poses.npz``): format, atomic writer and validating loader.

One ``np.savez_compressed`` file with exactly these keys:

- ``positions`` float32 ``(N, 21, 3)``: canonical poses in metres (``core.geometry``).
- ``yaw`` float32 ``(N,)`` and ``root`` float32 ``(N, 3)``: each frame's canonical transform, so
  that world = R_y(yaw) @ canonical + root (metres, +Y up, the clip's floor at y = 0). Root
  motion and facing are kept: two frames of a clip can be put in one frame of reference.
- ``clip`` int32 ``(N,)``: index into the clip table; ``frame`` int32 ``(N,)``: frame index at
  30 fps within the clip (gaps where frames were dropped).
- clip table, unicode ``(C,)``: ``clip_name``, ``clip_source``, ``clip_content``,
  ``clip_style``, ``clip_actor``, ``clip_split`` (``train`` | ``val`` | ``test``).
- ``meta``: a 0-d unicode array holding a JSON object (format version, fps, seed, ...).
"""

from __future__ import annotations

import io
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core.geometry import RigidTransform, yaw_matrix
from core.io import write_atomic
from core.skeleton import NUM_JOINTS

FORMAT_VERSION = 2
FPS = 30
#: ``holdout``: bodies kept out of training entirely (named in their joint maps).
SPLITS: tuple[str, ...] = ("train", "val", "test", "holdout")
CLIP_KEYS: tuple[str, ...] = (
    "clip_name",
    "clip_source",
    "clip_content",
    "clip_style",
    "clip_actor",
    "clip_split",
)
KEYS: tuple[str, ...] = ("positions", "yaw", "root", "clip", "frame", *CLIP_KEYS, "meta")


class DatasetError(ValueError):
    """A dataset file that is missing, unreadable or does not follow the format."""


@dataclass(frozen=True)
class PoseDataset:
    """Canonical poses with their clip table (see the module docstring for the fields)."""

    positions: npt.NDArray[np.float32]
    yaw: npt.NDArray[np.float32]
    root: npt.NDArray[np.float32]
    clip: npt.NDArray[np.int32]
    frame: npt.NDArray[np.int32]
    clip_name: npt.NDArray[np.str_]
    clip_source: npt.NDArray[np.str_]
    clip_content: npt.NDArray[np.str_]
    clip_style: npt.NDArray[np.str_]
    clip_actor: npt.NDArray[np.str_]
    clip_split: npt.NDArray[np.str_]
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.positions.shape[0])

    @property
    def num_clips(self) -> int:
        return int(self.clip_name.shape[0])

    def world(self) -> npt.NDArray[np.float64]:
        """World poses ``[N, 21, 3]`` (float64 metres): each canonical pose put back with its
        frame's transform, so frames of one clip share one frame of reference."""
        return np.asarray(self.transform().to_world(self.positions.astype(np.float64)))

    def transform(self) -> RigidTransform:
        """Each frame's canonical transform (world = rotation @ canonical + translation)."""
        return RigidTransform(
            rotation=yaw_matrix(self.yaw.astype(np.float64)),
            translation=self.root.astype(np.float64),
        )

    def split_mask(self, name: str) -> npt.NDArray[np.bool_]:
        """Per-frame mask of the frames whose clip is in split ``name``."""
        if name not in SPLITS:
            raise ValueError(f"unknown split {name!r}; splits are {', '.join(SPLITS)}")
        return np.asarray((self.clip_split == name)[self.clip], dtype=np.bool_)

    def source_mask(self, source: str) -> npt.NDArray[np.bool_]:
        """Per-frame mask of the frames of one source (e.g. ``"cmu-dance"``)."""
        return np.asarray((self.clip_source == source)[self.clip], dtype=np.bool_)

    def subset(self, mask: npt.NDArray[np.bool_]) -> PoseDataset:
        """The frames selected by a boolean mask (or index array); the clip table is kept."""
        mask = np.asarray(mask)
        if mask.dtype == np.bool_ and mask.shape != (len(self),):
            raise ValueError(f"mask has shape {mask.shape}, expected ({len(self)},)")
        return PoseDataset(
            positions=self.positions[mask],
            yaw=self.yaw[mask],
            root=self.root[mask],
            clip=self.clip[mask],
            frame=self.frame[mask],
            clip_name=self.clip_name,
            clip_source=self.clip_source,
            clip_content=self.clip_content,
            clip_style=self.clip_style,
            clip_actor=self.clip_actor,
            clip_split=self.clip_split,
            meta=self.meta,
        )

    def arrays(self) -> dict[str, npt.NDArray[Any]]:
        """The arrays exactly as stored in the file (``meta`` as a JSON 0-d string)."""
        return {
            "positions": self.positions,
            "yaw": self.yaw,
            "root": self.root,
            "clip": self.clip,
            "frame": self.frame,
            "clip_name": self.clip_name,
            "clip_source": self.clip_source,
            "clip_content": self.clip_content,
            "clip_style": self.clip_style,
            "clip_actor": self.clip_actor,
            "clip_split": self.clip_split,
            "meta": np.array(json.dumps(self.meta, sort_keys=True)),
        }


def validate_arrays(arrays: dict[str, npt.NDArray[Any]], where: str = "dataset") -> dict[str, Any]:
    """Check keys, shapes, dtypes and ranges; return the parsed ``meta``."""
    missing = [k for k in KEYS if k not in arrays]
    extra = sorted(set(arrays) - set(KEYS))
    if missing or extra:
        raise DatasetError(
            f"{where}: keys differ from the format: missing {missing}, extra {extra}"
        )
    pos = arrays["positions"]
    if pos.dtype != np.float32 or pos.ndim != 3 or pos.shape[1:] != (NUM_JOINTS, 3):
        raise DatasetError(
            f"{where}: 'positions' must be float32 (N, {NUM_JOINTS}, 3), "
            f"got {pos.dtype} {pos.shape}"
        )
    n = pos.shape[0]
    if arrays["yaw"].dtype != np.float32 or arrays["yaw"].shape != (n,):
        raise DatasetError(f"{where}: 'yaw' must be float32 ({n},), got {arrays['yaw'].shape}")
    if arrays["root"].dtype != np.float32 or arrays["root"].shape != (n, 3):
        raise DatasetError(f"{where}: 'root' must be float32 ({n}, 3), got {arrays['root'].shape}")
    for key in ("clip", "frame"):
        arr = arrays[key]
        if arr.dtype != np.int32 or arr.shape != (n,):
            raise DatasetError(
                f"{where}: {key!r} must be int32 ({n},), got {arr.dtype} {arr.shape}"
            )
    n_clips = arrays["clip_name"].shape[0] if arrays["clip_name"].ndim == 1 else -1
    for key in CLIP_KEYS:
        arr = arrays[key]
        if arr.dtype.kind != "U" or arr.shape != (n_clips,):
            raise DatasetError(
                f"{where}: {key!r} must be a unicode array of shape (C,) like 'clip_name', "
                f"got {arr.dtype} {arr.shape}"
            )
    if n and (arrays["clip"].min() < 0 or arrays["clip"].max() >= n_clips):
        raise DatasetError(f"{where}: 'clip' indices outside the clip table (C={n_clips})")
    if n and arrays["frame"].min() < 0:
        raise DatasetError(f"{where}: negative 'frame' values")
    bad_splits = sorted(set(arrays["clip_split"].tolist()) - set(SPLITS))
    if bad_splits:
        raise DatasetError(f"{where}: unknown clip_split values {bad_splits}")
    if len(set(arrays["clip_name"].tolist())) != n_clips:
        raise DatasetError(f"{where}: duplicate clip names")
    if not (np.isfinite(pos).all() and np.isfinite(arrays["yaw"]).all()):
        raise DatasetError(f"{where}: non-finite values in 'positions'")
    meta_arr = arrays["meta"]
    if meta_arr.dtype.kind != "U" or meta_arr.shape != ():
        raise DatasetError(f"{where}: 'meta' must be a 0-d unicode (JSON) array")
    try:
        meta = json.loads(str(meta_arr[()]))
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{where}: 'meta' is not valid JSON: {exc}") from None
    if not isinstance(meta, dict):
        raise DatasetError(f"{where}: 'meta' must be a JSON object")
    if meta.get("format_version") != FORMAT_VERSION:
        raise DatasetError(
            f"{where}: format_version {meta.get('format_version')!r} is not {FORMAT_VERSION}"
        )
    return meta


def save_dataset(path: str | Path, dataset: PoseDataset) -> Path:
    """Validate and write ``dataset`` atomically (``core.io.write_atomic``)."""
    path = Path(path)
    arrays = dataset.arrays()
    validate_arrays(arrays, str(path))
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)  # type: ignore[arg-type]
    write_atomic(path, buf.getvalue())
    return path


def is_dataset_file(path: str | Path) -> bool:
    """Whether ``path`` is a dataset file `pose-trainer dataset` wrote (any format version:
    a zip whose ``meta`` is a JSON object with ``format_version`` and ``joints``); only
    ``meta`` is read."""
    path = Path(path)
    if not path.is_file() or not zipfile.is_zipfile(path):
        return False
    try:
        with np.load(path, allow_pickle=False) as npz:
            if "meta" not in npz.files:
                return False
            meta = json.loads(str(npz["meta"][()]))
    except (OSError, ValueError, zipfile.BadZipFile, EOFError):
        return False
    return isinstance(meta, dict) and "format_version" in meta and "joints" in meta


def load_dataset(path: str | Path) -> PoseDataset:
    """Load and validate a dataset file (``DatasetError`` with a clear reason)."""
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: no such dataset file (build it with `pose-trainer dataset`)")
    if not zipfile.is_zipfile(path):  # (numpy would read it as a pickle, or one array)
        raise DatasetError(
            f"{path}: not a dataset file: a dataset is the .npz (zip) archive `pose-trainer "
            "dataset` writes"
        )
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DatasetError(f"{path}: not a readable .npz file: {exc}") from None
    meta = validate_arrays(arrays, str(path))
    return PoseDataset(
        positions=arrays["positions"],
        yaw=arrays["yaw"],
        root=arrays["root"],
        clip=arrays["clip"],
        frame=arrays["frame"],
        clip_name=arrays["clip_name"],
        clip_source=arrays["clip_source"],
        clip_content=arrays["clip_content"],
        clip_style=arrays["clip_style"],
        clip_actor=arrays["clip_actor"],
        clip_split=arrays["clip_split"],
        meta=meta,
    )
