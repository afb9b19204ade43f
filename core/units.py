"""Units and up axes: the one definition, for characters (service) and mocap maps (trainer)."""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt


def _frozen(rows: list[list[float]]) -> npt.NDArray[np.float64]:
    a = np.array(rows, dtype=np.float64)
    a.setflags(write=False)
    return a


#: Metres per unit, by name.
UNITS: Final[dict[str, float]] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}

#: Rotation taking a frame's up axis to +Y (right-handed to right-handed); read-only.
UP_AXES: Final[dict[str, npt.NDArray[np.float64]]] = {
    "+Y": _frozen([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
    # Z-up: (x, y, z) -> (x, z, -y), a -90 degree turn about +X.
    "+Z": _frozen([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
}
