"""Trainer: checkpoint tags (which config fields retrain which stage, and which older
checkpoints stay valid) and the learning-rate schedules; no training."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import pytest
import torch

from trainer.config import load_config
from trainer.stages import (
    StageState,
    _section,
    config_tag,
    load_checkpoint,
    save_checkpoint,
    schedule_lr,
    stage_tags,
)


def test_learning_rate_schedules() -> None:
    """``lr_schedule``: "constant" keeps the base rate, "cosine" halves it at mid-training
    and ends near 0, as a function of the step alone; the autoencoder's choice enters the
    checkpoint tags only when it is not the default (older runs stay valid)."""
    optim = torch.optim.Adam([torch.zeros(1, requires_grad=True)], lr=1.0)
    seen = {}
    for kind in ("constant", "cosine"):
        for epoch, step in ((0, 0), (1, 0), (1, 9)):
            optim.param_groups[0]["lr"] = 3e-3
            schedule_lr(optim, 3e-3, kind, epoch, step, steps=10, epochs=2)
            seen[kind, epoch, step] = optim.param_groups[0]["lr"]
    assert seen["constant", 1, 9] == seen["constant", 0, 0] == 3e-3
    assert seen["cosine", 0, 0] == pytest.approx(3e-3)
    assert seen["cosine", 1, 0] == pytest.approx(1.5e-3)
    assert 0 < seen["cosine", 1, 9] < 3e-5
    plain = load_config(None, {"autoencoder": {"lr_schedule": "constant"}})
    cosine = load_config(None, {"autoencoder": {"lr_schedule": "cosine"}})
    assert config_tag(plain, "autoencoder") == config_tag(load_config(None, {}), "autoencoder")
    assert config_tag(cosine, "autoencoder") != config_tag(plain, "autoencoder")
    assert config_tag(cosine, "completion1") == config_tag(plain, "completion1")


def test_autoencoder_loss_choice_reaches_the_tags_of_its_latent_space() -> None:
    """``autoencoder.loss``: the default leaves every checkpoint tag as it was; ``mpjpe``
    retrains the autoencoder and the solvers trained on its latent space, not the
    completion levels, which read nothing of it."""
    mse = load_config(None, {"autoencoder": {"loss": "mse"}})
    mpjpe = load_config(None, {"autoencoder": {"loss": "mpjpe"}})
    section = _section(mse, "autoencoder")
    assert "loss" not in section and "lr_schedule" not in section  # the tags of before
    for stage in ("autoencoder", "solvers", "solvers_long", "completion1"):
        assert config_tag(mse, stage) == config_tag(load_config(None, {}), stage)
        changes = config_tag(mpjpe, stage) != config_tag(mse, stage)
        assert changes == (not stage.startswith("completion")), stage


def test_long_other_weight_retrains_the_long_bank_alone() -> None:
    """``solver.long_other_weight``: the long bank's own weight of the goal's other joints;
    unset, no tag changes (it is not hashed); set, only ``solvers_long`` is trained anew."""
    base = load_config(None, {})
    assert "long_other_weight" not in _section(base, "solver")
    own = load_config(None, {"solver": {"long_other_weight": 0.1}})
    for stage in ("autoencoder", "solvers", "solvers_long", "completion1"):
        assert (config_tag(own, stage) != config_tag(base, stage)) == (stage == "solvers_long")


def test_completion_checkpoints_tagged_with_the_autoencoder_stay_valid(tmp_path: Path) -> None:
    """Completion tags used to hash the autoencoder's section too: such a checkpoint is
    still resumed under the same config, and not under another autoencoder."""
    cfg = load_config(None, {})
    other = load_config(None, {"autoencoder": {"epochs": 3}})
    net = torch.nn.Linear(2, 2)
    optim = torch.optim.Adam(net.parameters())
    ckpt = tmp_path / "completion1.pt"
    save_checkpoint(
        ckpt, net, optim, StageState(epoch=4), config_tag(cfg, "completion1", legacy=True)
    )
    assert stage_tags(cfg, "completion1")[0] == stage_tags(other, "completion1")[0]
    assert load_checkpoint(ckpt, net, optim, stage_tags(cfg, "completion1")).epoch == 4
    assert load_checkpoint(ckpt, net, optim, stage_tags(other, "completion1")).epoch == 0
    assert stage_tags(cfg, "solvers") == (config_tag(cfg, "solvers"),)


def test_a_checkpoint_is_resumed_only_on_the_dataset_it_was_trained_on(tmp_path: Path) -> None:
    """The tag names the dataset by its path: a dataset rebuilt at the same path had its
    old weights resumed (every stage "complete in checkpoint, skipping") while the manifest
    named the new file. The checkpoint records the dataset's sha256: another one starts the
    stage anew; a checkpoint from before it was recorded is resumed as it was."""
    from trainer.stages import dataset_sha256

    cfg = load_config(None, {})
    net = torch.nn.Linear(2, 2)
    optim = torch.optim.Adam(net.parameters())
    tags = stage_tags(cfg, "solvers")
    first, second = tmp_path / "a.npz", tmp_path / "b.npz"
    first.write_bytes(b"one dataset")
    second.write_bytes(b"another one")
    sha = dataset_sha256(first)
    assert sha == hashlib.sha256(b"one dataset").hexdigest() != dataset_sha256(second)
    ckpt = tmp_path / "solvers.pt"
    save_checkpoint(ckpt, net, optim, StageState(epoch=4), tags[0], sha)
    assert load_checkpoint(ckpt, net, optim, tags, sha).epoch == 4
    assert load_checkpoint(ckpt, net, optim, tags, dataset_sha256(second)).epoch == 0
    save_checkpoint(ckpt, net, optim, StageState(epoch=4), tags[0])  # (none recorded)
    assert load_checkpoint(ckpt, net, optim, tags, dataset_sha256(second)).epoch == 4


def test_serving_settings_enter_the_solver_tags_only_where_the_losses_see_them() -> None:
    """keep_ends and keep_elbows change the solvers' weights only with ends_loss (and, for
    the elbows, elbows_loss): switching one on for serving alone keeps every checkpoint."""
    base = {"rigid_loss": True, "ends_loss": True}

    def tag(stage: str, **solver: object) -> str:
        return config_tag(load_config(None, {"solver": {**base, **solver}}), stage)

    for stage in ("solvers", "solvers_long"):
        assert tag(stage, keep_elbows=True) == tag(stage, keep_elbows=False)
        assert tag(stage, keep_ease=0.005) == tag(stage)  # serving only: never in the losses
        assert tag(stage, bend_side=0.25) == tag(stage)
        assert tag(stage, critic_fabrik=0.005) == tag(stage)
        assert tag(stage, keep_collar=True) == tag(stage)
        assert tag(stage, keep_pelvis=0.02) == tag(stage)
        assert tag(stage, pelvis_travel=True) == tag(stage)
        assert tag(stage, reach_travel=True) == tag(stage)
        assert tag(stage, solve_mirror=True) == tag(stage)
        assert tag(stage, keep_elbows=True, elbows_loss=True) != tag(stage, keep_elbows=True)
        assert tag(stage, keep_ends=False) != tag(stage, keep_ends=True)
        assert tag(stage, ends_loss=False, keep_ends=False) == tag(stage, ends_loss=False)
    assert tag("completion1", keep_elbows=True, elbows_loss=True) == tag("completion1")


def test_a_rebuild_of_the_same_dataset_resumes_its_checkpoints(
    small_dataset: Path, mocap_clips: Any, tmp_path: Path
) -> None:
    """A studio audit (D8): rebuilding the dataset from the same files gave a file of
    another sha256 (its build time, its zip's dates), so every stage was thrown away and
    retrained, to bit-identical models. A checkpoint now also records the dataset's content
    (every array, ``meta`` but its build times): a rebuild resumes; other poses do not."""
    import numpy as np

    from trainer.data.build import build_dataset
    from trainer.stages import dataset_content_sha256, dataset_sha256

    rebuilt = tmp_path / "poses.npz"
    build_dataset(mocap_clips.root, rebuilt, seed=0, workers=2, progress=False)
    assert dataset_sha256(rebuilt) != dataset_sha256(small_dataset)  # (the file's bytes)
    with np.load(small_dataset, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    moved = tmp_path / "moved.npz"
    np.savez(moved, **{**arrays, "positions": arrays["positions"] * np.float32(1.01)})
    cfg = load_config(None, {})
    net = torch.nn.Linear(2, 2)
    optim = torch.optim.Adam(net.parameters())
    tags = stage_tags(cfg, "solvers")
    ckpt = tmp_path / "solvers.pt"
    sha, content = dataset_sha256(small_dataset), dataset_content_sha256(small_dataset)
    save_checkpoint(ckpt, net, optim, StageState(epoch=4), tags[0], sha, content)
    for data, epoch in ((rebuilt, 4), (moved, 0), (small_dataset, 4)):
        got = load_checkpoint(
            ckpt, net, optim, tags, dataset_sha256(data), dataset_content_sha256(data)
        )
        assert got.epoch == epoch, data
