"""The networks: tied-weight autoencoder, target solvers (trained as one stacked bank) and
key-point completion MLPs. Normalisation lives inside the modules as constant buffers,
so the exported graphs take and return canonical positions in metres."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable

import torch
from torch import nn

from core.skeleton import JOINT_INDEX, flat_columns

POSE_DIM = 63


class Normaliser(nn.Module):
    """Fixed per-feature affine map; buffers are set once and never updated."""

    mean: torch.Tensor
    std: torch.Tensor

    def __init__(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        super().__init__()
        self.register_buffer("mean", mean.detach().clone().float())
        self.register_buffer("std", std.detach().clone().float())

    def normalise(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean) / self.std

    def denormalise(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.std + self.mean


def feature_stats(poses: torch.Tensor, std_floor: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean and floored std of flattened ``[N, 63]`` poses (a pure function)."""
    flat = poses.reshape(poses.shape[0], -1).double()
    mean = flat.mean(dim=0)
    std = flat.std(dim=0).clamp_min(std_floor)
    return mean.float(), std.float()


def relu_stack(
    h: torch.Tensor, layers: Iterable[tuple[torch.Tensor, torch.Tensor | None]]
) -> torch.Tensor:
    """Linear layers ``(weight [out, in], bias)`` in turn, ReLU between them (not after
    the last)."""
    layers = list(layers)
    for i, (w, b) in enumerate(layers):
        h = nn.functional.linear(h, w, b)
        if i < len(layers) - 1:
            h = torch.relu(h)
    return h


