"""The machinery every training stage shares: the process group, seeded batches, the
epoch loop with its checkpoints, and the checkpoint tag that says which configuration
fields a stage's weights depend on.

Single process or under ``torchrun --nproc_per_node N`` (DDP, gloo, DistributedSampler;
rank 0 writes). Every stage checkpoints each epoch into ``run_dir`` and resumes from
there; all randomness comes from generators seeded by (seed, stage, epoch), so a resumed
run ends with the same weights as an uninterrupted one.
"""

from __future__ import annotations

import contextlib
import functools
import gc
import hashlib
import io
import json
import math
import os
import platform
import re
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from rich.console import Console
from rich.progress import Progress
from rich.table import Table
from torch import nn
from torch.utils.data import DistributedSampler

from core.io import sha256_file, write_atomic
from core.skeleton import set_key
from trainer.config import SERVING_SETTINGS, LrSchedule, TrainConfig, seen_by_losses
from trainer.data.dataset import DatasetError

console = Console(stderr=True)


# --------------------------------------------------------------------------------------
# Process group
# --------------------------------------------------------------------------------------
class CheckpointError(RuntimeError):
    """A checkpoint in the run dir that cannot be read (truncated by a full disk, a copy
    cut short): named with what to do, instead of torch's traceback."""


@dataclass(frozen=True)
class Dist:
    rank: int = 0
    world: int = 1

    @property
    def main(self) -> bool:
        return self.rank == 0

    def barrier(self) -> None:
        if self.world > 1:
            dist.barrier()

    def close(self) -> None:
        """Leave the process group (after the ranks' last collective): its threads end
        here, not in the interpreter's teardown, where a rank once aborted ("terminate
        called without an active exception") after training had ended. The training's
        DistributedDataParallel wrappers (reference cycles) are collected first, while the
        group is alive: left to the teardown, a reducer outliving its group is one way to
        that abort (it happened again in CI on 2026-12-05, after the group was destroyed
        and training had ended; not reproduced here)."""
        if self.world > 1 and dist.is_initialized():
            gc.collect()
            dist.destroy_process_group()


def init_distributed() -> Dist:
    """Join the torchrun process group when launched by torchrun, else single process."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not dist.is_initialized():
        dist.init_process_group(backend="gloo")
    if world > 1:
        return Dist(rank=dist.get_rank(), world=dist.get_world_size())
    return Dist()


def seed_all(seed: int) -> None:
    torch.manual_seed(seed)


def schedule_lr(
    optim: torch.optim.Optimizer, lr: float, schedule: LrSchedule, epoch: int, step: int,
    steps: int, epochs: int,
) -> None:  # fmt: skip
    """Set ``optim``'s learning rate for ``step`` of ``epoch`` (of ``epochs`` x ``steps``):
    ``lr`` throughout ("constant") or decayed to 0 along a half cosine ("cosine"). A function
    of the step alone, so a resumed stage continues exactly."""
    if schedule == "cosine":
        progress = (epoch * steps + step) / max(1, epochs * steps)
        for group in optim.param_groups:
            group["lr"] = lr * 0.5 * (1.0 + math.cos(math.pi * progress))


def stage_rng(seed: int, stage: str, epoch: int) -> np.random.Generator:
    digest = hashlib.sha256(f"{seed}:{stage}:{epoch}".encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:8], "little"))


# --------------------------------------------------------------------------------------
# Batches
# --------------------------------------------------------------------------------------
def batches(n: int, batch_size: int, d: Dist, seed: int, epoch: int) -> Iterator[torch.Tensor]:
    """Shuffled index batches of this rank's shard (DistributedSampler semantics)."""
    sampler: DistributedSampler[int] = DistributedSampler(
        range(n),  # type: ignore[arg-type]  # any Sized works
        num_replicas=d.world,
        rank=d.rank,
        shuffle=True,
        seed=seed,
        drop_last=True,
    )
    sampler.set_epoch(epoch)
    idx = torch.tensor(list(iter(sampler)), dtype=torch.long)
    for start in range(0, len(idx) - batch_size + 1, batch_size):
        yield idx[start : start + batch_size]


