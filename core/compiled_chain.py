"""The single-chain FABRIK of a character's exact reach, compiled (numba, :mod:`core.jit`).

``core.retarget`` FABRIKs the chain of single-child aims above each exact target or pin
onto it, in the character's own bone lengths, from the chain's fixed top: two to six
times an edit, up to 64 rounds each, where numpy's per-point steps cost ~30 us a chain.
:func:`chain_fabrik_into` is those steps: out of reach, the chain straightened towards the
goal; already there, left as it is (an untouched pin stays bit for bit); two bones, in
closed form (law of cosines, :func:`_two_bone_into`), since FABRIK crawls near full
stretch (2 mm short after 64 rounds, a standing leg) and cannot bend a straight chain;
else FABRIK's rounds. Products in source order: the same answer on every run.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.compiled import norm3
from core.jit import jit

F64 = npt.NDArray[np.float64]


@jit
def _two_bone_into(
    p: F64, goal: F64, a: float, b: float, bend: F64, has_bend: bool
) -> bool:  # pragma: no cover - compiled
    """A two-bone chain ``p [3, 3]`` onto ``goal`` in closed form (bone lengths ``a``,
    ``b``), in place: its middle joint in the plane through the base, the middle joint and
    the goal, on the middle joint's side; where the middle joint is on the line to the goal
    (a straight leg), on the side of ``bend`` (where the foot points, so a knee bends
    forward). False, ``p`` untouched, where no side is known or the goal is nearer than the
    bones allow, or beyond them."""
    tx, ty, tz = goal[0] - p[0, 0], goal[1] - p[0, 1], goal[2] - p[0, 2]
    d = norm3(tx, ty, tz)
    if d <= abs(a - b) or d <= 1e-12 or d > a + b:
        return False
    ux, uy, uz = tx / d, ty / d, tz / d
    mx, my, mz = p[1, 0] - p[0, 0], p[1, 1] - p[0, 1], p[1, 2] - p[0, 2]
    along = mx * ux + my * uy + mz * uz
    sx, sy, sz = mx - along * ux, my - along * uy, mz - along * uz
    n = norm3(sx, sy, sz)
    if n <= 1e-9 * a and has_bend:
        along = bend[0] * ux + bend[1] * uy + bend[2] * uz
        sx, sy, sz = bend[0] - along * ux, bend[1] - along * uy, bend[2] - along * uz
        n = norm3(sx, sy, sz)
    if n <= 1e-9 * a:
        return False
    x = (a * a - b * b + d * d) / (2.0 * d)
    h = np.sqrt(max(a * a - x * x, 0.0))
    base0, base1, base2 = p[0, 0], p[0, 1], p[0, 2]
    p[1, 0] = base0 + x * ux + h * (sx / n)
    p[1, 1] = base1 + x * uy + h * (sy / n)
    p[1, 2] = base2 + x * uz + h * (sz / n)
    for r in range(3):
        p[2, r] = goal[r]
    return True


@jit
def chain_fabrik_into(
    p: F64, goal: F64, tol: float, iterations: int, bend: F64, has_bend: bool
) -> None:  # pragma: no cover - compiled
    """Single-chain FABRIK of the points ``p [n, 3]`` onto ``goal`` in place, the first
    point fixed, within ``tol`` or ``iterations`` rounds (module docstring); ``bend``: where
    a straight two-bone chain bends to (``has_bend``)."""
    n = p.shape[0]
    lengths = np.empty(n - 1)
    total = 0.0
    for i in range(n - 1):
        lengths[i] = norm3(p[i + 1, 0] - p[i, 0], p[i + 1, 1] - p[i, 1], p[i + 1, 2] - p[i, 2])
        total += lengths[i]
    b0, b1, b2 = p[0, 0], p[0, 1], p[0, 2]
    reach = norm3(goal[0] - b0, goal[1] - b1, goal[2] - b2)
    if reach >= total:  # out of reach: straighten towards it
        scale = max(reach, 1e-300)
        dx, dy, dz = (goal[0] - b0) / scale, (goal[1] - b1) / scale, (goal[2] - b2) / scale
        for i in range(1, n):
            p[i, 0] = p[i - 1, 0] + dx * lengths[i - 1]
            p[i, 1] = p[i - 1, 1] + dy * lengths[i - 1]
            p[i, 2] = p[i - 1, 2] + dz * lengths[i - 1]
        return
    if norm3(p[n - 1, 0] - goal[0], p[n - 1, 1] - goal[1], p[n - 1, 2] - goal[2]) <= tol:
        return  # already there (an untouched pin stays bit for bit)
    if n == 3 and _two_bone_into(p, goal, lengths[0], lengths[1], bend, has_bend):
        return
    for _ in range(iterations):
        if norm3(p[n - 1, 0] - goal[0], p[n - 1, 1] - goal[1], p[n - 1, 2] - goal[2]) <= tol:
            break
        for r in range(3):
            p[n - 1, r] = goal[r]
        for i in range(n - 2, -1, -1):
            dx, dy, dz = p[i, 0] - p[i + 1, 0], p[i, 1] - p[i + 1, 1], p[i, 2] - p[i + 1, 2]
            s = lengths[i] / max(norm3(dx, dy, dz), 1e-300)
            p[i, 0] = p[i + 1, 0] + dx * s
            p[i, 1] = p[i + 1, 1] + dy * s
            p[i, 2] = p[i + 1, 2] + dz * s
        p[0, 0], p[0, 1], p[0, 2] = b0, b1, b2
        for i in range(1, n):
            dx, dy, dz = p[i, 0] - p[i - 1, 0], p[i, 1] - p[i - 1, 1], p[i, 2] - p[i - 1, 2]
            s = lengths[i - 1] / max(norm3(dx, dy, dz), 1e-300)
            p[i, 0] = p[i - 1, 0] + dx * s
            p[i, 1] = p[i - 1, 1] + dy * s
            p[i, 2] = p[i - 1, 2] + dz * s


def chain_fabrik(
    points: F64, goal: F64, tol: float, iterations: int = 64, bend: F64 | None = None
) -> F64:
    """:func:`chain_fabrik_into` of a copy of ``points [n, 3]``."""
    p = np.array(points, dtype=np.float64, order="C")
    chain_fabrik_into(
        p, np.require(goal, np.float64, ["C", "W"]), float(tol), int(iterations),
        np.zeros(3) if bend is None else np.require(bend, np.float64, ["C", "W"]),
        bend is not None,
    )  # fmt: skip
    return p


def warm() -> None:
    """Compile (or load from the cache) :func:`chain_fabrik_into` with its callers'
    signature."""
    line = np.array([[0.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, -2.0, 0.0]])
    chain_fabrik(line, np.array([0.5, -1.5, 0.0]), 1e-6)
    chain_fabrik(line, np.array([0.5, -1.5, 0.0]), 1e-6, bend=np.array([0.0, 0.0, 1.0]))
