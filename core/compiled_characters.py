"""Forward kinematics of a client's own skeleton, compiled (numba, :mod:`core.jit`).

A character solve aims the skeleton's joints group by group and reads the world pose
after each (``core.retarget``): about 200 forward kinematics for one exact-reach edit of
a 22-joint skeleton, which took half of its 110 ms as numpy loops over the joints. Here
one call is a few µs (that edit: 108.6 -> 41.3 ms median, with the anchors' points taken
in one array operation, ``JointMap.points``). The products are written out in source
order (no BLAS, no fused multiply-add), so an answer is the same on every run; they differ
from numpy's ``@`` (BLAS) by rounding only (6e-17 on the docs' BVH example;
tests/core/test_characters.py holds them to 1e-12 on real files).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.jit import jit

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


@jit
def forward_kinematics_into(
    parents: I64, rotations: F64, translations: F64, g_rot: F64, g_pos: F64
) -> None:  # pragma: no cover - compiled
    """World rotations ``g_rot [J, 3, 3]`` and positions ``g_pos [J, 3]`` of local
    ``rotations [J, 3, 3]`` and ``translations [J, 3]``; ``parents [J]`` in topological
    order (-1: a root)."""
    for j in range(parents.shape[0]):
        p = parents[j]
        if p < 0:
            for r in range(3):
                for c in range(3):
                    g_rot[j, r, c] = rotations[j, r, c]
                g_pos[j, r] = translations[j, r]
            continue
        for r in range(3):
            a0, a1, a2 = g_rot[p, r, 0], g_rot[p, r, 1], g_rot[p, r, 2]
            for c in range(3):
                g_rot[j, r, c] = (
                    a0 * rotations[j, 0, c] + a1 * rotations[j, 1, c] + a2 * rotations[j, 2, c]
                )
            g_pos[j, r] = g_pos[p, r] + (
                a0 * translations[j, 0] + a1 * translations[j, 1] + a2 * translations[j, 2]
            )


def forward_kinematics(parents: I64, rotations: F64, translations: F64) -> tuple[F64, F64]:
    """:func:`forward_kinematics_into` into new arrays (inputs made contiguous, writable
    float64: the one signature :func:`warm` compiles; a read-only array would compile
    another on a request)."""
    n = parents.shape[0]
    g_rot = np.empty((n, 3, 3))
    g_pos = np.empty((n, 3))
    forward_kinematics_into(
        np.require(parents, np.int64, ["C", "W"]),
        np.require(rotations, np.float64, ["C", "W"]),
        np.require(translations, np.float64, ["C", "W"]),
        g_rot,
        g_pos,
    )
    return g_rot, g_pos


def warm() -> None:
    """Compile (or load from the cache) this module's kernel."""
    forward_kinematics(np.array([-1, 0], dtype=np.int64), np.zeros((2, 3, 3)), np.zeros((2, 3)))
