"""Training of the autoencoder, the solver bank and the completion levels: each stage's
samples, losses and validation, run by the shared epoch loop of :mod:`trainer.stages`
(process group, checkpoints, resume), and :func:`train_all`, which runs them in order.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import torch
from rich.markup import escape
from torch import nn
from torch.nn.parallel import DistributedDataParallel

from core.ends import active
from core.skeleton import JOINT_INDEX, NUM_JOINTS
from core.skeleton import bone_lengths as bone_lengths_np
from trainer.augment import (
    FrameSource,
    augment_pairs,
    augment_poses,
    goal_in_start_frame,
    lift_onto,
    random_bodies,
    rebuild,
    turn,
)
from trainer.augment import mirror as mirror_poses
from trainer.config import AugmentConfig, TrainConfig
from trainer.data.checks import BONE_RANGE_TEXT, bad_bones, implausible
from trainer.data.dataset import FPS, DatasetError, PoseDataset, load_dataset
from trainer.models import (
    CompletionNet,
    Normaliser,
    SolverBank,
    TiedAutoencoder,
    feature_stats,
    merge_banks,
    target_columns,
)
from trainer.pairs import partner_ranges, sample_partners
from trainer.rigid import (
    across_pelvis_t,
    bone_lengths_t,
    bone_pass_t,
    carry_t,
    ends_t,
    parent_offsets_t,
)
from trainer.stages import (
    Bar,
    Dist,
    StageState,
    batches,
    console,
    freeze,
    init_distributed,
    mean_loss,
    run_stage,
    schedule_lr,
    seed_all,
    stage_rng,
    steps_per_epoch,
)


# --------------------------------------------------------------------------------------
# Data
# --------------------------------------------------------------------------------------
@dataclass
class Splits:
    train: PoseDataset
    val: PoseDataset
    test: PoseDataset


def load_splits(cfg: TrainConfig) -> Splits:
    data = load_dataset(cfg.dataset)
    train = data.subset(data.split_mask("train"))
    if cfg.max_train_frames is not None and len(train.positions) > cfg.max_train_frames:
        # whole clips, in order, until the cap: keeps pairs inside clips
        clips = np.unique(train.clip)
        rng = np.random.default_rng(cfg.seed)
        rng.shuffle(clips)
        sizes = np.array([(train.clip == c).sum() for c in clips])
        keep = clips[: max(1, int(np.searchsorted(np.cumsum(sizes), cfg.max_train_frames)) + 1)]
        train = train.subset(np.isin(train.clip, keep))
    splits = Splits(
        train=train,
        val=data.subset(data.split_mask("val")),
        test=data.subset(data.split_mask("test")),
    )
    # (it failed deep in training, or without test frames after it, in the evaluation:
    # "cannot reshape array of size 0")
    for name in ("train", "val", "test"):
        if len(getattr(splits, name).positions) == 0:
            counts = {s: int(data.split_mask(s).sum()) for s in ("train", "val", "test")}
            raise DatasetError(
                f"{cfg.dataset}: no {name} frames (frames per split: {counts}); clips are split "
                "by clip within each source, content and actor: 1 clip -> test, 2 -> test + "
                "train, 3 or more give val one (docs/data.md, Splits): add clips, or force a "
                "clip's split with an [[override]] split = ... in the map"
            )
    n = len(splits.train.positions)
    batches = {
        f"[{name}] batch_size": section.batch_size
        for name, section in (
            ("autoencoder", cfg.autoencoder), ("solver", cfg.solver), ("completion", cfg.completion)
        )
    }  # fmt: skip
    odd = implausible(data)
    if odd and not cfg.accept_implausible:  # (it trained and exported: served nonsense)
        raise DatasetError(
            f"{cfg.dataset}: its poses are implausible for a human body, likely a wrong key "
            f"of the map: {'; '.join(odd)}; fix the map and rebuild the dataset (the dataset "
            "summary warned of it; docs/data.md), or, if the poses are right, train with "
            "--accept-implausible (accept_implausible = true in the config)"
        )
    bad = bad_bones(reference_lengths(splits.train))
    if bad:  # (it trained every stage, then the export failed: "reference bone lengths
        # must be in (0, 2) metres", a pydantic traceback)
        raise DatasetError(
            f"{cfg.dataset}: the train split's mean bone length is outside {BONE_RANGE_TEXT} "
            f"for {', '.join(bad)}: the map's two source joints of such a bone coincide (or "
            "lie far apart: the `unit`?); fix the map and rebuild (the dataset summary warned "
            "of it)"
        )
    short = {key: size for key, size in batches.items() if size > n}
    if short:  # (it trained nothing: no step ran, losses 0, and the models were exported)
        wanted = ", ".join(f"{key} = {size}" for key, size in short.items())
        raise DatasetError(
            f"{cfg.dataset}: the train split has {n} frames, fewer than one batch ({wanted}): "
            "no training step would run; add clips to train (an [[override]] split = "
            f'"train" in the map) or lower those batch sizes in the config to at most {n}'
        )
    return splits


def flat(positions: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(positions.reshape(len(positions), -1), np.float32))


def reference_lengths(data: PoseDataset) -> np.ndarray:
    """Mean length of every bone over the frames of ``data`` ``[20]`` (metres): the
    manifest's reference skeleton, and the size every body is normalised to."""
    return np.asarray(bone_lengths_np(data.positions.astype(np.float64)).mean(axis=0))


