"""Neural NARX: the dissertation's multilayer perceptron (§2.5, ch. 4 and 5.2) and its simulation-error variant.

:class:`NARXMLP` (registry id ``narx-mlp``) is the model of Tables 4.1 and 5.3: a dense network (eq. 2-10) fed
with the regressor of eq. 2-14 — ``ny`` past outputs and ``nu`` past inputs (lags 1 … 1024) — trained
one-step-ahead (series-parallel) on the targets of eq. 2-15 with MSE loss (eq. 2-27) and RMSprop (eq.
2-25/2-26), on data normalised to zero mean and unit variance. Defaults are Table 4.1: 4 hidden layers of
25 ReLU units, lags 10, learning rate 1e-4, batches of 128 pairs, 100 epochs (Table 5.3 used 75).

:class:`NARXMLPSim` (``narx-mlp-sim``) is the same network trained on *simulation* error (parallel
configuration): many windows of ``window`` samples, each started from measured samples (multiple
shooting), are simulated in parallel as one batch by feeding the network its own predictions, and the loss
is back-propagated through the whole recursion (truncated back-propagation through time). This is the
remedy the dissertation's poor free-run validation (R² 0.55 ± 0.05, Fig. 5.13) calls for. By default it
starts from a short one-step training (``pretrain_epochs``), which puts the recursion in a stable region.

Training runs on ``device`` (auto: CUDA when present); prediction always runs on the CPU in float64 from
the trained weights (``weights_``), with the free run compiled by numba, so a saved model predicts the same
after loading on any machine.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import torch

from sysid.errors import ConfigError, DataError
from sysid.neural.core import (
    FlatMLP,
    LagData,
    RMSprop,
)
from sysid.neural.narx_base import NeuralNARXBase, _check_storage
from sysid.progress import progress

__all__ = ["NARXMLP", "NARXMLPSim"]


class NARXMLP(NeuralNARXBase):
    """NARX multilayer perceptron trained one-step-ahead (series-parallel), as in the dissertation.

    Parameters
    ----------
    ny, nu : int
        Output and input lags (eq. 2-9/2-14), 0 … 1024, ny ≥ 1 (Table 4.1: 10, 10; ``n_y``, ``n_u`` deprecated).
    hidden : list of int
        Hidden layer widths, e.g. ``[25, 25, 25, 25]`` (``--set hidden=25-25-25-25``).
    activation : str
        ``sigmoid``, ``tanh`` or ``relu`` (eq. 2-11 … 2-13) in every hidden layer; linear output.
    lr, batch_size, epochs : float, int, int
        RMSprop step η (eq. 2-26), pairs per mini-batch, passes over the data (Table 4.1: 1e-4, 128, 100).
    seed : int
        Seeds the initial weights and the batch order; ``device``: ``auto`` (CUDA when present), ``cpu``, ``cuda``.
    nk : int
        Input delay [samples]: regressors u(t-nk) … u(t-nk-nu+1). Eq. 2-14 is nk = 1; a channel with a time of
        flight of d samples wants nk ≈ d.
    linear : bool
        Linear bypass ŷ = L φ + MLP(φ), L and the output bias started (and L kept) at the least-squares ARX of the
        same lags and the output layer at zero: training learns a correction of the ARX model.
    select_tail : float
        Share (0 … 0.5) of the last estimation record held out; the weights kept, initial or after any epoch, are
        those with the best free-run R² there (``selected_epoch_``). 0: the last epoch is kept.
    ensemble : int
        k networks (seeds ``seed·k + i``) averaged at every step, merged into one network of widths k·h with
        block-diagonal weights (:func:`sysid.neural.core.merge_ensemble`): less seed-to-seed spread, k× the cost.
    dtype : str
        Training precision, ``float32`` or ``float64`` (:mod:`sysid.neural.device`); prediction is float64.
    """

    name = "narx-mlp"

    def __init__(
        self,
        ny: int = 10,
        nu: int = 10,
        hidden: Sequence[int] = (25, 25, 25, 25),
        activation: str = "relu",
        lr: float = 1e-4,
        batch_size: int = 128,
        epochs: int = 100,
        seed: int = 0,
        device: str = "auto",
        nk: int = 1,
        linear: bool = False,
        select_tail: float = 0.0,
        ensemble: int = 1,
        dtype: str = "float32",
    ):
        self.dtype = dtype
        self.linear = linear
        self.select_tail = select_tail
        self.ensemble = ensemble
        self.ny = ny
        self.nu = nu
        self.nk = nk
        self.hidden = list(hidden) if isinstance(hidden, (list, tuple)) else hidden
        self.activation = activation
        self.lr = lr
        self.batch_size = batch_size
        self.epochs = epochs
        self.seed = seed
        self.device = device

    def _train(self, net: FlatMLP, data: LagData, gen: torch.Generator) -> None:
        self._train_one_step(net, data, gen, self.epochs, self.lr, select=True)


class NARXMLPSim(NeuralNARXBase):
    """The NARX-MLP trained by simulation (output) error over windows: the parallel configuration.

    Each epoch draws ``ceil(rows / window)`` windows at random starts, each started from the measured
    ``y(s-1) … y(s-ny)``. Extra parameters (the rest as :class:`NARXMLP`; ``select_tail``, ``linear``,
    ``ensemble`` and ``dtype`` as there, epoch 0 being the pretrained net):

    window : int
        Steps T of each window; the loss is the MSE of the T free-run predictions, back-propagated through the
        recursion (truncated BPTT).
    batch_size : int
        Windows simulated in parallel per gradient step.
    pretrain_epochs, pretrain_lr, pretrain_batch_size : int, float, int or None
        One-step epochs before the simulation-error ones (0: none), their step size and batch (None:
        ``batch_size``). With a :class:`NARXMLP`'s epochs, step, batch and seed, the pretrained net is that model.
    """

    name = "narx-mlp-sim"

    def __init__(
        self,
        ny: int = 10,
        nu: int = 10,
        hidden: Sequence[int] = (25, 25, 25, 25),
        activation: str = "relu",
        lr: float = 1e-3,
        batch_size: int = 32,
        epochs: int = 100,
        seed: int = 0,
        device: str = "auto",
        window: int = 50,
        pretrain_epochs: int = 10,
        pretrain_lr: float = 1e-3,
        nk: int = 1,
        select_tail: float = 0.0,
        pretrain_batch_size: int | None = None,
        linear: bool = False,
        ensemble: int = 1,
        dtype: str = "float32",
    ):
        self.dtype = dtype
        self.linear = linear
        self.ensemble = ensemble
        self.ny = ny
        self.nu = nu
        self.nk = nk
        self.hidden = list(hidden) if isinstance(hidden, (list, tuple)) else hidden
        self.activation = activation
        self.lr = lr
        self.batch_size = batch_size
        self.epochs = epochs
        self.seed = seed
        self.device = device
        self.window = window
        self.pretrain_epochs = pretrain_epochs
        self.pretrain_lr = pretrain_lr
        self.select_tail = select_tail
        self.pretrain_batch_size = pretrain_batch_size

    def _check_params(self, check_device: bool = True) -> None:
        super()._check_params(check_device)
        pb = self.pretrain_batch_size
        if pb is not None and (not isinstance(pb, (int, np.integer)) or isinstance(pb, bool) or pb < 1):
            raise ConfigError(
                f"{self.name}: pretrain_batch_size={pb!r} must be a positive integer (or None: batch_size)"
            )
        if (
            not isinstance(self.window, (int, np.integer))
            or isinstance(self.window, bool)
            or not 1 <= self.window <= 100_000
        ):
            raise ConfigError(f"{self.name}: window={self.window!r} must be an integer in [1, 100000]")
        if not isinstance(self.pretrain_epochs, (int, np.integer)) or self.pretrain_epochs < 0:
            raise ConfigError(f"{self.name}: pretrain_epochs={self.pretrain_epochs!r} must be a non-negative integer")
        if not (isinstance(self.pretrain_lr, (int, float)) and 0 < self.pretrain_lr < 10):
            raise ConfigError(f"{self.name}: pretrain_lr={self.pretrain_lr!r} must be a positive number below 10")

    def _train(self, net: FlatMLP, data: LagData, gen: torch.Generator) -> None:
        if self.pretrain_epochs:
            self._train_one_step(net, data, gen, self.pretrain_epochs, self.pretrain_lr, self.pretrain_batch_size)
        best = None
        if self._tail is not None:
            best = (self._tail_r2(net), 0, net.flat.detach().clone())
        T = int(self.window)
        starts = data.window_starts(T)
        if starts.size == 0:
            raise DataError(f"{self.name}: no record has {T + data.lag} samples for one window; lower window")
        dev = data.device
        starts_t = torch.as_tensor(starts, device=dev)
        steps = torch.arange(T, device=dev)
        n_win = max(1, math.ceil(data.n_rows / T))
        opt = RMSprop(net.flat, self.lr)
        B = int(self.batch_size)
        nyr, ch = data.n_yreg, data.ny_ch
        for _ in progress(range(int(self.epochs)), desc=f"{self.name} simulation", unit="epoch"):
            pick = torch.randint(0, starts.size, (n_win,), generator=gen).to(dev)
            total = torch.zeros((), device=dev, dtype=data.dtype)
            for sel in pick.split(B):
                s = starts_t[sel]
                rows = (s[:, None] + steps[None, :]).reshape(-1)
                Xw = data.x(rows).view(s.shape[0], T, data.n_in)
                target = data.Y[rows].view(s.shape[0], T, ch)
                yreg = Xw[:, 0, :nyr]  # measured y(s-1) … y(s-ny): the shooting node
                preds = []
                for j in range(T):
                    yh = net(torch.cat([yreg, Xw[:, j, nyr:]], dim=1))
                    preds.append(yh)
                    yreg = torch.cat([yh, yreg[:, : nyr - ch]], dim=1) if nyr > ch else yh
                d = torch.stack(preds, dim=1) - target
                loss = (d * d).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
                total += loss.detach() * s.shape[0]
            _check_storage(net)
            self.loss_history_.append(float(total.item()) / n_win)
            if best is not None:
                score = self._tail_r2(net)
                if score > best[0]:
                    best = (score, len(self.loss_history_) - int(self.pretrain_epochs), net.flat.detach().clone())
        if best is not None:
            with torch.no_grad():
                net.flat.copy_(best[2])
            self.selection_r2_, self.selected_epoch_ = float(best[0]), int(best[1])
