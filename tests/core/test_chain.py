"""The compiled single-chain FABRIK of a character's exact reach (``core.compiled_chain``)
against the numpy steps it replaced, kept here as the reference."""

from __future__ import annotations

import numpy as np
import pytest

from core.compiled_chain import chain_fabrik

F64 = np.ndarray


def _two_bone(points: F64, goal: F64, lengths: F64, bend: F64 | None) -> F64 | None:
    a, b = float(lengths[0]), float(lengths[1])
    base, mid = points[0], points[1]
    to_goal = goal - base
    d = float(np.linalg.norm(to_goal))
    if d <= abs(a - b) or d <= 1e-12 or d > a + b:
        return None
    u = to_goal / d
    side = (mid - base) - float((mid - base) @ u) * u
    n = float(np.linalg.norm(side))
    if n <= 1e-9 * a and bend is not None:
        side = bend - float(bend @ u) * u
        n = float(np.linalg.norm(side))
    if n <= 1e-9 * a:
        return None
    x = (a * a - b * b + d * d) / (2.0 * d)
    h = np.sqrt(max(a * a - x * x, 0.0))
    return np.stack([base, base + x * u + h * (side / n), goal])


def _reference(points: F64, goal: F64, tol: float, bend: F64 | None) -> F64:
    """``core.retarget._fabrik`` as numpy steps (the code before the kernel, 73e7718)."""
    p = points.copy()
    lengths = np.linalg.norm(np.diff(p, axis=0), axis=1)
    base = p[0].copy()
    if np.linalg.norm(goal - base) >= lengths.sum():
        d = (goal - base) / max(np.linalg.norm(goal - base), 1e-300)
        for i in range(1, len(p)):
            p[i] = p[i - 1] + d * lengths[i - 1]
        return p
    if np.linalg.norm(p[-1] - goal) <= tol:
        return p
    if len(p) == 3 and (closed := _two_bone(p, goal, lengths, bend)) is not None:
        return closed
    for _ in range(64):
        if np.linalg.norm(p[-1] - goal) <= tol:
            break
        p[-1] = goal
        for i in range(len(p) - 2, -1, -1):
            d = p[i] - p[i + 1]
            p[i] = p[i + 1] + d * (lengths[i] / max(np.linalg.norm(d), 1e-300))
        p[0] = base
        for i in range(1, len(p)):
            d = p[i] - p[i - 1]
            p[i] = p[i - 1] + d * (lengths[i - 1] / max(np.linalg.norm(d), 1e-300))
    return p


@pytest.mark.parametrize("joints", [2, 3, 4, 6])
def test_compiled_chain_fabrik_is_the_numpy_steps(joints: int) -> None:
    """Random chains of 2-6 points (an arm, a leg, a spine), goals within reach, beyond
    it and on the end already, straight two-bone chains with and without a side to bend
    to: the compiled chain within 1e-9 of the numpy steps' (64 rounds of rounding apart at
    most), its bone lengths kept, the same bytes twice, the input left as it was."""
    rng = np.random.default_rng(joints)
    for case in range(60):
        points = np.cumsum(rng.normal(0.0, 0.3, (joints, 3)), axis=0)
        if case % 6 == 5:  # straight: a standing leg
            points = points[0] + np.linspace(0.0, 1.0, joints)[:, None] * rng.normal(size=3)
        reach = float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())
        goal = points[0] + rng.normal(size=3) * reach * rng.uniform(0.1, 1.3)
        if case % 10 == 9:
            goal = points[-1] + 1e-9
        bend = rng.normal(size=3) if case % 2 else None
        before = points.copy()
        got = chain_fabrik(points, goal, 1e-6, bend=bend)
        want = _reference(points, goal, 1e-6, bend)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * max(reach, 1.0))
        np.testing.assert_allclose(
            np.linalg.norm(np.diff(got, axis=0), axis=1),
            np.linalg.norm(np.diff(points, axis=0), axis=1), rtol=1e-9,
        )  # fmt: skip
        assert chain_fabrik(points, goal, 1e-6, bend=bend).tobytes() == got.tobytes()
        assert points.tobytes() == before.tobytes()