def as_joints(flat_poses: torch.Tensor) -> torch.Tensor:
    return flat_poses.reshape(len(flat_poses), NUM_JOINTS, 3)


# --------------------------------------------------------------------------------------
# Stages
# --------------------------------------------------------------------------------------
def mpjpe_loss(pred: torch.Tensor, true: torch.Tensor) -> torch.Tensor:
    """Mean per-joint distance (m) between flattened ``[N, 63]`` poses, differentiable."""
    dist: torch.Tensor = torch.linalg.vector_norm((pred - true).reshape(len(pred), -1, 3), dim=-1)
    return dist.mean()


def mpjpe_cm(pred: torch.Tensor, true: torch.Tensor) -> float:
    """Mean per-joint position error in cm between flattened ``[N, 63]`` poses."""
    return float(mpjpe_loss(pred, true)) * 100.0


def ae_samples(
    poses: torch.Tensor, rng: np.random.Generator, aug: AugmentConfig, total: float
) -> torch.Tensor:
    """What the autoencoder learns from: poses on random bodies, facings and offsets (or the
    poses as recorded when augmentation is off), flattened ``[B, 63]``."""
    if not aug.enabled:
        return poses
    out = augment_poses(as_joints(poses), rng, aug, total)
    return out.reshape(len(poses), -1)


