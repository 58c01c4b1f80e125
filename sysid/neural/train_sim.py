"""Training on truncated simulation error over overlapping sections (the SUBNET fitting loop), model-agnostic.

Beintema, Tóth & Schoukens (Automatica 2023), eq. (9)–(10): the loss of one mini-batch is

    V = 1/(B·T·ny) Σ_sections Σ_{j=0}^{T-1} ‖ y(k_i + j) − ŷ(k_i + j | k_i) ‖²

where every section starts at a time k_i with the ``lag`` measured samples before it (from which the model
estimates its initial state) and is simulated T steps on the input alone. The sections of one epoch are ALL
start times of the estimation records (overlapping, shuffled), in mini-batches of ``batch_size``; Adam
(``torch.optim.Adam``) minimises V. After each epoch the model simulates each validation record in full (its
state estimated from the record's first ``lag`` samples) and the weights of the lowest validation simulation
RMSE are kept (early stopping; ``patience`` epochs without improvement end the training).

Any ``torch.nn.Module`` called as ``model(ypast (B, lag, ny), upast (B, lag, nu), useq (B, T, nu)) -> (B, T,
ny)`` fits this loop (:class:`sysid.neural.subnet.SubnetModel` does). Data are normalised float pairs
``(u (N, nu), y (N, ny))``; a section never spans two records.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

__all__ = ["Sections", "SimTrainResult", "train_simulation", "validation_rmse"]


class Sections:
    """All sections ``[k - lag, k + T)`` of a list of ``(u, y)`` records, as tensors on ``device``."""

    def __init__(self, pairs: Sequence[tuple[np.ndarray, np.ndarray]], lag: int, T: int, device: torch.device,
                 dtype: torch.dtype = torch.float32):
        self.lag, self.T = int(lag), int(T)
        us, ys, starts = [], [], []
        offset = 0
        for u, y in pairs:
            n = u.shape[0]
            if n >= self.lag + self.T:
                starts.append(np.arange(self.lag, n - self.T + 1) + offset)
            us.append(u)
            ys.append(y)
            offset += n
        self.starts = np.concatenate(starts) if starts else np.zeros(0, dtype=np.int64)
        self.u = torch.as_tensor(np.concatenate(us), dtype=dtype, device=device)
        self.y = torch.as_tensor(np.concatenate(ys), dtype=dtype, device=device)
        self.device = device
        self._past = torch.arange(-self.lag, 0, device=device)
        self._fut = torch.arange(0, self.T, device=device)

    def __len__(self) -> int:
        return int(self.starts.size)

    def batch(self, k: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(ypast, upast, useq, ytarget) of the sections starting at times ``k`` (indices into the records)."""
        past = k[:, None] + self._past[None, :]
        fut = k[:, None] + self._fut[None, :]
        return self.y[past], self.u[past], self.u[fut], self.y[fut]


@dataclass
class SimTrainResult:
    """What :func:`train_simulation` did: per-epoch training loss (mean section MSE, normalised units), the
    validation RMSE after each epoch (index 0: before training), the epoch whose weights were kept (0 = the
    initial ones) and the CPU seconds spent."""

    loss_history: list[float] = field(default_factory=list)
    val_history: list[float] = field(default_factory=list)
    best_epoch: int | None = None
    epochs_run: int = 0
    cpu_seconds: float = 0.0
    wall_seconds: float = 0.0


@torch.no_grad()
def validation_rmse(model: torch.nn.Module, pairs: Sequence[tuple[np.ndarray, np.ndarray]], lag: int,
                    device: torch.device, dtype: torch.dtype = torch.float32) -> float:
    """Free-run RMSE (normalised units) over validation records, each simulated from its first ``lag``
    samples; ``inf`` when the simulation is non-finite."""
    se, n = 0.0, 0
    for u, y in pairs:
        if u.shape[0] <= lag:
            continue
        ut = torch.as_tensor(u, dtype=dtype, device=device)[None]
        yt = torch.as_tensor(y, dtype=dtype, device=device)[None]
        yh = model(yt[:, :lag], ut[:, :lag], ut[:, lag:])
        d = (yh - yt[:, lag:]).double()
        v = float((d * d).sum().item())
        if not math.isfinite(v):
            return math.inf
        se += v
        n += d.numel()
    return math.sqrt(se / n) if n else math.inf