class TiedAutoencoder(nn.Module):
    """63 -> 200 -> 200 -> 64 (ReLU, linear latent); the decoder reuses the encoder's
    weight matrices transposed in reverse order, with biases of its own."""

    def __init__(self, norm: Normaliser, hidden: list[int], latent: int) -> None:
        super().__init__()
        self.norm = norm
        sizes = [POSE_DIM, *hidden, latent]
        self.weights = nn.ParameterList()
        self.enc_bias = nn.ParameterList()
        self.dec_bias = nn.ParameterList()
        for fan_in, fan_out in itertools.pairwise(sizes):
            w = torch.empty(fan_out, fan_in)
            nn.init.kaiming_uniform_(w, a=math.sqrt(5))
            self.weights.append(nn.Parameter(w))
            bound = 1.0 / math.sqrt(fan_in)
            self.enc_bias.append(nn.Parameter(torch.empty(fan_out).uniform_(-bound, bound)))
            self.dec_bias.append(nn.Parameter(torch.zeros(fan_in)))
        self.latent_dim = latent

    def encode(self, pose: torch.Tensor) -> torch.Tensor:
        return relu_stack(self.norm.normalise(pose), zip(self.weights, self.enc_bias, strict=True))

    def decode(self, latent: torch.Tensor) -> torch.Tensor:
        h = latent
        for i in reversed(range(len(self.weights))):
            h = nn.functional.linear(h, self.weights[i].t(), self.dec_bias[i])
            if i > 0:
                h = torch.relu(h)
        return self.norm.denormalise(h)

    def forward(
        self, pose: torch.Tensor, noise: float = 0.0, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """The round trip of ``pose``; with ``noise`` > 0, ``[clean; shaken]`` round trips
        (the second half decoded from latents plus Gaussian noise, drawn from ``generator``,
        of ``noise`` times each latent dimension's batch std:
        trainer.config.AutoencoderConfig.latent_noise)."""
        z = self.encode(pose)
        if noise > 0:
            draw = torch.randn(z.shape, generator=generator, dtype=z.dtype, device=z.device)
            z = torch.cat([z, z + draw * (noise * z.detach().std(dim=0, keepdim=True))])
        return self.decode(z)


def target_columns(joints: list[str]) -> list[int]:
    """Columns of the flattened pose holding the given joints (x, y, z each)."""
    return [int(c) for c in flat_columns([JOINT_INDEX[j] for j in joints])]


class SolverBank(nn.Module):
    """S solvers with identical layer sizes, evaluated together with batched matmuls.

    Solver s maps (latent z, normalised targets of its joint set) to a new latent. Sets
    smaller than the largest are zero-padded; the padded input columns get zero
    gradients and are sliced away at export.
    """

    def __init__(
        self,
        norm: Normaliser,
        sets: list[list[str]],
        latent: int,
        hidden: list[int],
        residual: bool,
    ) -> None:
        super().__init__()
        self.norm = norm
        self.sets = [list(s) for s in sets]
        self.residual = residual
        self.max_targets = max(len(s) for s in sets)
        n = len(sets)
        sizes = [latent + 3 * self.max_targets, *hidden, latent]
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for fan_in, fan_out in itertools.pairwise(sizes):
            bound = 1.0 / math.sqrt(fan_in)
            self.weights.append(
                nn.Parameter(torch.empty(n, fan_in, fan_out).uniform_(-bound, bound))
            )
            self.biases.append(nn.Parameter(torch.empty(n, 1, fan_out).uniform_(-bound, bound)))
        # zero the weights of padded target columns so padding is inert from the start
        with torch.no_grad():
            for s, joints in enumerate(self.sets):
                self.weights[0][s, latent + 3 * len(joints) :, :] = 0.0
        cols = torch.zeros(n, 3 * self.max_targets, dtype=torch.long)
        mask = torch.zeros(n, 3 * self.max_targets)
        for s, joints in enumerate(self.sets):
            c = target_columns(joints)
            cols[s, : len(c)] = torch.tensor(c)
            mask[s, : len(c)] = 1.0
        self.cols: torch.Tensor
        self.mask: torch.Tensor
        self.register_buffer("cols", cols)
        self.register_buffer("mask", mask)
        self.latent_dim = latent

    def forward(self, latent: torch.Tensor, target_pose: torch.Tensor) -> torch.Tensor:
        """``latent [S, B, D]``, ``target_pose [S, B, 63]`` (metres) -> ``[S, B, D]``.

        Each solver reads only its own joints' columns of the target pose.
        """
        normed = self.norm.normalise(target_pose)
        targets = torch.gather(normed, 2, self.cols[:, None, :].expand(-1, normed.shape[1], -1))
        h = torch.cat([latent, targets * self.mask[:, None, :]], dim=-1)
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = torch.baddbmm(b, h, w)
            if i < last:
                h = torch.relu(h)
        return latent + h if self.residual else h


def merge_banks(*banks: SolverBank) -> SolverBank:
    """One bank holding every solver of ``banks`` (same normaliser, latent and layer
    sizes), each answering exactly as in its own bank: the first layer's target rows are
    zero-padded to the widest set, like any set smaller than the largest."""
    first = banks[0]
    hidden = [w.shape[2] for w in first.weights[:-1]]
    for b in banks[1:]:
        if (b.norm is not first.norm or b.latent_dim != first.latent_dim
                or b.residual != first.residual or len(b.weights) != len(first.weights)
                or [w.shape[2] for w in b.weights[:-1]] != hidden):  # fmt: skip
            raise ValueError("merge_banks: the banks differ in normaliser, latent or layers")
    sets = [joints for b in banks for joints in b.sets]
    out = SolverBank(first.norm, sets, first.latent_dim, hidden, first.residual)
    with torch.no_grad():
        for i in range(len(out.weights)):
            out.weights[i].zero_()
            row = 0
            for b in banks:
                w = b.weights[i]
                out.weights[i][row : row + len(w), : w.shape[1]] = w
                out.biases[i][row : row + len(w)] = b.biases[i]
                row += len(w)
    return out.train(first.training)


class SingleSolver(nn.Module):
    """One solver sliced out of a bank, with the export signature
    ``(latent [N, D], targets [N, 3k] in metres) -> latent [N, D]``."""

    def __init__(self, bank: SolverBank, index: int) -> None:
        super().__init__()
        joints = bank.sets[index]
        cols = target_columns(joints)
        self.mean: torch.Tensor
        self.std: torch.Tensor
        self.register_buffer("mean", bank.norm.mean[cols].clone())
        self.register_buffer("std", bank.norm.std[cols].clone())
        self.residual = bank.residual
        d = bank.latent_dim
        self.layers = nn.ModuleList()
        for i, (w, b) in enumerate(zip(bank.weights, bank.biases, strict=True)):
            weight = w[index].detach().clone()
            if i == 0:
                weight = weight[: d + len(cols)]
            layer = nn.Linear(weight.shape[0], weight.shape[1])
            with torch.no_grad():
                layer.weight.copy_(weight.t())
                layer.bias.copy_(b[index, 0].detach())
            self.layers.append(layer)

    def forward(self, latent: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        h = torch.cat([latent, (targets - self.mean) / self.std], dim=-1)
        last = len(self.layers) - 1
        for i, layer in enumerate(self.layers):
            h = layer(h)
            if i < last:
                h = torch.relu(h)
        return latent + h if self.residual else h


class CompletionNet(nn.Module):
    """Key points (pelvis-centred, any yaw, metres) -> whole pose ``[N, 63]`` (metres)."""

    def __init__(self, joints: list[str], hidden: list[int], activation: str) -> None:
        super().__init__()
        self.joints = list(joints)
        act: type[nn.Module] = nn.SELU if activation == "selu" else nn.ReLU
        layers: list[nn.Module] = []
        sizes = [3 * len(joints), *hidden]
        for fan_in, fan_out in itertools.pairwise(sizes):
            linear = nn.Linear(fan_in, fan_out)
            if activation == "selu":  # LeCun normal init, as SELU expects
                nn.init.normal_(linear.weight, std=1.0 / math.sqrt(fan_in))
                nn.init.zeros_(linear.bias)
            layers += [linear, act()]
        layers.append(nn.Linear(sizes[-1], POSE_DIM))
        self.net = nn.Sequential(*layers)

    def forward(self, keypoints: torch.Tensor) -> torch.Tensor:
        out: torch.Tensor = self.net(keypoints)
        return out
