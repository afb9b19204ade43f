"""Where a floor lies against a body: the band of floors the networks know, below a
body's pelvis, and ``/v1/solve``'s ``floor_warning`` of a floor outside it (``/v1/complete``
takes its floor into that band instead, ``service.completion``): one definition.

No body of the training data stood higher above its floor than 3.5 pelvis-to-neck
distances (mid-jump; 2.2 standing), nor with its pelvis under it (0.45 at the lowest, a
body lying there). A solve's ``options.floor`` 5 m above a standing body, or 50 m below it,
was taken as it came without a word, and the answer did not say which floor it used
(an API audit, 2026-12-07). The solve is answered as asked: the warning only says how the
floor was read.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from core.skeleton import JOINT_INDEX

F64 = npt.NDArray[np.floating[Any]]

#: The floor the networks know lies at most this many pelvis-to-neck distances below the
#: pelvis, and not above it. ``service.completion`` takes a floor outside into this band:
#: a floor farther below says nothing but a size the networks never saw (50 m below the
#: key points, the answer's bones came out up to 7 m long, 10 km below, 1.4 km; reviewed
#: 2026-12-04), and 9 m above them it made bones up to 1.25 m long. A solve is answered
#: with the floor it was given and says so (:func:`floor_warnings`).
FLOOR_REACH = 4.0
#: Nor stood with its lowest joint under the floor by more than this many pelvis-to-neck
#: distances (ReActIdle's takes stand a few cm under theirs). A body built with its root at
#: the origin (SMPL-like rigs: the pelvis at the floor, the feet 0.8-0.9 m under it) was
#: solved without a word, the answer up to 4.3 cm from the standing body's (an API audit,
#: 2026-12-07).
SUNK = 0.5
_PELVIS, _NECK = JOINT_INDEX["pelvis"], JOINT_INDEX["neck"]


def floor_warnings(poses: F64, floors: float | F64) -> list[str | None]:
    """The ``floor_warning`` of each start pose of ``poses`` (``[B, 21, 3]``, world) over
    its floor ``floors`` (world y: one for all, or ``[B]``), in one numpy pass (a single
    edit, a batch's items, the columnar form's rows; ~4 us for one pose): None where the
    floor lies below the pelvis by at most :data:`FLOOR_REACH` pelvis-to-neck distances,
    else where it lies."""
    pelvis = poses[:, _PELVIS, 1]
    trunks = poses[:, _NECK] - poses[:, _PELVIS]
    torsos = np.sqrt(np.add.reduce(trunks * trunks, axis=1))
    lowest = poses[:, :, 1].min(axis=1)
    off = _outside(floors, pelvis, torsos, lowest)
    out: list[str | None] = [None] * len(poses)
    if off.any():
        at = np.broadcast_to(floors, pelvis.shape)
        for b in np.flatnonzero(off).tolist():
            out[b] = _words(float(at[b]), float(pelvis[b]), float(torsos[b]), float(lowest[b]))
    return out


def floor_warning(pose: F64, floor: float, height: str = "y") -> str | None:
    """The ``floor_warning`` of one start pose (``[21, 3]``, world) over ``floor``: as
    :func:`floor_warnings` says it (the same rule, :func:`_outside`, on Python floats: ~1 us,
    a lone edit's hot path; numpy's passes cost ~5). ``height`` names the up axis in the words:
    the pose form's world y, a character's own up axis (``"z"`` for ``+Z``, its
    coordinates in metres)."""
    (px, py, pz), (nx, ny, nz) = pose[[_PELVIS, _NECK]].tolist()
    tx, ty, tz = nx - px, ny - py, nz - pz
    torso = math.sqrt(tx * tx + ty * ty + tz * tz)
    lowest = min(pose[:, 1].tolist())
    if _outside(floor, py, torso, lowest):
        return _words(float(floor), py, torso, lowest, height)
    return None


def _outside(floor: Any, pelvis: Any, torso: Any, lowest: Any) -> Any:
    """Whether a floor lies outside the band the networks know (the rule, once): above the
    pelvis, more than :data:`FLOOR_REACH` pelvis-to-neck distances ``torso`` below it, or
    above the lowest joint by more than :data:`SUNK` of them. Python floats (a lone edit)
    or numpy arrays (a batch) alike: ``|`` on bools or on boolean arrays."""
    return (
        (floor > pelvis) | (floor < pelvis - FLOOR_REACH * torso) | (floor > lowest + SUNK * torso)
    )


def _words(floor: float, pelvis: float, torso: float, lowest: float, height: str = "y") -> str:
    """The warning of a floor at world y ``floor`` under (over) a pelvis at ``pelvis``,
    ``torso`` its pelvis-to-neck distance, ``lowest`` the start's lowest joint's height;
    ``height``: the up axis's name in the words."""
    if pelvis >= floor > lowest + SUNK * torso:
        where = (
            f"{floor - lowest:.3g} m above the start pose's lowest joint ({height} = "
            f"{lowest:.3g} m; its pelvis at {pelvis:.3g} m)"
        )
        read = "so this body was solved with its legs under its ground (a root at the origin?)"
    elif floor > pelvis:
        where = f"{floor - pelvis:.3g} m above the start pose's pelvis ({height} = {pelvis:.3g} m)"
        read = "so this body was solved standing under its ground"
    else:
        times = (pelvis - floor) / torso if torso > 0 else float("inf")
        where = (
            f"{pelvis - floor:.3g} m below the start pose's pelvis ({height} = {pelvis:.3g} m), "
            f"{times:.3g} times its pelvis-to-neck distance"
        )
        read = f"no body the networks learned stood more than {FLOOR_REACH:g} times higher"
    return (
        f"options.floor: the floor ({height} = {floor:.3g} m) lies {where}: {read}; the floor "
        "is the world height of the ground the character stands on (0 for the ground at "
        f"{height} = 0, 1.0 for a character on a 1 m box)"
    )