def steps_per_epoch(n: int, batch_size: int, d: Dist) -> int:
    """Optimiser steps in an epoch of ``n`` samples; refuses none (the stage would train
    nothing and its losses read 0)."""
    steps = (n // d.world) // batch_size
    if steps == 0:
        raise DatasetError(
            f"{n} training samples over {d.world} process(es) fill no batch of {batch_size}: "
            "no training step would run; lower batch_size or add training data"
        )
    return steps


# --------------------------------------------------------------------------------------
# Checkpoints
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Bar:
    """One epoch's progress bar (rich); ``update()`` after every step."""

    progress: Progress
    task: Any

    def update(self) -> None:
        self.progress.advance(self.task)


@dataclass
class StageState:
    epoch: int = 0  # epochs completed
    history: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0
    hosts: list[str] = field(default_factory=list)  # :func:`host` of each run that trained it


def host() -> str:
    """What decides a stage's arithmetic besides the code and the seed: the CPU model and
    the SIMD level torch dispatches to, the torch version and the thread count (the same
    seed on another CPU gives slightly other weights; docs/generalisation-serving.md item 29)."""
    model = platform.processor() or platform.machine()
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    capability = torch.backends.cpu.get_cpu_capability()
    return f"{model}, {capability}, torch {torch.__version__}, {torch.get_num_threads()} threads"


@functools.cache
def _sha256_of(path: str, size: int, mtime_ns: int) -> str:
    return sha256_file(Path(path))


def dataset_sha256(path: str | Path) -> str:
    """The sha256 of the dataset file at ``path`` (once per file version in a process)."""
    st = Path(path).stat()
    return _sha256_of(str(Path(path).resolve()), st.st_size, st.st_mtime_ns)


#: ``meta`` keys a rebuild of the same dataset changes: when and how fast it was built.
BUILD_TIMES: tuple[str, ...] = ("created_utc", "build_seconds")


@functools.cache
def _content_of(path: str, size: int, mtime_ns: int) -> str:
    digest = hashlib.sha256()
    with np.load(path, allow_pickle=False) as npz:
        for name in sorted(npz.files):
            array = npz[name]
            if name == "meta":
                meta = {k: v for k, v in json.loads(str(array)).items() if k not in BUILD_TIMES}
                array = np.array(json.dumps(meta, sort_keys=True))
            digest.update(f"{name} {array.dtype.str} {array.shape}\n".encode())
            digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def dataset_content_sha256(path: str | Path) -> str:
    """A sha256 of the dataset at ``path`` as training reads it: every array and ``meta``
    but its build times (:data:`BUILD_TIMES`). Rebuilding the same dataset from the same
    files changes the file's sha256 (the times, the zip's dates), which made every stage
    retrain, to bit-identical models (a studio audit, D8); this does not change."""
    st = Path(path).stat()
    return _content_of(str(Path(path).resolve()), st.st_size, st.st_mtime_ns)


def save_checkpoint(
    path: Path, model: nn.Module, optim: torch.optim.Optimizer, state: StageState, tag: str,
    dataset: str = "", content: str = "",
) -> None:  # fmt: skip
    """``dataset``: the sha256 of the dataset trained on, ``content`` its
    :func:`dataset_content_sha256` (a checkpoint is resumed only on it)."""
    buf = io.BytesIO()
    torch.save(
        {
            "tag": tag,
            "dataset_sha256": dataset,
            "dataset_content_sha256": content,
            "epoch": state.epoch,
            "history": state.history,
            "seconds": state.seconds,
            "hosts": state.hosts,
            "model": model.state_dict(),
            "optim": optim.state_dict(),
        },
        buf,
    )
    write_atomic(path, buf.getvalue())


def whole_sentences(text: str, limit: int = 200) -> str:
    """The first line of ``text`` cut after its last whole sentence within ``limit``
    characters (a first sentence longer than that cut at a word, with "…"): torch's
    "...there is a high likelihood that your checkpoint file is" was cut mid-sentence at
    200 characters (a studio audit, 2026-12-07)."""
    line = (text.strip().splitlines() or [""])[0].strip()
    if len(line) <= limit:
        return line
    ends = [m.end() for m in re.finditer(r"[.!?](?=\s|$)", line) if m.end() <= limit]
    if ends:
        return line[: ends[-1]]
    return line[: limit - 1].rsplit(" ", 1)[0] + "…"


def load_checkpoint(
    path: Path, model: nn.Module, optim: torch.optim.Optimizer, tags: tuple[str, ...],
    dataset: str = "", content: str = "",
) -> StageState:  # fmt: skip
    """The checkpoint at ``path`` if its tag is one of ``tags`` (see :func:`stage_tags`) and
    it was trained on the dataset whose sha256 is ``dataset``, or whose content is
    ``content`` (:func:`dataset_content_sha256`: the same dataset rebuilt) (the tag names
    the dataset by its path: a dataset rebuilt at the same path had its old weights resumed,
    the manifest naming the new file; a checkpoint from before the sha was recorded is
    resumed)."""
    if not path.exists():
        return StageState()
    try:  # (a torch traceback: "failed finding central directory", a studio audit, D14)
        ckpt = torch.load(path, map_location="cpu", weights_only=False)
        if not isinstance(ckpt, dict):
            raise TypeError(f"a {type(ckpt).__name__}, not a checkpoint's table")
    except Exception as exc:  # truncated, not torch's, pickled elsewhere: whatever it is
        why = whole_sentences(str(exc)) or type(exc).__name__
        raise CheckpointError(
            f"{path}: not a readable checkpoint ({why}); delete it (its stage trains anew) "
            "or train with --fresh (every stage anew)"
        ) from None
    if ckpt.get("tag") not in tags:
        console.print(f"[yellow]{path.name}: written by another config; starting the stage anew")
        return StageState()
    was = ckpt.get("dataset_sha256") or ""
    same = bool(content) and ckpt.get("dataset_content_sha256") == content
    if dataset and was and was != dataset and same:
        console.print(f"[cyan]{path.name}: the dataset was rebuilt with the same poses; resumed")
    elif dataset and was and was != dataset:
        console.print(
            f"[yellow]{path.name}: trained on another dataset (sha256 {was[:12]}, now "
            f"{dataset[:12]}); starting the stage anew"
        )
        return StageState()
    model.load_state_dict(ckpt["model"])
    optim.load_state_dict(ckpt["optim"])
    return StageState(
        epoch=ckpt["epoch"],
        history=ckpt["history"],
        seconds=ckpt["seconds"],
        hosts=list(ckpt.get("hosts", [])),  # written before hosts were: none recorded
    )


#: Fields added after checkpoints of their stages existed: in a tag only where they differ
#: from their default, so that runs from before them stay valid.
_ADDED_LATER: dict[str, tuple[str, ...]] = {
    "autoencoder": ("loss", "lr_schedule", "latent_noise"),
    "solver": (
        "rigid_loss",
        "joint_loss",
        "stay_frame",
        "carry_loss",
        "ends_loss",
        "keep_elbows",
        "elbows_loss",
        "long_other_weight",
        "other_weights",
        "stay_weights",
        "stay_frames",
    ),
    "augment": ("lift_start", "joint_shift"),
    "completion": ("loss",),
}


def _section(cfg: TrainConfig, name: str, exclude: tuple[str, ...] = ()) -> dict[str, Any]:
    """A config section as a checkpoint tag sees it: without ``exclude`` and without the
    fields of :data:`_ADDED_LATER` that are at their default."""
    section = getattr(cfg, name)
    out: dict[str, Any] = section.model_dump(exclude=set(exclude))
    fields = type(section).model_fields
    for key in _ADDED_LATER.get(name, ()):
        if key in out and out[key] == fields[key].default:
            del out[key]
    return out


def config_tag(cfg: TrainConfig, stage: str, *, legacy: bool = False) -> str:
    """The fields of ``cfg`` the weights of ``stage`` depend on, hashed: a checkpoint of
    another tag is trained anew. The completion levels read nothing of the autoencoder
    (their own networks, seeds and sample streams), so its section is not in their tags;
    ``legacy``: the tag as it was before that, with it."""
    pairs_only = ("world_pairs", "align_pelvis", "align_floor", "lift_start")  # solvers only
    relevant: dict[str, Any] = {
        "seed": cfg.seed,
        "dataset": cfg.dataset,
        "max_train_frames": cfg.max_train_frames,
        "augment": _section(cfg, "augment", pairs_only),
    }
    if legacy or not stage.startswith("completion"):
        relevant["autoencoder"] = _section(cfg, "autoencoder")
    if stage.startswith("solver"):
        # each bank reads only its own sets and epochs (its own seed and pair stream), so
        # neither is retrained when only the other's change; passes, carry: serving only
        other = ("sets", "epochs") if stage == "solvers_long" else ("long_sets", "long_epochs")
        # (carry, keep_ends and keep_elbows are training settings too where the losses see
        # them: solver.carry_loss, solver.ends_loss, solver.elbows_loss)
        keep = seen_by_losses(cfg.solver.model_dump())
        serving = tuple(k for k in SERVING_SETTINGS if k not in keep)
        per_set = ("long_other_weight", "other_weights", "stay_weights", "stay_frames")
        solver = _section(cfg, "solver", (*serving, *other, *per_set))
        # the weights trained with (SolverConfig.weight_of), not how they are written; where
        # one is other_weight, absent, as in the tags from before the two options
        sc = cfg.solver
        if sc.weight_of([], long=True) != sc.other_weight and stage == "solvers_long":
            solver["long_other_weight"] = sc.weight_of([], long=True)
        own = {set_key(s): sc.weight_of(s) for s in sc.sets if sc.weight_of(s) != sc.other_weight}
        if own and stage == "solvers":
            solver["other_weights"] = own
        stay = {set_key(s): sc.stay_of(s) for s in sc.sets if sc.stay_of(s) != sc.stay_weight}
        if stay and stage == "solvers":
            solver["stay_weights"] = stay
        frames = {set_key(s): sc.frame_of(s) for s in sc.sets if sc.frame_of(s) != sc.stay_frame}
        if frames and stage == "solvers":
            solver["stay_frames"] = frames
        relevant["solver"] = solver
        relevant["augment"] = _section(cfg, "augment")
    if stage.startswith("completion"):  # serving_*: serving only; joint_shift: not read
        relevant["augment"] = _section(cfg, "augment", (*pairs_only, "joint_shift"))
        relevant["completion"] = _section(cfg, "completion", ("serving_yaws", "serving_mirror"))
    text = json.dumps(relevant, sort_keys=True)
    return f"{stage}:{hashlib.sha256(text.encode()).hexdigest()[:16]}"


def stage_tags(cfg: TrainConfig, stage: str) -> tuple[str, ...]:
    """The tag a checkpoint of ``stage`` is written with, then the older forms of it still
    accepted (so that runs from before a tag changed stay valid)."""
    tags = (config_tag(cfg, stage), config_tag(cfg, stage, legacy=True))
    return tuple(dict.fromkeys(tags))


def epoch_table(title: str, history: list[dict[str, float]]) -> Table:
    table = Table(title=title)
    keys = list(history[0].keys()) if history else []
    for key in keys:
        table.add_column(key, justify="right")
    for row in history:
        table.add_row(*(f"{row[k]:.0f}" if k == "epoch" else f"{row[k]:.5g}" for k in keys))
    return table


def run_stage(
    *,
    name: str,
    cfg: TrainConfig,
    d: Dist,
    model: nn.Module,
    trainable: nn.Module,
    optim: torch.optim.Optimizer,
    epochs: int,
    steps: int,
    train_epoch: Callable[[int, Bar], float],
    validate: Callable[[], dict[str, float]],
    fresh: bool,
) -> StageState:
    """The epoch loop shared by every stage: resume, train, validate, log, checkpoint."""
    ckpt = Path(cfg.run_dir) / f"{name}.pt"
    tags = stage_tags(cfg, name)
    tag = tags[0]
    data, content = dataset_sha256(cfg.dataset), dataset_content_sha256(cfg.dataset)
    state = StageState() if fresh else load_checkpoint(ckpt, trainable, optim, tags, data, content)
    if d.world > 1:  # every rank starts from rank 0's weights
        for p in trainable.state_dict().values():
            dist.broadcast(p, src=0)
    if state.epoch >= epochs:
        if d.main:
            console.print(f"[green]{name}: complete in checkpoint, skipping ({state.epoch} epochs)")
        return state
    if state.epoch and d.main:
        console.print(f"[cyan]{name}: resuming after epoch {state.epoch}")
    if (here := host()) not in state.hosts:
        state.hosts.append(here)
    for epoch in range(state.epoch, epochs):
        t0 = time.perf_counter()
        model.train()
        with Progress(console=console, transient=True, disable=not d.main) as progress:
            task = progress.add_task(f"{name} {epoch + 1}/{epochs}", total=steps)
            train_loss = train_epoch(epoch, Bar(progress, task))
        model.eval()
        with torch.no_grad():
            metrics = validate()
        state.seconds += time.perf_counter() - t0
        state.epoch = epoch + 1
        row = {"epoch": float(epoch + 1), "train_loss": train_loss, **metrics}
        state.history.append(row)
        if d.main:
            console.print(
                f"{name} epoch {epoch + 1}/{epochs}: "
                + ", ".join(f"{k}={v:.5g}" for k, v in row.items() if k != "epoch")
                + f" ({time.perf_counter() - t0:.1f}s)"
            )
            save_checkpoint(ckpt, trainable, optim, state, tag, data, content)
        d.barrier()
    if d.main:
        console.print(epoch_table(f"{name}: losses per epoch", state.history))
    return state


def freeze(module: nn.Module) -> None:
    """Evaluation mode, no gradients: a finished stage's network is only read from now on."""
    module.eval()
    for p in module.parameters():
        p.requires_grad_(False)


def mean_loss(total: torch.Tensor, count: int, d: Dist) -> float:
    """The mean of an epoch's step losses over every rank."""
    if d.world > 1:
        buf = torch.tensor([float(total), float(count)], dtype=torch.float64)
        dist.all_reduce(buf)
        return float(buf[0]) / max(float(buf[1]), 1.0)
    return float(total) / max(count, 1)
