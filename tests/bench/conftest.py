"""Fixtures of the benchmark tests."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def holdout_dataset(small_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The small real dataset with its cmu-dance clips relabelled as held-out bodies and
    one Bandai val clip too (two held-out sources), the rest as built."""
    from trainer.data.dataset import load_dataset, save_dataset

    data = load_dataset(small_dataset)
    split = data.clip_split.astype("<U16")
    split[data.clip_source == "cmu-dance"] = "holdout"
    bandai_val = np.flatnonzero((data.clip_source == "bandai-namco") & (split == "val"))
    split[bandai_val[:1]] = "holdout"
    assert (split == "test").any()
    path = tmp_path_factory.mktemp("holdout") / "poses.npz"
    save_dataset(path, dataclasses.replace(data, clip_split=split))
    return path


@pytest.fixture(scope="session")
def bench_dataset(request: pytest.FixtureRequest) -> Path:
    """data/poses.npz if it was built (with held-out bodies), else the small one (once per
    session: reading data/poses.npz to look for held-out bodies took ~3.5 s a module)."""
    path = REPO_ROOT / "data" / "poses.npz"
    if path.is_file():
        from trainer.data.dataset import load_dataset

        if load_dataset(path).split_mask("holdout").any():
            return path
    built: Path = request.getfixturevalue("holdout_dataset")
    return built
