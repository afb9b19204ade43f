"""One solver's whole edit as one graph, in two forms.

:class:`FusedGraph` says what a fused edit computes, in the trainer's own modules;
:class:`LeanFusedGraph` computes the same with fewer, larger operations, and is what
``export`` writes (``fused_<key>.onnx``). The service runs one fused graph per pass of a
single-solver edit, so its node count is most of a solve's time: onnxruntime spends ~1 us
per node on a batch of one, while the arithmetic of the whole graph is a few us.

The lean form
- folds the input normalisation into the first layers' weights (the encoder's and the
  solver's target columns) and the output denormalisation into the decoder's last layer;
- runs the solver and the decoder ONCE on a doubled batch, ``[targets; start's own
  targets]`` (anchored) or ``[solved; start]`` latents (delta), where the reference runs
  each twice, then subtracts the two halves.
Its answers equal the reference's to float32 rounding (export checks 1e-5 per network).
"""

from __future__ import annotations

from typing import cast

import torch
from torch import nn

from trainer.models import SingleSolver, TiedAutoencoder, relu_stack, target_columns


class FusedGraph(nn.Module):
    """One solver's whole edit, ``pose, targets -> solved_pose``, answered as the service
    serves it (``trainer.train.solved_poses``): plain D(S(z, t)), delta
    ``pose + D(S(z, t)) - D(z)`` or anchored ``pose + D(S(z, t)) - D(S(z, x_t))``."""

    def __init__(
        self, ae: TiedAutoencoder, solver: SingleSolver, joints: list[str], mode: str
    ) -> None:
        super().__init__()
        self.ae, self.solver, self.mode = ae, solver, mode
        self.cols: torch.Tensor
        self.register_buffer("cols", torch.tensor(target_columns(joints)))

    def forward(self, pose: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        z = self.ae.encode(pose)
        out = self.ae.decode(self.solver(z, targets))
        if self.mode == "delta":
            out = pose + (out - self.ae.decode(z))
        elif self.mode == "anchored":
            stay = self.ae.decode(self.solver(z, pose.index_select(1, self.cols)))
            out = pose + (out - stay)
        return out


def _linear(weight: torch.Tensor, bias: torch.Tensor | None) -> nn.Linear:
    """A float32 layer from float64 ``weight [out, in]`` and ``bias [out]``."""
    layer = nn.Linear(weight.shape[1], weight.shape[0], bias=bias is not None)
    with torch.no_grad():
        layer.weight.copy_(weight.float())
        if bias is not None:
            layer.bias.copy_(bias.float())
    return layer


class LeanFusedGraph(nn.Module):
    """:class:`FusedGraph`'s answer in fewer operations (see the module's note). The
    autoencoder's inner layers keep their tied weights (one copy in the file; onnxruntime
    folds the transposes when it loads the graph); only the outer layers, which carry the
    folded normalisation, have a copy of their own."""

    def __init__(
        self, ae: TiedAutoencoder, solver: SingleSolver, joints: list[str], mode: str
    ) -> None:
        super().__init__()
        self.mode, self.residual = mode, solver.residual
        with torch.no_grad():
            mean, std = ae.norm.mean.double(), ae.norm.std.double()
            w = [p.detach().double() for p in ae.weights]
            enc_b = [p.detach().double() for p in ae.enc_bias]
            dec_b = [p.detach().double() for p in ae.dec_bias]
            # (x - mean) / std folded into the encoder's first layer, * std (+ mean) into
            # the decoder's last
            self.enc_first = _linear(w[0] / std[None, :], enc_b[0] - w[0] @ (mean / std))
            self.dec_last = _linear(w[0].t() * std[:, None], dec_b[0] * std)
            # solver: latent part and (targets - mean) / std part of its first layer
            first = cast(nn.Linear, solver.layers[0])
            fw, fb = first.weight.detach().double(), first.bias.detach().double()
            d = ae.latent_dim
            t_mean, t_std = solver.mean.double(), solver.std.double()
            self.from_latent = _linear(fw[:, :d], fb - fw[:, d:] @ (t_mean / t_std))
            self.from_targets = _linear(fw[:, d:] / t_std[None, :], None)
            rest = [
                _linear(layer.weight.detach().double(), layer.bias.detach().double())
                for layer in (cast(nn.Linear, m) for m in solver.layers[1:])
            ]
        self.rest = nn.ModuleList(rest)
        self.tied = nn.ParameterList([nn.Parameter(p.detach().clone()) for p in ae.weights[1:]])
        self.enc_bias = nn.ParameterList(
            [nn.Parameter(p.detach().clone()) for p in ae.enc_bias[1:]]
        )
        self.dec_bias = nn.ParameterList(
            [nn.Parameter(p.detach().clone()) for p in ae.dec_bias[1:]]
        )
        self.mean: torch.Tensor
        self.cols: torch.Tensor
        self.register_buffer("mean", mean.float())
        self.register_buffer("cols", torch.tensor(target_columns(joints)))

    def _encode(self, pose: torch.Tensor) -> torch.Tensor:
        h = torch.relu(self.enc_first(pose))
        return relu_stack(h, zip(self.tied, self.enc_bias, strict=True))

    def _decode(self, latent: torch.Tensor) -> torch.Tensor:
        """Denormalised but for the mean (it cancels in a difference of two decodes)."""
        h = latent
        for i in reversed(range(len(self.tied))):
            h = torch.relu(nn.functional.linear(h, self.tied[i].t(), self.dec_bias[i]))
        out: torch.Tensor = self.dec_last(h)
        return out

    def _solve(self, z: torch.Tensor, targets: torch.Tensor, copies: int) -> torch.Tensor:
        """The solver on ``copies`` stacked target batches for one batch of latents."""
        h = self.from_latent(z)
        h = torch.cat([h] * copies, 0) if copies > 1 else h
        h = torch.relu(h + self.from_targets(targets))
        layers = (cast(nn.Linear, layer) for layer in self.rest)
        h = relu_stack(h, ((layer.weight, layer.bias) for layer in layers))
        z = torch.cat([z] * copies, 0) if copies > 1 else z
        return z + h if self.residual else h

    def forward(self, pose: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        z = self._encode(pose)
        n = pose.shape[0]
        if self.mode == "plain":
            return self._decode(self._solve(z, targets, 1)) + self.mean
        if self.mode == "anchored":
            both = torch.cat([targets, pose.index_select(1, self.cols)], 0)
            latents = self._solve(z, both, 2)
        else:  # delta: the solved latent and the start's own
            latents = torch.cat([self._solve(z, targets, 1), z], 0)
        y = self._decode(latents)
        return pose + (y[:n] - y[n:])
