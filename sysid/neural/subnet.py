"""Encoder state-space network (SUBNET), the model only: f, h and the initial-state encoder ψ.

Written from Beintema, Tóth & Schoukens, "Nonlinear state-space identification using deep encoder networks"
(L4DC 2021) and "Deep subspace encoders for nonlinear system identification" (Automatica 2023), eq. (2)–(9)
there, in normalised units (zero-mean, unit-variance u and y)::

    x(k+1) = f(x(k), u(k))                                       state transition
    y(k)   = h(x(k))            [h(x(k), u(k)) with feedthrough]  output
    x(k)   = ψ(y(k-1) … y(k-n_a), u(k-1) … u(k-n_b))              encoder: initial state from the past

Each of f, h, ψ is a linear map plus a dense network (the paper's "linear bypass"; one hidden layer of 64 tanh
units by default): ``g(z) = W z + b + V σ(U z + c)`` (:class:`BypassMLP`). Hidden widths ``()`` leave the linear
map alone, so with all three empty the model is a linear state-space model with a linear state observer.

Training (the truncated T-step simulation loss over sections of the data) is in
:mod:`sysid.neural.training` (the loop shared with ``rnn`` and ``wh-net``); the identifier (normalisation,
fit/predict/save) in :mod:`sysid.neural.ss_encoder`. Prediction runs in float64 numpy from the exported weights
(:func:`export_weights`, :func:`simulate_np`), so it is the same on every machine.

Tensors: ``ypast`` (B, lag, ny) and ``upast`` (B, lag, nu) hold the ``lag = max(n_a, n_b)`` samples before
the first simulated step in time order (oldest first); ``useq`` (B, T, nu) the inputs u(k) … u(k+T-1);
the output (B, T, ny) is ŷ(k) … ŷ(k+T-1).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np
import torch

__all__ = ["BypassMLP", "SubnetModel", "export_weights", "simulate_np", "encode_np", "bypass_np"]

_ACT = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "sigmoid": torch.nn.Sigmoid}


class BypassMLP(torch.nn.Module):
    """``g(z) = W z + b + MLP(z)``: a linear map plus a dense network of hidden widths ``hidden`` (linear
    output layer). ``hidden = ()``: the linear map only. Weights: PyTorch's default uniform initialisation,
    drawn from the global generator (seeded by the caller)."""

    def __init__(self, n_in: int, n_out: int, hidden: Sequence[int], activation: str = "tanh"):
        super().__init__()
        self.linear = torch.nn.Linear(n_in, n_out)
        layers: list[torch.nn.Module] = []
        a = n_in
        for w in hidden:
            layers += [torch.nn.Linear(a, int(w)), _ACT[activation]()]
            a = int(w)
        self.net = torch.nn.Sequential(*layers, torch.nn.Linear(a, n_out)) if layers else None

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        out = self.linear(z)
        return out if self.net is None else out + self.net(z)


class SubnetModel(torch.nn.Module):
    """f, h and the encoder ψ of the SUBNET state-space model (see the module docstring).

    Parameters
    ----------
    nx, nu, ny : state, input and output dimensions.
    na, nb : past outputs / inputs the encoder reads (its window is ``lag = max(na, nb)`` samples).
    f_hidden, h_hidden, e_hidden : hidden widths of f, h and ψ (``()``: linear).
    activation : ``tanh`` (paper), ``relu`` or ``sigmoid``.
    feedthrough : h also reads u(k) (a direct term D u(k)); the paper's default is without.
    """

    def __init__(
        self,
        nx: int,
        nu: int,
        ny: int,
        na: int,
        nb: int,
        f_hidden: Sequence[int] = (64,),
        h_hidden: Sequence[int] = (64,),
        e_hidden: Sequence[int] = (64,),
        activation: str = "tanh",
        feedthrough: bool = False,
    ):
        super().__init__()
        self.nx, self.nu, self.ny, self.na, self.nb = int(nx), int(nu), int(ny), int(na), int(nb)
        self.feedthrough = bool(feedthrough)
        self.lag = max(self.na, self.nb)
        self.f = BypassMLP(self.nx + self.nu, self.nx, f_hidden, activation)
        self.h = BypassMLP(self.nx + (self.nu if self.feedthrough else 0), self.ny, h_hidden, activation)
        self.encoder = BypassMLP(self.na * self.ny + self.nb * self.nu, self.nx, e_hidden, activation)

    def encode(self, ypast: torch.Tensor, upast: torch.Tensor) -> torch.Tensor:
        """x(k) from y(k-1) … y(k-na), u(k-1) … u(k-nb): the last na / nb rows of the windows, newest first."""
        B = ypast.shape[0]
        yp = ypast[:, ypast.shape[1] - self.na :].flip(1).reshape(B, -1)
        up = upast[:, upast.shape[1] - self.nb :].flip(1).reshape(B, -1)
        return self.encoder(torch.cat([yp, up], dim=1))

    def states(self, x: torch.Tensor, useq: torch.Tensor) -> torch.Tensor:
        """x(k) … x(k+T-1) (B, T, nx) from x(k) and u(k) … u(k+T-1): the recursion x ← f(x, u).

        With one hidden layer in f (the paper's default) the input's share of f's first layer and of its linear
        map is computed for all T steps at once before the loop, so each step is three matrix products and one
        activation (the arithmetic of :class:`BypassMLP`, reordered)."""
        f, nx, T = self.f, self.nx, useq.shape[1]
        out = []
        if f.net is not None and len(f.net) == 3:
            first, act, last = cast(torch.nn.Linear, f.net[0]), f.net[1], cast(torch.nn.Linear, f.net[2])
            # input shares for all steps at once; unbind (not indexing) keeps the backward pass O(T)
            lin_u = (torch.matmul(useq, f.linear.weight[:, nx:].t()) + (f.linear.bias + last.bias)).unbind(1)
            hid_u = (torch.matmul(useq, first.weight[:, nx:].t()) + first.bias).unbind(1)
            Lx, Ux, V = f.linear.weight[:, :nx].t(), first.weight[:, :nx].t(), last.weight.t()
            for j in range(T):
                out.append(x)
                x = torch.addmm(torch.addmm(lin_u[j], x, Lx), act(torch.addmm(hid_u[j], x, Ux)), V)
        else:
            for j in range(T):
                out.append(x)
                x = f(torch.cat([x, useq[:, j]], dim=1))
        return torch.stack(out, dim=1)

    def output(self, xs: torch.Tensor, useq: torch.Tensor) -> torch.Tensor:
        """ŷ = h(x) (or h(x, u) with feedthrough) for states ``xs`` (B, T, nx) — no recursion, one batch."""
        return self.h(torch.cat([xs, useq], dim=2) if self.feedthrough else xs)

    def simulate(self, x: torch.Tensor, useq: torch.Tensor) -> torch.Tensor:
        """Free-run ŷ(k) … ŷ(k+T-1) from the state x(k) and the inputs u(k) … u(k+T-1)."""
        return self.output(self.states(x, useq), useq)

    def forward(self, ypast: torch.Tensor, upast: torch.Tensor, useq: torch.Tensor) -> torch.Tensor:
        return self.simulate(self.encode(ypast, upast), useq)


# ---------------------------------------------------------------------------------------------- float64 numpy
def _bypass_weights(g: BypassMLP) -> dict[str, np.ndarray | list]:
    to = lambda t: t.detach().to("cpu", torch.float64).numpy().copy()  # noqa: E731
    layers = [m for m in (g.net or []) if isinstance(m, torch.nn.Linear)]
    return {"W": to(g.linear.weight), "b": to(g.linear.bias), "layers": [(to(m.weight), to(m.bias)) for m in layers]}


def export_weights(model: SubnetModel) -> dict[str, dict]:
    """float64 copies of f, h, ψ for :func:`simulate_np` / :func:`encode_np`."""
    return {k: _bypass_weights(getattr(model, k)) for k in ("f", "h", "encoder")}


def bypass_np(g: dict, z: np.ndarray, act=np.tanh) -> np.ndarray:
    """``W z + b + MLP(z)`` for rows ``z`` (B, n_in) in float64."""
    out = z @ g["W"].T + g["b"]
    a = z
    layers = g["layers"]
    for i, (W, b) in enumerate(layers):
        a = a @ W.T + b
        if i < len(layers) - 1:
            a = act(a)
    return out + a if layers else out


def encode_np(w: dict, ypast: np.ndarray, upast: np.ndarray, na: int, nb: int, act=np.tanh) -> np.ndarray:
    """x(k) for windows ``ypast`` (B, lag, ny), ``upast`` (B, lag, nu) (oldest first), as :meth:`SubnetModel.encode`."""
    B = ypast.shape[0]
    yp = ypast[:, ypast.shape[1] - na :][:, ::-1].reshape(B, -1)
    up = upast[:, upast.shape[1] - nb :][:, ::-1].reshape(B, -1)
    return bypass_np(w["encoder"], np.concatenate([yp, up], axis=1), act)


def simulate_np(
    w: dict, x: np.ndarray, useq: np.ndarray, feedthrough: bool = False, bound: float = np.inf, act=np.tanh
) -> tuple[np.ndarray, int]:
    """Free run in float64 from states ``x`` (B, nx) over ``useq`` (B, T, nu) → (ŷ (B, T, ny), first step at
    which some |ŷ| exceeds ``bound`` or is non-finite, or -1). Steps from a divergence on are nan."""
    B, T, _ = useq.shape
    ny = w["h"]["W"].shape[0]
    out = np.full((B, T, ny), np.nan)
    diverged = -1
    with np.errstate(over="ignore", invalid="ignore"):
        for j in range(T):
            xu = np.concatenate([x, useq[:, j]], axis=1)
            yj = bypass_np(w["h"], xu if feedthrough else x, act)
            if not (np.isfinite(yj).all() and (np.abs(yj) <= bound).all()):
                diverged = j
                break
            out[:, j] = yj
            x = bypass_np(w["f"], xu, act)
    return out, diverged
