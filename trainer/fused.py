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

import torch
from torch import nn

from trainer.models import SingleSolver, TiedAutoencoder, target_columns


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
    """:class:`FusedGraph`'s answer in fewer operations (see the module's note)."""

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
            # encoder: (x - mean) / std folded into its first layer
            enc = [_linear(w[0] / std[None, :], enc_b[0] - w[0] @ (mean / std))]
            enc += [_linear(w[i], enc_b[i]) for i in range(1, len(w))]
            # solver: latent part and (targets - mean) / std part of its first layer
            first = solver.layers[0]
            fw, fb = first.weight.detach().double(), first.bias.detach().double()
            d = ae.latent_dim
            t_mean, t_std = solver.mean.double(), solver.std.double()
            self.from_latent = _linear(fw[:, :d], fb - fw[:, d:] @ (t_mean / t_std))
            self.from_targets = _linear(fw[:, d:] / t_std[None, :], None)
            rest = [
                _linear(layer.weight.detach().double(), layer.bias.detach().double())
                for layer in solver.layers[1:]
            ]
            # decoder: tied weights transposed; * std (+ mean) folded into its last layer
            dec = [_linear(w[i].t(), dec_b[i]) for i in range(len(w) - 1, 0, -1)]
            dec.append(_linear(w[0].t() * std[:, None], dec_b[0] * std))
        self.encoder = nn.ModuleList(enc)
        self.rest = nn.ModuleList(rest)
        self.decoder = nn.ModuleList(dec)
        self.mean: torch.Tensor
        self.cols: torch.Tensor
        self.register_buffer("mean", mean.float())
        self.register_buffer("cols", torch.tensor(target_columns(joints)))

    @staticmethod
    def _mlp(layers: nn.ModuleList, h: torch.Tensor) -> torch.Tensor:
        last = len(layers) - 1
        for i, layer in enumerate(layers):
            h = layer(h)
            if i < last:
                h = torch.relu(h)
        return h

    def _solve(self, z: torch.Tensor, targets: torch.Tensor, copies: int) -> torch.Tensor:
        """The solver on ``copies`` stacked target batches for one batch of latents."""
        h = self.from_latent(z)
        h = torch.cat([h] * copies, 0) if copies > 1 else h
        h = torch.relu(h + self.from_targets(targets))
        step = self._mlp(self.rest, h)
        z = torch.cat([z] * copies, 0) if copies > 1 else z
        return z + step if self.residual else step

    def forward(self, pose: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
        z = self._mlp(self.encoder, pose)
        n = pose.shape[0]
        if self.mode == "plain":
            return self._mlp(self.decoder, self._solve(z, targets, 1)) + self.mean
        if self.mode == "anchored":
            both = torch.cat([targets, pose.index_select(1, self.cols)], 0)
            latents = self._solve(z, both, 2)
        else:  # delta: the solved latent and the start's own
            latents = torch.cat([self._solve(z, targets, 1), z], 0)
        y = self._mlp(self.decoder, latents)
        return pose + (y[:n] - y[n:])
