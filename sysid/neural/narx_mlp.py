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
        Output and input lags (eq. 2-9/2-14), 0 … 1024 (ny ≥ 1). Table 4.1: 10 and 10. The older names
        ``n_y``, ``n_u`` are accepted as deprecated aliases (:data:`sysid.config.ALIASES`).
    hidden : list of int
        Hidden layer widths, e.g. ``[25, 25, 25, 25]`` (``--set hidden=25-25-25-25``).
    activation : str
        ``sigmoid`` (eq. 2-11), ``tanh`` (2-12) or ``relu`` (2-13) in every hidden layer; linear output.
    lr, batch_size, epochs : float, int, int
        RMSprop learning rate η (eq. 2-26), input/output pairs per mini-batch and passes over the data
        (Table 4.1: 1e-4, 128, 100).
    seed : int
        Seeds the initial weights and the batch order (deterministic on the CPU).
    device : str
        ``auto`` (CUDA when present), ``cpu`` or ``cuda``.
    nk : int
        Input delay in samples: the input regressors are u(t-nk) … u(t-nk-nu+1). The dissertation's eq. 2-14
        is nk = 1 (default); a transmission channel with a time of flight of d samples wants nk ≈ d, so that
        nu covers the response instead of the dead time.
    linear : bool
        Linear bypass: ŷ = L φ + MLP(φ) (φ the regressor of eq. 2-14), with L and the output bias started at the
        least-squares ARX of the same lags (L kept fixed in training) and the network's output layer at zero, so
        training starts from the ARX model and learns a nonlinear correction. False (default): the dissertation's
        plain network.
    select_tail : float
        Fraction (0 … 0.5) of the last estimation record held out of training; the weights kept are those,
        initial or after any epoch, with the best free-run R² on that tail (``selected_epoch_`` 0 = the initial
        weights, i.e. the ARX model with ``linear``). 0 (default): no hold-out, the last epoch is kept.
    ensemble : int
        Number k of networks averaged (1 … 64; default 1 = the single network of ``seed``). Member i is trained
        exactly as a single model of seed ``seed·k + i`` (its own initial weights, batch order and, with
        ``select_tail``, its own selected epoch: ``selected_epoch_`` becomes a list); the prediction is the
        members' mean at every step — in free run the mean is fed back (one model, not k simulations). After
        training the members are merged into ONE network of hidden widths k·h with block-diagonal weights
        (:func:`sysid.neural.core.merge_ensemble`), so prediction and saved files use the single-network code;
        ``n_parameters_`` counts k × a member's parameters plus the linear bypass once, not the zero blocks.
        Reduces the seed-to-seed spread of the free run at k times the training cost.
    dtype : str
        Training precision, ``float32`` (default, fastest) or ``float64``. With float64 one-step training gives the
        same weights on CPUs with different vector instruction sets to about 12 digits; simulation-error training
        can amplify any rounding difference (see :mod:`sysid.neural.device`). Prediction is float64 either way.
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
    """The NARX-MLP trained by simulation (output) error over windows — the parallel configuration.

    Extra parameters (the rest as :class:`NARXMLP`):

    window : int
        Steps T of each simulated window; the loss is the MSE of the T free-run predictions and is
        back-propagated through the recursion (truncated BPTT).
    batch_size : int
        Windows simulated in parallel per gradient step.
    pretrain_epochs : int
        One-step (series-parallel) epochs before the simulation-error epochs (0 to start from scratch).
    pretrain_lr : float
        Learning rate of the one-step pretraining.
    pretrain_batch_size : int or None
        Mini-batch of the one-step pretraining (None: ``batch_size``). With the same epochs, learning rate and
        batch as a :class:`NARXMLP` of the same seed, the pretrained net IS that one-step model (warm start).
    select_tail : float
        Fraction (0 … 0.5) of the last estimation record held out of training; the weights kept are those,
        after pretraining or after any simulation-error epoch, with the best free-run R² on that tail (early
        stopping / model selection on estimation data only; ``selected_epoch_`` 0 means the pretrained net).
        0 (default): no hold-out, the last epoch is kept.
    linear : bool
        Linear bypass started at the least-squares ARX, as for :class:`NARXMLP`.
    ensemble : int
        k networks (seeds ``seed·k + i``) trained alike and averaged, merged into one network, as for
        :class:`NARXMLP`.
    dtype : str
        Training precision ``float32`` (default) or ``float64``, as for :class:`NARXMLP`.

    Each epoch draws ``ceil(rows / window)`` window starts at random positions (so that on average every
    sample is a target once per epoch); each window starts from the measured ``y(s-1) … y(s-ny)``.
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
