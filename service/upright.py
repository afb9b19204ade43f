"""The answers' ``up_warning`` of a body read with +Y up (``/v1/complete``'s key points,
``/v1/solve``'s start pose in the pose form, each item of a batch): one definition of how
far its pelvis-to-neck line may lean from +Y before the answer says so, and the words.

Key points or a pose captured with +Z up and sent as they are were completed or solved
as a body lying down without a word (API audits, 2026-12-07: the completion's clamped
``floor`` alone showed it; a solve's nothing). A body lying down is answered as asked:
the warning only says how it was read.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from core.skeleton import JOINT_INDEX

F64 = npt.NDArray[np.floating[Any]]

#: degrees: how far the pelvis-to-neck line may lean from +Y before the answer says so
LEAN = 60.0
_PELVIS, _NECK = JOINT_INDEX["pelvis"], JOINT_INDEX["neck"]

#: what each input is, how it was answered, as the warning says it (the field first)
_READ = {
    "keypoints": (
        "key points are read with +Y up, so this body was completed {how}; key points "
        "captured with another axis up must be turned to +Y up first"
    ),
    "pose": (
        "a pose is read with +Y up, so this body was solved {how}; a pose captured "
        "with another axis up must be turned to +Y up first (or sent in the character "
        'form, which takes its "up")'
    ),
}


def leans(trunks: F64) -> F64:
    """Degrees from +Y of each pelvis-to-neck line of ``trunks`` (``[..., 3]``); 0 for a
    line of no length (it says nothing)."""
    return np.degrees(np.arctan2(np.hypot(trunks[..., 0], trunks[..., 2]), trunks[..., 1]))


def leaning(field: str, trunk: F64, lean: float) -> str | None:
    """``up_warning`` of the input ``field`` (``keypoints`` or ``pose``) whose
    pelvis-to-neck line ``trunk`` leans ``lean`` degrees (:func:`leans`) from +Y: None
    within :data:`LEAN`, else how far and along which axis it runs: a body lying down, or
    upside down where that is -Y (it said "lying down" of a body upside down too)."""
    if not lean > LEAN:
        return None
    axis = int(np.argmax(np.abs(trunk)))
    along = f"{'+' if trunk[axis] > 0 else '-'}{'XYZ'[axis]}"
    return (
        f"{field}: the pelvis-to-neck line leans {lean:.0f} degrees from +Y (it runs along "
        f"{along}): {_READ[field].format(how='upside down' if along == '-Y' else 'lying down')}"
    )


def pose_warnings(poses: F64) -> list[str | None]:
    """The ``up_warning`` of each start pose of ``poses`` (``[B, 21, 3]``, world), in one
    numpy pass (a batch's items, the columnar form's rows)."""
    trunks = poses[:, _NECK] - poses[:, _PELVIS]
    return [leaning("pose", trunks[b], lean) for b, lean in enumerate(leans(trunks).tolist())]


def pose_warning(pose: F64) -> str | None:
    """The ``up_warning`` of one start pose (``[21, 3]``, world): as :func:`pose_warnings`
    says it, in Python floats (~1 us, a lone edit's hot path; numpy's passes cost ~4), and
    by :func:`pose_warnings` itself within 1e-9 degrees of :data:`LEAN`."""
    (px, py, pz), (nx, ny, nz) = pose[[_PELVIS, _NECK]].tolist()
    tx, ty, tz = nx - px, ny - py, nz - pz
    lean = math.degrees(math.atan2(math.hypot(tx, tz), ty))
    if abs(lean - LEAN) <= 1e-9:
        return pose_warnings(pose[None])[0]
    return None if lean <= LEAN else pose_warnings(pose[None])[0]


def keypoints_warning(pelvis: F64, neck: F64) -> str | None:
    """The ``up_warning`` of key points whose pelvis and neck are at these points."""
    trunk = neck - pelvis
    return leaning("keypoints", trunk, float(leans(trunk)))
