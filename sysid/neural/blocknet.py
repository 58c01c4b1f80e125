"""Block-oriented network G1 → F → G2 (+ a parallel linear path), the model only (no training loop).

The model (Forgione & Piga, "dynoNet", Int. J. Adaptive Control and Signal Processing 2021, the Wiener–Hammerstein
structure of their eq. 22):

    z(t) = G1(q) u(t)              linear dynamical layer, n_in → ``channels`` (one B/A per input–channel pair)
    w(t) = F(z(t))                 static network per time step: ``channels`` → hidden tanh layers → ``channels_out``
    ŷ(t) = G2(q) w(t) [+ G0(q) u(t)]  second linear dynamical layer (and optionally a linear path G0 from the input)

with G1, G2, G0 :class:`sysid.neural.iir.LinearDynamic` layers run from rest. ŷ is an output-error (free-run)
prediction: it never reads the measured output, so the one-step, k-step and free-run predictions coincide.

Training (the simulation MSE of whole records from rest, or of sections of them, with early stopping on a held-out
tail) is :func:`sysid.neural.training.train_records`, the fitting loop shared with the other sequence models.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from sysid.neural.iir import LinearDynamic

__all__ = ["BlockNet"]

_ACT = {"tanh": torch.tanh, "relu": torch.relu, "sigmoid": torch.sigmoid}


class BlockNet(torch.nn.Module):
    """G1 → F → G2 (+ G0) on ``u`` (B, T, n_in) → ``ŷ`` (B, T, n_out), float64."""

    def __init__(
        self,
        n_in: int,
        n_out: int,
        channels: int,
        channels_out: int,
        hidden: Sequence[int],
        nb: int,
        na: int,
        nb2: int,
        na2: int,
        nk: int = 0,
        linear: bool = False,
        activation: str = "tanh",
        generator: torch.Generator | None = None,
    ):
        super().__init__()
        gen = generator or torch.Generator().manual_seed(0)
        self.activation = activation
        self.g1 = LinearDynamic(n_in, channels, nb, na, nk, gen)
        sizes = [int(channels), *[int(h) for h in hidden], int(channels_out)]
        layers = []
        for a, b in zip(sizes[:-1], sizes[1:]):
            lin = torch.nn.Linear(a, b, dtype=torch.float64)
            lim = math.sqrt(6.0 / (a + b))  # Glorot-uniform weights, zero biases
            with torch.no_grad():
                lin.weight.copy_((torch.rand(b, a, generator=gen, dtype=torch.float64) * 2 - 1) * lim)
                lin.bias.zero_()
            layers.append(lin)
        self.f = torch.nn.ModuleList(layers)
        self.g2 = LinearDynamic(channels_out, n_out, nb2, na2, 0, gen)
        self.g0 = LinearDynamic(n_in, n_out, nb, na, nk, gen) if linear else None

    def static(self, z: torch.Tensor) -> torch.Tensor:
        """F applied at every time step (the last axis holds the channels)."""
        act = _ACT[self.activation]
        last = len(self.f) - 1
        for i, lin in enumerate(self.f):
            z = lin(z)
            if i < last:
                z = act(z)
        return z

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        y = self.g2(self.static(self.g1(u)))
        return y if self.g0 is None else y + self.g0(u)