def train_simulation(model: torch.nn.Module, train: Sequence[tuple[np.ndarray, np.ndarray]], lag: int, T: int,
                     epochs: int, batch_size: int = 256, lr: float = 1e-3,
                     val: Sequence[tuple[np.ndarray, np.ndarray]] | None = None, patience: int = 0,
                     clip: float = 0.0, generator: torch.Generator | None = None,
                     device: torch.device = torch.device("cpu"), log: Callable[[str], None] | None = None,
                     max_seconds: float | None = None, lr_min: float | None = None) -> SimTrainResult:
    """Minimise the truncated T-step simulation loss of ``model`` on ``train`` with Adam (see the module
    docstring); early stopping on the free-run RMSE of ``val`` when given (the best weights are loaded back into
    ``model``). ``patience`` > 0 stops after that many epochs without a better validation RMSE; ``clip`` > 0
    clips the gradient norm; ``max_seconds`` (wall clock) stops after the epoch that passes it — a guard for
    shared machines, not a setting that results should depend on. ``lr_min``: the step size follows a cosine from
    ``lr`` down to ``lr_min`` over ``epochs`` (``torch.optim.lr_scheduler.CosineAnnealingLR``, one step per
    epoch; Loshchilov & Hutter 2017, eq. 5); ``None`` keeps ``lr`` constant. Returns a :class:`SimTrainResult`."""
    gen = generator or torch.Generator().manual_seed(0)
    sec = Sections(train, lag, T, device)
    if len(sec) == 0:
        raise ValueError(f"no record has lag + T = {lag + T} samples for one section")
    opt = torch.optim.Adam(model.parameters(), lr=float(lr))
    sched = (torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(int(epochs), 1), eta_min=float(lr_min))
             if lr_min is not None else None)
    res = SimTrainResult()
    c0, w0 = time.process_time(), time.perf_counter()
    best_state = None
    if val:
        best = validation_rmse(model, val, lag, device)
        res.val_history.append(best)
        best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        res.best_epoch = 0
    starts = torch.as_tensor(sec.starts, device=device)
    B = int(batch_size)
    since_best = 0
    for ep in range(1, int(epochs) + 1):
        perm = torch.randperm(len(sec), generator=gen).to(device)
        total = torch.zeros((), dtype=torch.float64, device=device)
        for sel in perm.split(B):
            ypast, upast, useq, target = sec.batch(starts[sel])
            d = model(ypast, upast, useq) - target
            loss = (d * d).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            if clip:
                torch.nn.utils.clip_grad_norm_(model.parameters(), float(clip))
            opt.step()
            total += loss.detach().double() * sel.numel()
        res.loss_history.append(float(total.item()) / len(sec))
        res.epochs_run = ep
        if sched is not None:
            sched.step()
        msg = f"epoch {ep}: train loss {res.loss_history[-1]:.4g}"
        if val:
            v = validation_rmse(model, val, lag, device)
            res.val_history.append(v)
            msg += f", validation RMSE {v:.4g}"
            if v < best:
                best, since_best, res.best_epoch = v, 0, ep
                best_state = {k: t.detach().clone() for k, t in model.state_dict().items()}
            else:
                since_best += 1
        if log:
            log(msg)
        if not math.isfinite(res.loss_history[-1]) and best_state is not None:
            break  # diverged: the best weights so far are restored below
        if patience and since_best >= int(patience):
            break
        if max_seconds is not None and time.perf_counter() - w0 > float(max_seconds):
            break
    if best_state is not None:
        model.load_state_dict(best_state)
    res.cpu_seconds = time.process_time() - c0
    res.wall_seconds = time.perf_counter() - w0
    return res
