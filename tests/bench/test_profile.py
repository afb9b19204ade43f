"""``python -m bench.profile``: a lone soft edit's steps timed, the engine's internals as
they are (it breaks here, not silently, when they change)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench import profile
from service.engine import Engine
from service.runtime import _FewRows


@pytest.mark.parametrize("targets", [1, 2, 5])
def test_every_step_is_timed(engine: Engine, bench_dataset: Path, targets: int) -> None:
    bound = _FewRows.bound
    p = profile.common_edit(engine, bench_dataset, targets, seed=0)
    got = profile.steps(engine, p, windows=1, calls=2)
    assert _FewRows.bound is bound  # the runs are real again
    assert "onnxruntime: one run of 2 rows, x2" in got or targets == 1
    assert "kernel settle_last" in got and "whole (Engine.solve)" in got
    assert all(0.0 < us < 1e6 for us in got.values())
