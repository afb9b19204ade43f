"""A probe of representation, not a shipped model: does an autoencoder on bone DIRECTIONS
reconstruct held-out bodies closer than the shipped one on joint positions?

The shipped autoencoder (``trainer.models.TiedAutoencoder``) reads a pose as 21 joint
positions, canonical frame, every body scaled to one total bone length. Half of its error
on bodies it never saw is their proportions (issue 11). A pose read as the pelvis position
and the 20 bones' unit directions (63 numbers as well) holds no proportions at all: the
decoded directions are put back on the body's OWN bone lengths, root outwards, so the
answer has them exactly, whatever the body.

This trains such an autoencoder with the shipped one's recipe (the same samples: random
bodies, placements, mirror, facings and offsets of ``ae_samples``; the same architecture,
optimiser, batch, epochs and loss: MSE of normalised features; a recipe with a learning-rate
schedule or another loss is refused, not silently trained otherwise) and scores both on the
held-out poses ``python -m bench.heldout`` scores the shipped one on
(``bench.heldout.recon_sample``), and as many of each in-studio TEST source drawn the same
way, through the same mapping as ``Engine.reconstruct`` (canonical frame, one size). Beside
them: the shipped autoencoder's answer after the bone pass (the body's own lengths), the
fair peer of an answer that has them by construction.

    python -m trainer.probe_directions --out reports/probe_directions.json
    python -m trainer.probe_directions --loss positions \
        --out reports/probe_directions_positions.json

Measured: docs/generalisation-serving-2.md item 44.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated

import numpy as np
import numpy.typing as npt
import torch
import typer
from torch import nn

from bench.heldout import HeldoutConfig, recon_sample
from core.geometry import canonical_transform
from core.io import write_atomic
from core.kinematics import bone_pass
from core.skeleton import BONE_CHILDREN, BONE_PARENTS, NUM_JOINTS, bone_lengths
from service.engine import Engine
from trainer.config import load_config
from trainer.data.dataset import load_dataset
from trainer.models import Normaliser, TiedAutoencoder, feature_stats
from trainer.stages import Dist, batches, console, seed_all, stage_rng, steps_per_epoch
from trainer.train import ae_samples, as_joints, flat, load_splits, reference_lengths

F64 = npt.NDArray[np.float64]
PELVIS = 0
app = typer.Typer(add_completion=False)
ONE = Dist()  # one process


def to_directions(poses: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``[B, 21, 3]`` poses -> features ``[B, 63]`` (pelvis, then the 20 bones' unit
    directions in ``BONES`` order) and the bones' lengths ``[B, 20]``."""
    bones = poses[:, BONE_CHILDREN] - poses[:, BONE_PARENTS]
    lengths = torch.linalg.vector_norm(bones, dim=-1)
    units = bones / lengths.clamp_min(1e-9)[..., None]
    return torch.cat([poses[:, PELVIS], units.reshape(len(poses), -1)], dim=-1), lengths