def train_autoencoder(
    cfg: TrainConfig, d: Dist, train: torch.Tensor, val: torch.Tensor, total: float, fresh: bool
) -> tuple[TiedAutoencoder, StageState]:
    ac, aug = cfg.autoencoder, cfg.augment
    stats_sample = train[:: max(1, len(train) // 100_000)]
    stats_sample = ae_samples(stats_sample, np.random.default_rng(cfg.seed + 7), aug, total)
    mean, std = feature_stats(stats_sample, ac.std_floor)
    val = ae_samples(val, np.random.default_rng(cfg.seed + 8), aug, total)
    torch.manual_seed(cfg.seed)
    ae = TiedAutoencoder(Normaliser(mean, std), ac.hidden, ac.latent)
    net: nn.Module = DistributedDataParallel(ae) if d.world > 1 else ae
    optim = torch.optim.Adam(ae.parameters(), lr=ac.lr)
    steps = steps_per_epoch(len(train), ac.batch_size, d)

    def train_epoch(epoch: int, bar: Bar) -> float:
        rng = stage_rng(cfg.seed, "autoencoder", epoch)
        # the latents' noise: its own stream per epoch and rank, so a resumed run draws what
        # an uninterrupted one does (the global torch generator is not in the checkpoint)
        noise_rng = stage_rng(cfg.seed, f"autoencoder-noise:{d.rank}", epoch)
        shakes = torch.Generator().manual_seed(int(noise_rng.integers(2**62)))
        total_loss, count = torch.zeros((), dtype=torch.float64), 0
        for step, idx in enumerate(batches(len(train), ac.batch_size, d, cfg.seed, epoch)):
            schedule_lr(optim, ac.lr, ac.lr_schedule, epoch, step, steps, ac.epochs)
            x = ae_samples(train[idx], rng, aug, total)
            if ac.latent_noise > 0:  # [clean; shaken] reconstructions of the batch
                recon, x = net(x, ac.latent_noise, shakes), torch.cat([x, x])
            else:
                recon = net(x)
            if ac.loss == "mpjpe":
                loss = mpjpe_loss(recon, x)
            else:
                loss = nn.functional.mse_loss(ae.norm.normalise(recon), ae.norm.normalise(x))
            optim.zero_grad(set_to_none=True)
            loss.backward()
            optim.step()
            total_loss += loss.detach().double()
            count += 1
            bar.update()
        return mean_loss(total_loss, count, d)

    def validate() -> dict[str, float]:
        recon = ae(val)
        loss = float(nn.functional.mse_loss(ae.norm.normalise(recon), ae.norm.normalise(val)))
        return {"val_loss": loss, "val_mpjpe_cm": mpjpe_cm(recon, val)}

    state = run_stage(
        name="autoencoder",
        cfg=cfg,
        d=d,
        model=net,
        trainable=ae,
        optim=optim,
        epochs=ac.epochs,
        steps=steps,
        train_epoch=train_epoch,
        validate=validate,
        fresh=fresh,
    )
    freeze(ae)
    return ae, state


@dataclass(frozen=True)
class PairSource:
    frames: FrameSource
    lo: np.ndarray
    hi: np.ndarray
    frame: np.ndarray

    @property
    def poses(self) -> torch.Tensor:
        return self.frames.poses.reshape(len(self.frames.poses), -1)

    @classmethod
    def of(cls, data: PoseDataset, max_gap: int) -> PairSource:
        lo, hi = partner_ranges(data.clip, data.frame, max_gap)
        frames = FrameSource(
            poses=torch.from_numpy(np.ascontiguousarray(data.positions, np.float32)),
            yaw=torch.from_numpy(np.ascontiguousarray(data.yaw, np.float32)),
            root=torch.from_numpy(np.ascontiguousarray(data.root, np.float32)),
        )
        return cls(frames=frames, lo=lo, hi=hi, frame=data.frame)

    def fixed_pairs(self, seed: int, limit: int) -> tuple[torch.Tensor, torch.Tensor]:
        rng = np.random.default_rng(seed)
        anchors = np.arange(len(self.poses))
        if len(anchors) > limit:
            anchors = np.sort(rng.choice(anchors, size=limit, replace=False))
        partners = sample_partners(self.lo, self.hi, anchors, rng)
        keep = partners != anchors
        return torch.from_numpy(anchors[keep]), torch.from_numpy(partners[keep])

    def pairs(
        self,
        start: torch.Tensor,
        goal: torch.Tensor,
        rng: np.random.Generator,
        aug: AugmentConfig,
        total: float,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Flattened ``(start, goal)`` ``[B, 63]`` as the service sees an edit: the goal in
        the start's frame, both on one random body (see ``trainer.augment``)."""
        if aug.enabled and aug.world_pairs:
            s, g = goal_in_start_frame(self.frames, start, goal, rng, aug)
        else:
            s, g = self.frames.poses[start], self.frames.poses[goal]
            if aug.enabled and aug.lift_start > 0:
                s = lift_onto(s, g, torch.from_numpy(rng.random(len(s)) < aug.lift_start))
        if aug.enabled:
            s, g = augment_pairs(s, g, rng, aug, total)
        return s.reshape(len(s), -1), g.reshape(len(g), -1)


def answer_mode(delta: bool, anchor: bool) -> str:
    """How a solver's latent becomes the answer (see :func:`solved_poses`)."""
    return "anchored" if delta and anchor else "delta" if delta else "plain"


#: ``solver.stay_frame``: what the stay term compares of an answer and its start.
STAY_FRAMES: dict[str, Callable[[torch.Tensor], torch.Tensor]] = {
    "world": lambda x: x,
    "local": parent_offsets_t,
    "across": across_pelvis_t,
}


def solver_losses(
    ae: TiedAutoencoder,
    bank: SolverBank,
    net: nn.Module,
    start: torch.Tensor,
    goal: torch.Tensor,
    other_weight: float | torch.Tensor,
    bone_weight: float = 0.0,
    mode: str = "plain",
    stay_weight: float | torch.Tensor = 0.0,
    rigid: bool = False,
    distance: bool = False,
    stay_frame: str | list[str] = "world",
    carry: float = 0.0,
    ends: npt.NDArray[np.bool_] | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-solver loss ``[S]`` and answers ``[S, B, 63]`` for a batch of pairs (``mode`` as
    the service answers, :func:`solved_poses`):
    MSE(target joints) + other_weight * MSE(other joints) (``other_weight``: one for every
    solver, or ``[S]``, one each)
    + bone_weight * MSE(decoded bone lengths - start bone lengths) (same clip, same body)
    + stay_weight * MSE(other joints - their start positions).
    ``rigid``: the joint terms are measured on the answer after the service's bone pass
    to the start's bone lengths (:mod:`trainer.rigid`), i.e. on what is served.
    ``distance``: the joint terms are mean per-joint distances instead of MSEs.
    ``stay_frame``: the stay term on each joint's world position ("world"), its offset
    from its parent ("local": the root's position; :func:`trainer.rigid.parent_offsets_t`)
    or its place relative to the pelvis across ("across": :func:`trainer.rigid.across_pelvis_t`);
    one for every solver, or a list, one each (each solver's term in its own frame).
    ``carry`` (with ``rigid``): the answer also with the service's carry below each
    solver's targets (:func:`trainer.rigid.carry_t`), as served with ``serving.carry``.
    ``ends`` (with ``rigid``): then each solver's targeted joints of the chains it marks
    (:func:`core.ends.active`) kept where the network put them
    (:func:`trainer.rigid.ends_t`), as served with ``serving.keep_ends`` and
    ``serving.keep_elbows``; None: none."""
    n_sets = len(bank.sets)
    decoded = solved_poses(ae, net, start, goal, n_sets, mode)
    start_lengths = bone_lengths_t(start)
    answer = bone_pass_t(decoded, start_lengths) if rigid else decoded
    sets = [[JOINT_INDEX[j] for j in joints] for joints in bank.sets]
    if rigid and carry > 0:
        answer = carry_t(answer, start, start_lengths, sets, carry)
    if rigid and ends is not None and ends.any():
        answer = ends_t(answer, decoded, sets, ends)
    goal_s = goal.unsqueeze(0).expand(n_sets, -1, -1)
    target_mask = torch.zeros(n_sets, 1, goal.shape[1])
    for s, joints in enumerate(bank.sets):
        target_mask[s, 0, target_columns(joints)] = 1.0
    tm = target_mask[:, 0]
    if distance:  # per joint: the mask's x column marks the joint
        tm = tm[:, 0::3]

    def per_item(diff: torch.Tensor) -> torch.Tensor:
        """``[S, B, 63]`` -> per column (MSE) or per joint (distance), mean over B."""
        if distance:
            n, b = diff.shape[0], diff.shape[1]
            dist: torch.Tensor = torch.linalg.vector_norm(diff.reshape(n, b, -1, 3), dim=-1)
            return dist.mean(dim=1)
        return (diff**2).mean(dim=1)

    per_col = per_item(answer - goal_s)  # [S, 63] or [S, 21]
    target_term = (per_col * tm).sum(-1) / tm.sum(-1)
    other_term = (per_col * (1 - tm)).sum(-1) / (1 - tm).sum(-1)
    loss = target_term + other_weight * other_term
    if float(torch.as_tensor(stay_weight).max()) > 0:  # the joints not asked for move as
        # little as the targets allow (``stay_weight``: one for every solver, or ``[S]``)
        def moves(name: str) -> torch.Tensor:
            frame = STAY_FRAMES[name]
            return per_item(frame(answer) - frame(start).unsqueeze(0))

        if isinstance(stay_frame, str):
            moved = moves(stay_frame)
        else:  # each solver's row from its own frame's moves (each frame computed once)
            by_frame = {name: moves(name) for name in dict.fromkeys(stay_frame)}
            moved = torch.stack([by_frame[name][s] for s, name in enumerate(stay_frame)])
        loss = loss + stay_weight * (moved * (1 - tm)).sum(-1) / (1 - tm).sum(-1)
    if bone_weight > 0:
        bone_err = bone_lengths_t(decoded) - start_lengths.unsqueeze(0)
        loss = loss + bone_weight * (bone_err**2).mean(dim=(1, 2))
    return loss, decoded


def solved_poses(
    ae: TiedAutoencoder,
    net: nn.Module,
    start: torch.Tensor,
    goal: torch.Tensor,
    n_sets: int,
    mode: str,
) -> torch.Tensor:
    """Every solver's answer ``[S, B, 63]`` for pairs ``[B, 63]``, z = E(start):

    * ``plain``: D(S(z, t)) (the paper);
    * ``delta``: start + D(S(z, t)) - D(z): the autoencoder's error on the start pose
      stays out of the answer;
    * ``anchored``: start + D(S(z, t)) - D(S(z, x_t)): also what the solver does when
      asked to stay where it is, so an edit that asks for nothing changes nothing."""
    z = ae.encode(start).unsqueeze(0).expand(n_sets, -1, -1)
    decoded = ae.decode(net(z, goal.unsqueeze(0).expand(n_sets, -1, -1)))
    if mode == "delta":
        decoded = decoded + (start - ae.decode(z[0])).unsqueeze(0)
    elif mode == "anchored":
        stay = ae.decode(net(z, start.unsqueeze(0).expand(n_sets, -1, -1)))
        decoded = decoded + (start.unsqueeze(0) - stay)
    return decoded


def solver_metrics(
    ae: TiedAutoencoder,
    bank: SolverBank,
    start: torch.Tensor,
    goal: torch.Tensor,
    mode: str = "plain",
) -> dict[str, dict[str, float]]:
    """Per solver: mean reach error of its targets and MPJPE of the whole pose (cm)."""
    decoded = solved_poses(ae, bank, start, goal, len(bank.sets), mode)
    start_lengths = bone_lengths_t(start)
    out: dict[str, dict[str, float]] = {}
    for s, joints in enumerate(bank.sets):
        err = (decoded[s] - goal).reshape(len(goal), NUM_JOINTS, 3).norm(dim=-1)
        cols = [c // 3 for c in target_columns(joints)[::3]]
        bone = (bone_lengths_t(decoded[s]) - start_lengths).abs()
        rigid = bone_pass_t(decoded[s], start_lengths)
        served = (rigid - goal).reshape(len(goal), NUM_JOINTS, 3).norm(dim=-1)
        out["+".join(sorted(joints))] = {
            "reach_cm": float(err[:, cols].mean()) * 100.0,
            "served_reach_cm": float(served[:, cols].mean()) * 100.0,
            "mpjpe_cm": float(err.mean()) * 100.0,
            "bone_cm": float(bone.mean()) * 100.0,
        }
    return out


def per_set(weights: list[float]) -> float | torch.Tensor:
    """A loss term's weight for a bank: one float where every set has the same, else ``[S]``
    (each set's loss weighs its own)."""
    return weights[0] if len(set(weights)) == 1 else torch.tensor(weights, dtype=torch.float32)


def train_solvers(
    cfg: TrainConfig, d: Dist, ae: TiedAutoencoder, splits: Splits, total: float, fresh: bool,
    long: bool = False,
) -> tuple[SolverBank, StageState]:  # fmt: skip
    """The solver bank of ``solver.sets`` (stage ``solvers``), or with ``long`` the bank of
    ``solver.long_sets`` trained apart for ``solver.long_epochs`` (stage ``solvers_long``:
    its own initialisation and partners; the same batch order)."""
    sc, aug = cfg.solver, cfg.augment
    sets, epochs = (sc.long_sets, sc.long_epochs) if long else (sc.sets, sc.epochs)
    stage = "solvers_long" if long else "solvers"
    stream = "solver-long-pairs" if long else "solver-pairs"
    mode = answer_mode(sc.delta, sc.anchor)
    max_gap = max(1, round(sc.max_gap_seconds * FPS))
    src = PairSource.of(splits.train, max_gap)
    val = PairSource.of(splits.val, max_gap)
    va, vp = val.fixed_pairs(cfg.seed + 1, cfg.max_eval_frames)
    v_start, v_goal = val.pairs(va, vp, np.random.default_rng(cfg.seed + 9), aug, total)
    torch.manual_seed(cfg.seed + (2 if long else 1))
    bank = SolverBank(ae.norm, sets, ae.latent_dim, sc.hidden, sc.residual)
    net: nn.Module = DistributedDataParallel(bank) if d.world > 1 else bank
    params = [p for n, p in bank.named_parameters() if not n.startswith("norm.")]
    optim = torch.optim.Adam(params, lr=sc.lr)
    steps = steps_per_epoch(len(src.poses), sc.batch_size, d)

    other_weight = per_set([sc.weight_of(s, long) for s in sets])
    stay_weight = per_set([sc.stay_of(s, long) for s in sets])
    frames = [sc.frame_of(s, long) for s in sets]
    stay_frame = frames[0] if len(set(frames)) == 1 else frames

    def losses(model: nn.Module, start: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """:func:`solver_losses` with this config's terms (training and validation alike)."""
        out, _ = solver_losses(
            ae, bank, model, start, goal, other_weight, sc.bone_weight, mode,
            stay_weight, sc.rigid_loss, sc.joint_loss == "distance",
            stay_frame, sc.carry if sc.carry_loss else 0.0,
            active(sc.keep_ends, sc.keep_elbows and sc.elbows_loss) if sc.ends_loss else None,
        )  # fmt: skip
        return out

    def train_epoch(epoch: int, bar: Bar) -> float:
        rng = stage_rng(cfg.seed, stream, epoch)
        partner_idx = sample_partners(src.lo, src.hi, np.arange(len(src.poses)), rng)
        same = rng.random(len(partner_idx)) < sc.identity_fraction
        partner_idx[same] = np.flatnonzero(same)  # "already there": learn to stay put
        partners = torch.from_numpy(partner_idx)
        total_loss, count = torch.zeros((), dtype=torch.float64), 0
        for idx in batches(len(src.poses), sc.batch_size, d, cfg.seed + 1, epoch):
            start, goal = src.pairs(idx, partners[idx], rng, aug, total)
            loss = losses(net, start, goal).sum()
            optim.zero_grad(set_to_none=True)
            loss.backward()
            optim.step()
            total_loss += loss.detach().double() / len(bank.sets)
            count += 1
            bar.update()
        return mean_loss(total_loss, count, d)

    def validate() -> dict[str, float]:
        val_losses = losses(bank, v_start, v_goal)
        metrics = solver_metrics(ae, bank, v_start, v_goal, mode)
        return {
            "val_loss": float(val_losses.mean()),
            "val_reach_cm": float(np.mean([m["reach_cm"] for m in metrics.values()])),
            "val_served_reach_cm": float(np.mean([m["served_reach_cm"] for m in metrics.values()])),
            "val_mpjpe_cm": float(np.mean([m["mpjpe_cm"] for m in metrics.values()])),
            "val_bone_cm": float(np.mean([m["bone_cm"] for m in metrics.values()])),
        }

    state = run_stage(
        name=stage,
        cfg=cfg,
        d=d,
        model=net,
        trainable=bank,
        optim=optim,
        epochs=epochs,
        steps=steps,
        train_epoch=train_epoch,
        validate=validate,
        fresh=fresh,
    )
    bank.eval()
    return bank, state


def augment(
    poses: torch.Tensor,
    rng: np.random.Generator,
    mirror: bool,
    yaw: bool,
    aug: AugmentConfig | None = None,
) -> torch.Tensor:
    """Completion samples ``[B, 63]``: with ``aug``, a random body at a random size (key
    points tell the size: completion is never size-normalised); a random mirror; a random
    yaw about +Y through the pelvis floor point."""
    out = as_joints(poses)
    n = len(out)
    if aug is not None and aug.enabled:
        scale, shift = random_bodies(n, rng, aug, placement=False)  # augment.joint_shift: not here
        out = rebuild(out, scale, shift)
        size = np.where(rng.random(n) < 0.5, 1.0, rng.uniform(0.6, 1.2, n))
        out = out * torch.from_numpy(size).float()[:, None, None]
    if mirror:
        flip = torch.from_numpy(rng.random(n) < 0.5)[:, None, None]
        out = torch.where(flip, mirror_poses(out), out)
    if yaw:
        out = turn(out, torch.from_numpy(rng.uniform(0.0, 2.0 * math.pi, n)).float())
    return out.reshape(n, -1)


def completion_inputs(
    nets: list[CompletionNet], level: int, poses: torch.Tensor, keep: torch.Tensor | None
) -> torch.Tensor:
    """Inputs of completion level ``level`` (1-based) for true poses ``[B, 63]``.

    ``keep [B, 21]`` says which joints are given; the others are filled with the previous
    level's prediction, chaining from level 1 exactly as the service does.
    """
    pred: torch.Tensor | None = None
    for lv in range(1, level + 1):
        joints = nets[lv - 1].joints
        cols = target_columns(joints)
        given = poses[:, cols]
        if pred is not None and keep is not None:
            mask = keep[:, [JOINT_INDEX[j] for j in joints]].repeat_interleave(3, dim=1)
            given = torch.where(mask, given, pred[:, cols])
        if lv == level:
            return given
        with torch.no_grad():
            pred = nets[lv - 1](given)
    raise AssertionError("unreachable")


def completion_loss(pred: torch.Tensor, poses: torch.Tensor, kind: str) -> torch.Tensor:
    """The completion training loss of ``pred`` against ``poses`` (both ``[B, 63]``, m):
    MSE, or the mean per-joint distance (``mpjpe``)."""
    if kind == "mse":
        return nn.functional.mse_loss(pred, poses)
    return mpjpe_loss(pred, poses)


def train_completion(
    cfg: TrainConfig, d: Dist, splits: Splits, fresh: bool
) -> tuple[list[CompletionNet], list[StageState]]:
    cc = cfg.completion
    train = flat(splits.train.positions)
    val = flat(splits.val.positions)
    if len(val) > cfg.max_eval_frames:
        sel = np.random.default_rng(cfg.seed + 2).choice(
            len(val), cfg.max_eval_frames, replace=False
        )
        val = val[torch.from_numpy(np.sort(sel))]
    val_aug = augment(val, np.random.default_rng(cfg.seed + 3), cc.mirror, cc.yaw, cfg.augment)
    nets: list[CompletionNet] = []
    states: list[StageState] = []
    base = {JOINT_INDEX[j] for j in cc.schemes[0]}
    for level in range(1, len(cc.schemes) + 1):
        joints = cc.level_joints(level)
        torch.manual_seed(cfg.seed + 10 + level)
        model = CompletionNet(joints, cc.hidden, cc.activation)
        nets.append(model)
        net: nn.Module = DistributedDataParallel(model) if d.world > 1 else model
        optim = torch.optim.Adam(model.parameters(), lr=cc.lr, weight_decay=cc.weight_decay)
        steps = steps_per_epoch(len(train), cc.batch_size, d)
        name = f"completion{level}"

        def keep_mask(n: int, rng: np.random.Generator) -> torch.Tensor:
            keep = torch.from_numpy(rng.random((n, NUM_JOINTS)) >= cc.fill_probability)
            keep[:, sorted(base)] = True
            return keep

        def train_epoch(
            epoch: int,
            bar: Bar,
            level: int = level,
            net: nn.Module = net,
            optim: torch.optim.Optimizer = optim,
            steps: int = steps,
        ) -> float:
            rng = stage_rng(cfg.seed, f"completion{level}", epoch)
            total, count = torch.zeros((), dtype=torch.float64), 0
            for step, idx in enumerate(
                batches(len(train), cc.batch_size, d, cfg.seed + 10 + level, epoch)
            ):
                schedule_lr(optim, cc.lr, cc.lr_schedule, epoch, step, steps, cc.epochs)
                poses = augment(train[idx], rng, cc.mirror, cc.yaw, cfg.augment)
                keep = keep_mask(len(poses), rng) if level > 1 else None
                x = completion_inputs(nets, level, poses, keep)
                loss = completion_loss(net(x), poses, cc.loss)
                optim.zero_grad(set_to_none=True)
                loss.backward()
                optim.step()
                total += loss.detach().double()
                count += 1
                bar.update()
            return mean_loss(total, count, d)

        def validate(level: int = level, model: CompletionNet = model) -> dict[str, float]:
            pred = model(completion_inputs(nets, level, val_aug, None))
            return {
                "val_loss": float(nn.functional.mse_loss(pred, val_aug)),
                "val_mpjpe_cm": mpjpe_cm(pred, val_aug),
            }

        states.append(
            run_stage(
                name=name,
                cfg=cfg,
                d=d,
                model=net,
                trainable=model,
                optim=optim,
                epochs=cc.epochs,
                steps=steps,
                train_epoch=train_epoch,
                validate=validate,
                fresh=fresh,
            )
        )
        freeze(model)
    return nets, states


@dataclass
class Trained:
    ae: TiedAutoencoder
    bank: SolverBank
    completion: list[CompletionNet]
    states: dict[str, StageState]
    splits: Splits


def train_all(cfg: TrainConfig, *, fresh: bool = False) -> Trained:
    d = init_distributed()
    torch.set_num_threads(cfg.threads)
    torch.use_deterministic_algorithms(True)
    seed_all(cfg.seed)
    splits = load_splits(cfg)  # (before the run folder: a dataset refused leaves none)
    Path(cfg.run_dir).mkdir(parents=True, exist_ok=True)
    if d.main:
        for warning in splits.train.meta.get("warnings", []):  # the build's, again
            console.print(f"[yellow]warning: dataset: {escape(warning)}")
        if unused := cfg.solver.unused_weights():  # a set's weight naming no set trained
            keys = ", ".join(f"solver.{key}" for key in unused)  # (one line each: a studio
            console.print(  # that reduced the sets read five of keys it never wrote, D12)
                f"[yellow]warning: {escape(keys)}: no set of solver.sets, ignored (inherited "
                "by a config that changes the sets, or a typo)"
            )
        console.print(
            f"train {len(splits.train.positions)} frames, val {len(splits.val.positions)}, "
            f"test {len(splits.test.positions)}; world size {d.world}"
        )
    train = flat(splits.train.positions)
    val = flat(splits.val.positions)
    if len(val) > cfg.max_eval_frames:
        sel = np.random.default_rng(cfg.seed).choice(len(val), cfg.max_eval_frames, replace=False)
        val = val[torch.from_numpy(np.sort(sel))]
    total = float(reference_lengths(splits.train).sum())
    ae, ae_state = train_autoencoder(cfg, d, train, val, total, fresh)
    bank, solver_state = train_solvers(cfg, d, ae, splits, total, fresh)
    states = {"autoencoder": ae_state, "solvers": solver_state}
    if cfg.solver.long_sets:
        long_bank, states["solvers_long"] = train_solvers(
            cfg, d, ae, splits, total, fresh, long=True
        )
        bank = merge_banks(bank, long_bank)
    completion, completion_states = train_completion(cfg, d, splits, fresh)
    if d.world > 1:  # every rank reports what it ended with (ranks must agree)
        digest = hashlib.sha256()
        for module in (ae, bank, *completion):
            for tensor in module.state_dict().values():
                digest.update(tensor.detach().contiguous().numpy().tobytes())
        print(f"weights digest rank {d.rank}: {digest.hexdigest()}", flush=True)
        d.barrier()
        d.close()
    states.update({f"completion{i + 1}": s for i, s in enumerate(completion_states)})
    return Trained(ae=ae, bank=bank, completion=completion, states=states, splits=splits)
