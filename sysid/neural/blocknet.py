"""Block-oriented network G1 → F → G2 (+ a parallel linear path) trained on the simulation error of whole records.

The model (Forgione & Piga, "dynoNet", Int. J. Adaptive Control and Signal Processing 2021, the Wiener–Hammerstein
structure of their eq. 22):

    z(t) = G1(q) u(t)              linear dynamical layer, n_in → ``channels`` (one B/A per input–channel pair)
    w(t) = F(z(t))                 static network per time step: ``channels`` → hidden tanh layers → ``channels_out``
    ŷ(t) = G2(q) w(t) [+ G0(q) u(t)]  second linear dynamical layer (and optionally a linear path G0 from the input)

with G1, G2, G0 :class:`sysid.neural.iir.LinearDynamic` layers run from rest. ŷ is an output-error (free-run)
prediction: it never reads the measured output, so the one-step, k-step and free-run predictions coincide.

Training (:func:`train_records`) minimises the simulation MSE of the whole estimation records in one pass per Adam
step (full batch: every step simulates each record from its first sample; the loss skips each record's first
``warmup`` samples, where the zero initial state is a transient). The last ``val_fraction`` of the last record is
held out: its samples are simulated in the same pass (continuing from the training part, so no new transient) but
left out of the loss, and the weights of the lowest hold-out RMSE are kept (early stopping). The learning rate
follows a cosine schedule from ``lr`` to ``lr_min`` over ``epochs`` (``torch.optim.lr_scheduler.CosineAnnealingLR``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from sysid.neural.iir import LinearDynamic
from sysid.neural.train_sim import SimTrainResult

__all__ = ["BlockNet", "BlockTrainResult", "train_records"]

MAX_RESTARTS = 20  # unstable steps undone (each halving the learning rate) before training gives up
_ACT = {"tanh": torch.tanh, "relu": torch.relu, "sigmoid": torch.sigmoid}


class BlockNet(torch.nn.Module):
    """G1 → F → G2 (+ G0) on ``u`` (B, T, n_in) → ``ŷ`` (B, T, n_out), float64."""

    def __init__(self, n_in: int, n_out: int, channels: int, channels_out: int, hidden: Sequence[int], nb: int, na: int,
                 nb2: int, na2: int, nk: int = 0, linear: bool = False, activation: str = "tanh",
                 generator: torch.Generator | None = None):
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


@dataclass
class BlockTrainResult(SimTrainResult):
    """What :func:`train_records` did, as :class:`~sysid.neural.train_sim.SimTrainResult` says, except that the
    hold-out RMSE of an epoch is that of its forward pass (the weights before that epoch's step); plus why the
    training stopped and how many unstable steps were undone."""

    stopped: str = "epochs"
    restarts: int = 0


def _masks(
    pairs: Sequence[tuple[np.ndarray, np.ndarray]], warmup: int, val_fraction: float
) -> list[tuple[slice, slice | None]]:
    """(training samples, hold-out samples) of each record: training skips the first ``warmup``; the hold-out is the
    last ``val_fraction`` of the last record."""
    out = []
    for k, (u, _) in enumerate(pairs):
        n = u.shape[0]
        cut = n - int(round(val_fraction * n)) if k == len(pairs) - 1 and val_fraction else n
        out.append((slice(min(warmup, cut), cut), slice(cut, n) if cut < n else None))
    return out


def _weights(model: torch.nn.Module) -> dict[str, torch.Tensor]:
    """A detached copy of the model's parameters (to step back to, or to keep as the best)."""
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def _full_pass(model: torch.nn.Module, us, ys, masks, n_train: int, n_val: int, backward: bool) -> tuple[float, float]:
    """Simulate every record from rest: (training MSE, hold-out sum of squares); gradients of the training MSE are
    accumulated when ``backward``."""
    sse, vse = 0.0, 0.0
    for u, y, (tr, va) in zip(us, ys, masks):
        with torch.set_grad_enabled(backward):
            yhat = model(u)[0]
            d = yhat[tr] - y[tr]
            part = (d * d).sum() / (n_train * y.shape[1])
        if backward:
            part.backward()
        sse += float(part.item())
        if va is not None:
            dv = (yhat[va] - y[va]).detach()
            vse += float((dv * dv).sum().item())
    return sse, vse


def _window_steps(model: torch.nn.Module, opt: torch.optim.Optimizer, us, ys, masks, window: int, batch: int,
                  warmup: int, n_train: int, gen: torch.Generator) -> float:
    """One epoch of mini-batch Adam steps on sections of ``window`` samples drawn at random (``gen``) from the
    training parts of the records, each simulated from rest with its first ``warmup`` samples out of the loss;
    as many steps as cover the training samples once on average. Returns the epoch's mean section MSE (inf as soon
    as one step's loss is not finite, before that step is taken)."""
    starts = [(k, tr.start, tr.stop - window) for k, (tr, _) in enumerate(masks) if tr.stop - tr.start >= window]
    steps = max(1, math.ceil(n_train / (batch * (window - warmup))))
    total = 0.0
    for _ in range(steps):
        pick = torch.randint(len(starts), (batch,), generator=gen).tolist()
        offs = torch.rand(batch, generator=gen, dtype=torch.float64).tolist()
        secs = [(starts[p][0], starts[p][1] + int(o * (starts[p][2] - starts[p][1] + 1))) for p, o in zip(pick, offs)]
        u = torch.stack([us[k][0, s:s + window] for k, s in secs])
        y = torch.stack([ys[k][s:s + window] for k, s in secs])
        opt.zero_grad(set_to_none=True)
        d = model(u)[:, warmup:] - y[:, warmup:]
        loss = (d * d).mean()
        if not math.isfinite(float(loss.item())):
            return math.inf
        loss.backward()
        opt.step()
        total += float(loss.item())
    return total / steps


def train_records(model: torch.nn.Module, pairs: Sequence[tuple[np.ndarray, np.ndarray]], warmup: int, epochs: int,
                  lr: float = 1e-3, lr_min: float = 1e-5, val_fraction: float = 0.0, patience: int = 0,
                  device: torch.device = torch.device("cpu"), log: Callable[[str], None] | None = None,
                  log_every: int = 100, max_seconds: float | None = None, window: int = 0, batch: int = 1,
                  seed: int = 0) -> BlockTrainResult:
    """Adam on the simulation MSE of ``pairs`` (normalised ``(u (N, n_in), y (N, n_out))``), see the module
    docstring. ``model`` is any float64 module mapping ``u`` (B, N, n_in) to ``ŷ`` (B, N, n_out) from rest (a
    :class:`BlockNet`, or a single :class:`~sysid.neural.iir.LinearDynamic` layer).

    ``window = 0``: full batch, one step per epoch on the whole records. ``window > warmup``: mini-batches of
    ``batch`` sections of ``window`` samples (drawn with a generator seeded by ``seed``), as many steps per epoch as
    cover the training samples once; the hold-out is then simulated once per epoch after its steps. ``best_epoch``
    counts the epochs behind the kept weights (0: the initial ones). Without a hold-out the last epoch's weights
    are kept; a non-finite loss restores the last good weights, halves the step size and goes on (at most
    ``MAX_RESTARTS`` times). ``max_seconds`` (wall clock) is a guard for shared machines, not a setting results
    should depend on."""
    us = [torch.as_tensor(u, dtype=torch.float64, device=device)[None] for u, _ in pairs]
    ys = [torch.as_tensor(y, dtype=torch.float64, device=device) for _, y in pairs]
    masks = _masks(pairs, warmup, val_fraction)
    n_train = sum(m.stop - m.start for m, _ in masks)
    n_val = sum(v.stop - v.start for _, v in masks if v is not None)
    if n_train < 1:
        raise ValueError("no training samples after the warm-up and the hold-out")
    window = int(window)
    if window and (window <= warmup or not any(m.stop - m.start >= window for m, _ in masks)):
        raise ValueError(f"window={window} must exceed the warm-up ({warmup}) and fit in a record's training part")
    gen = torch.Generator().manual_seed(int(seed))
    opt = torch.optim.Adam(model.parameters(), lr=float(lr))
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(1, int(epochs)), eta_min=float(lr_min))
    res = BlockTrainResult()
    c0, w0 = time.process_time(), time.perf_counter()
    best, best_state, since_best = math.inf, None, 0
    prev_state = _weights(model) if window else None  # sections step before the first check
    for ep in range(1, int(epochs) + 1):
        if window:  # the steps first, then the hold-out of the weights they reached
            sse = _window_steps(model, opt, us, ys, masks, window, int(batch), warmup, n_train, gen)
            vse = math.inf if not math.isfinite(sse) else (
                _full_pass(model, us, ys, masks, n_train, n_val, backward=False)[1] if n_val else 0.0)
        else:  # the hold-out of this forward pass: the weights before the step
            opt.zero_grad(set_to_none=True)
            sse, vse = _full_pass(model, us, ys, masks, n_train, n_val, backward=True)
        res.loss_history.append(sse)
        res.epochs_run = ep
        if not (math.isfinite(sse) and math.isfinite(vse)) or sse > 1e6:  # a step left a denominator unstable
            if prev_state is None or res.restarts >= MAX_RESTARTS:
                res.stopped = "non-finite loss"
                break
            model.load_state_dict(prev_state)  # step back and go on at half the step size
            res.restarts += 1
            for grp in opt.param_groups:
                grp["lr"] *= 0.5
            sched.base_lrs = [v * 0.5 for v in sched.base_lrs]
            sched.eta_min *= 0.5
            opt.state.clear()
            continue
        prev_state = _weights(model)  # checked finite: the weights to step back to
        current = math.sqrt(vse / (n_val * ys[-1].shape[1])) if n_val else math.nan
        res.val_history.append(current)
        if n_val and current < best:
            best, since_best, res.best_epoch = current, 0, ep - (0 if window else 1)
            best_state = _weights(model)
        elif n_val:
            since_best += 1
        if log and (ep == 1 or ep % int(log_every) == 0):
            log(f"epoch {ep}: train MSE {sse:.4g}, hold-out RMSE {current:.4g}, lr {sched.get_last_lr()[0]:.3g}")
        if patience and n_val and since_best >= int(patience):
            res.stopped = "patience"
            break
        if not window:
            opt.step()
        sched.step()
        if max_seconds is not None and time.perf_counter() - w0 > float(max_seconds):
            res.stopped = "max_seconds"
            break
    if best_state is not None:
        model.load_state_dict(best_state)
    elif not n_val:
        res.best_epoch = res.epochs_run
    res.cpu_seconds = time.process_time() - c0
    res.wall_seconds = time.perf_counter() - w0
    return res