def from_directions(features: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """Features ``[B, 63]`` and bone lengths ``[B, 20]`` -> poses ``[B, 21, 3]``: each
    decoded direction made unit and laid root outwards with its bone's length."""
    units = features[:, 3:].reshape(len(features), -1, 3)
    units = units / torch.linalg.vector_norm(units, dim=-1, keepdim=True).clamp_min(1e-9)
    joints: list[torch.Tensor | None] = [None] * NUM_JOINTS
    joints[PELVIS] = features[:, :3]
    for b, (child, parent) in enumerate(zip(BONE_CHILDREN, BONE_PARENTS, strict=True)):
        base = joints[int(parent)]
        assert base is not None  # BONES is in topological order
        joints[int(child)] = base + lengths[:, b, None] * units[:, b]
    return torch.stack([j for j in joints if j is not None], dim=1)


def train_directions(
    config: Path, epochs: int | None, loss_kind: str
) -> tuple[TiedAutoencoder, float, float]:
    """The direction autoencoder, trained as ``trainer.train.train_autoencoder`` trains
    the shipped one; returns it, the reference total bone length and the seconds taken.
    ``loss_kind``: ``features`` (the shipped loss: MSE of the normalised features) or
    ``positions`` (MSE of the joints once laid on the sample's own lengths, metres: a bone
    near the pelvis counts for every joint it carries)."""
    cfg = load_config(config)
    torch.set_num_threads(cfg.threads)
    torch.use_deterministic_algorithms(True)
    seed_all(cfg.seed)
    ac, aug = cfg.autoencoder, cfg.augment
    if ac.lr_schedule != "constant" or ac.loss != "mse":
        raise typer.BadParameter(
            f"the probe trains at a constant rate on the MSE of normalised features; {config} "
            f"asks lr_schedule={ac.lr_schedule!r}, loss={ac.loss!r}"
        )
    splits = load_splits(cfg)
    train = flat(splits.train.positions)
    total = float(reference_lengths(splits.train).sum())
    sample = ae_samples(
        train[:: max(1, len(train) // 100_000)], np.random.default_rng(cfg.seed + 7), aug, total
    )
    mean, std = feature_stats(to_directions(as_joints(sample))[0], ac.std_floor)
    torch.manual_seed(cfg.seed)
    ae = TiedAutoencoder(Normaliser(mean, std), ac.hidden, ac.latent)
    optim = torch.optim.Adam(ae.parameters(), lr=ac.lr)
    n_epochs = epochs if epochs is not None else ac.epochs
    steps = steps_per_epoch(len(train), ac.batch_size, ONE)
    t0 = time.perf_counter()
    for epoch in range(n_epochs):
        rng = stage_rng(cfg.seed, "autoencoder", epoch)
        loss_sum = 0.0
        for idx in batches(len(train), ac.batch_size, ONE, cfg.seed, epoch):
            poses = as_joints(ae_samples(train[idx], rng, aug, total))
            x, lengths = to_directions(poses)
            if loss_kind == "positions":
                loss = nn.functional.mse_loss(from_directions(ae(x), lengths), poses)
            else:
                loss = nn.functional.mse_loss(ae.norm.normalise(ae(x)), ae.norm.normalise(x))
            optim.zero_grad(set_to_none=True)
            loss.backward()
            optim.step()
            loss_sum += float(loss.detach())
        console.print(f"directions epoch {epoch + 1}/{n_epochs}: loss {loss_sum / steps:.6f}")
    ae.eval()
    return ae, total, time.perf_counter() - t0


def round_trip(ae: TiedAutoencoder, world: F64, total: float) -> F64:
    """The direction autoencoder's round trip of world poses ``[B, 21, 3]``, mapped as
    ``Engine.reconstruct`` maps them (canonical frame, one total bone length) and laid
    on each body's own lengths."""
    frame = canonical_transform(world)
    canon = frame.to_canonical(world)
    scale = bone_lengths(world).sum(axis=-1)[:, None, None] / total
    poses = torch.from_numpy((canon / scale).astype(np.float32))
    with torch.no_grad():
        x, lengths = to_directions(poses)
        out = from_directions(ae(x), lengths).double().numpy()
    return np.asarray(frame.to_world(out * scale))


def errors_cm(pred: F64, true: F64) -> dict[str, float]:
    """Mean per-joint distance, and the worst joint's mean, cm."""
    per_joint = np.linalg.norm(pred - true, axis=-1).mean(axis=0) * 100.0
    return {
        "mean": round(float(per_joint.mean()), 3),
        "worst_joint": round(float(per_joint.max()), 3),
    }


@app.command()
def main(
    models: Annotated[Path, typer.Option(help="The shipped models (the position peer).")] = Path(
        "models"
    ),
    config: Annotated[Path, typer.Option(help="The recipe to train with.")] = Path(
        "trainer/configs/default.toml"
    ),
    epochs: Annotated[int | None, typer.Option(help="Epochs (the recipe's by default).")] = None,
    loss: Annotated[str, typer.Option(help="features (the shipped loss) or positions.")] = (
        "features"
    ),
    out: Annotated[Path, typer.Option(help="Where the JSON goes.")] = Path(
        "reports/probe_directions.json"
    ),
) -> None:
    if loss not in ("features", "positions"):
        raise typer.BadParameter(f"loss must be features or positions, got {loss!r}")
    ae, total, seconds = train_directions(config, epochs, loss)
    engine = Engine(models, threads=1)
    cfg = HeldoutConfig()
    dataset = load_dataset(load_config(config).dataset)
    rows: dict[str, dict[str, dict[str, float]]] = {}
    pooled: dict[str, list[F64]] = {"poses": [], "positions": [], "bone_pass": [], "dirs": []}
    for split in ("holdout", "test"):
        part = dataset.subset(dataset.split_mask(split))
        world = part.world()
        sources = sorted(set(part.clip_source[np.unique(part.clip)].tolist()))
        for k, source in enumerate(sources):
            poses = np.asarray(
                recon_sample(world[part.source_mask(source)], cfg, k, len(sources)), np.float64
            )
            shipped = engine.reconstruct(poses)
            answers = {
                "positions": shipped,
                "bone_pass": np.asarray(bone_pass(shipped, bone_lengths(poses))),
                "dirs": round_trip(ae, poses, total),
            }
            rows[f"{split}: {source}"] = {k2: errors_cm(a, poses) for k2, a in answers.items()}
            if split == "holdout":
                pooled["poses"].append(poses)
                for k2, a in answers.items():
                    pooled[k2].append(a)
    truth = np.concatenate(pooled["poses"])
    rows["holdout: all"] = {
        k2: errors_cm(np.concatenate(pooled[k2]), truth)
        for k2 in ("positions", "bone_pass", "dirs")
    }
    for name, row in rows.items():
        console.print(
            f"{name}: positions {row['positions']['mean']:.2f} cm, after the bone pass "
            f"{row['bone_pass']['mean']:.2f}, directions {row['dirs']['mean']:.2f} "
            f"(worst joint {row['positions']['worst_joint']:.2f} / "
            f"{row['bone_pass']['worst_joint']:.2f} / {row['dirs']['worst_joint']:.2f})"
        )
    report = {
        "config": str(config),
        "epochs": epochs,
        "loss": loss,
        "train_seconds": round(seconds, 1),
        "models": engine.version,
        "rows": rows,
    }
    write_atomic(out, json.dumps(report, indent=1).encode())
    console.print(f"wrote {out}")


if __name__ == "__main__":
    app()
