"""``core.geometry.rotation_about``: the numpy turn about an axis."""

from __future__ import annotations

import numpy as np


def test_rotation_about_is_the_compiled_turn() -> None:
    """``rotation_about`` (numpy) and ``core.compiled_hinges._turn_into`` (compiled): one
    rotation, a turn of ``angle`` about the axis that leaves the axis where it is."""
    from core.compiled_hinges import _turn_into
    from core.geometry import rotation_about

    rng = np.random.default_rng(0)
    for axis, angle in zip(rng.normal(size=(20, 3)), rng.uniform(-3.0, 3.0, 20), strict=True):
        axis /= np.linalg.norm(axis)
        r = rotation_about(axis, float(angle))
        compiled = np.empty((3, 3))
        _turn_into(axis, float(angle), compiled)
        np.testing.assert_allclose(r, compiled, atol=1e-14)
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-14)
        np.testing.assert_allclose(r @ axis, axis, atol=1e-14)
        across = np.cross(axis, rng.normal(size=3))
        across /= np.linalg.norm(across)
        assert np.isclose(across @ (r @ across), np.cos(angle), atol=1e-12)
