"""The side elbows and knees bend to, fitted on a dataset's training poses
(``pose-trainer bend-sides``): the tables ``core.ends.BEND_ELBOW`` and ``BEND_KNEE`` that
``serving.bend_side`` turns a limb the networks drew too straight towards.

For each limb of each pose (the right ones mirrored onto the left, x negated), ``u`` is the
unit line from the shoulder (hip) to the wrist (ankle) and ``p`` the unit direction of the
elbow (knee) off that line, for limbs bent at least :data:`MIN_BEND` (less says little of
the side: on held-out skeletons, standing legs "bent" 2-5 cm by where their knee joint is
placed lean every way); the table ``W [4, 3]``
is the least-squares fit of ``p`` on ``[u, 1]``, so that ``u @ W[:3] + W[3]``, taken across
``u``, is the side a limb pointing along ``u`` bends to. Numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core.ends import across, preferred_side
from core.skeleton import JOINT_INDEX

F64 = npt.NDArray[np.float64]

#: Limbs bent less than this (m) say nothing of their side and are left out.
MIN_BEND = 0.02
#: (top, middle, end) joint names of the left arm and leg.
LIMBS: dict[str, tuple[str, str, str]] = {
    "elbow": ("left_shoulder", "left_elbow", "left_wrist"),
    "knee": ("left_hip", "left_knee", "left_ankle"),
}
_FLIP = np.asarray([-1.0, 1.0, 1.0])


@dataclass(frozen=True)
class Sides:
    """One limb's table ``w [4, 3]``, the limbs it was fitted on, and the share of them it
    puts within 90 degrees of their own side (``agree``) and the mean cosine."""

    w: F64
    limbs: int
    agree: float
    cosine: float


def lines_and_sides(poses: F64, limb: str, min_bend: float = MIN_BEND) -> tuple[F64, F64]:
    """``u [N, 3]`` and ``p [N, 3]`` (see the module) of both sides' ``limb`` of ``poses
    [B, 21, 3]`` (canonical) bent at least ``min_bend`` (m), the right ones mirrored onto
    the left."""
    us, ps = [], []
    right = tuple(n.replace("left_", "right_") for n in LIMBS[limb])
    for names, flip in ((LIMBS[limb], np.ones(3)), (right, _FLIP)):
        top, mid, end = (poses[:, JOINT_INDEX[n]] * flip for n in names)
        u = end - top
        u = u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-12)
        off = across(mid - top, u)
        size = np.linalg.norm(off, axis=-1)
        keep = size >= min_bend
        us.append(u[keep])
        ps.append(off[keep] / size[keep, None])
    return np.concatenate(us), np.concatenate(ps)


def agreement(w: F64, u: F64, p: F64) -> tuple[float, float]:
    """The share of limbs ``(u, p)`` whose side the table ``w`` puts within 90 degrees, and
    the mean cosine between the two."""
    side = preferred_side(w, u)
    cos = np.sum(side * p, axis=-1) / np.maximum(np.linalg.norm(side, axis=-1), 1e-12)
    return float(np.mean(cos > 0.0)), float(np.mean(cos))


def fit_sides(poses: F64, limb: str, min_bend: float = MIN_BEND) -> Sides:
    """The table of ``limb`` ("elbow", "knee") fitted on ``poses [B, 21, 3]``."""
    u, p = lines_and_sides(np.asarray(poses, dtype=np.float64), limb, min_bend)
    if len(u) < 4:
        raise ValueError(f"too few {limb}s bent {min_bend * 100:g} cm or more to fit a side")
    a = np.hstack([u, np.ones((len(u), 1))])
    w = np.asarray(np.linalg.lstsq(a, p, rcond=None)[0], dtype=np.float64)
    share, cosine = agreement(w, u, p)
    return Sides(w=w, limbs=len(u), agree=share, cosine=cosine)
