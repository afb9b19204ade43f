"""Pose pairs from the same clip: the training signal of the solvers (numpy only)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

IntArray = npt.NDArray[np.int64]


def partner_ranges(
    clip: npt.NDArray[np.integer], frame: npt.NDArray[np.integer], max_gap: int
) -> tuple[IntArray, IntArray]:
    """For each frame i, the index range [lo, hi) of frames of the same clip whose frame
    number is within ``max_gap`` of frame i. Frames must be sorted by (clip, frame)."""
    key = clip.astype(np.int64) * (1 << 32) + frame.astype(np.int64)
    if np.any(np.diff(key) <= 0):
        raise ValueError("frames must be sorted by (clip, frame) without repeats")
    lo = np.searchsorted(key, key - max_gap, side="left")
    hi = np.searchsorted(key, key + max_gap, side="right")
    return lo.astype(np.int64), hi.astype(np.int64)


def sample_partners(
    lo: IntArray,
    hi: IntArray,
    anchors: IntArray,
    rng: np.random.Generator,
    *,
    min_gap_index: int = 1,
    frame: npt.NDArray[np.integer] | None = None,
    min_gap: int = 0,
) -> IntArray:
    """One partner per anchor, uniform over its range, never the anchor itself.

    With ``frame`` and ``min_gap``, partners closer than ``min_gap`` frames are rejected
    and redrawn (anchors with no valid partner get themselves back; callers filter them).
    """
    a_lo, a_hi = lo[anchors], hi[anchors]
    span = a_hi - a_lo
    out = anchors.copy()
    todo = np.flatnonzero(span > min_gap_index)
    for _ in range(16):
        if todo.size == 0:
            break
        draw = a_lo[todo] + (rng.random(todo.size) * span[todo]).astype(np.int64)
        ok = draw != anchors[todo]
        if frame is not None and min_gap > 0:
            ok &= np.abs(frame[draw] - frame[anchors[todo]]) >= min_gap
        out[todo[ok]] = draw[ok]
        todo = todo[~ok]
    return out
