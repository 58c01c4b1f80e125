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
import time
import warnings
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
import torch

from sysid.base import Identifier, as_record_list
from sysid.data.record import Normaliser, Record
from sysid.errors import ConfigError, DataError, DivergenceWarning
from sysid.neural.core import (
    ACT_CODE,
    ACTIVATIONS,
    FlatMLP,
    LagData,
    RMSprop,
    count_mlp_parameters,
    free_run_mlp,
    k_step_mlp,
    lag_matrix_np,
    least_squares_linear,
    merge_ensemble,
    mlp_forward_np,
    regressor_lag,
)
from sysid.neural.device import configure_threads, select_device, train_dtype
from sysid.neural.persist import TorchFileSave
from sysid.neural.records import (
    DIVERGENCE_BOUND,
    MAX_LAG,
    _as2d,
    check_channels,
    check_predict_input,
    fit_normaliser,
    normalised_pairs,
)
from sysid.progress import progress

__all__ = ["NARXMLP", "NARXMLPSim"]

# Most members of an ensemble (``ensemble=k``): k trainings, and a merged network k times as wide.
MAX_ENSEMBLE = 64


def _check_storage(net: FlatMLP) -> None:
    """Once per epoch: the layer gradients must still be the slices of the flat buffer the optimiser reads."""
    if not net.check_grad_storage():  # pragma: no cover - would be a torch behaviour change
        raise RuntimeError("neural training: layer gradients left the flat buffer; the optimiser would not see them")


class _NeuralNARXBase(TorchFileSave, Identifier):
    """Shared fit/predict/persistence of the two NARX-MLP identifiers (training differs)."""

    name = "narx-mlp-base"
    hidden: Sequence[int]
    loss_history_: list[float]
    selected_epoch_: int | list[int] | None  # one per ensemble member after an ensemble fit
    selection_r2_: float | list[float] | None
    _tail: Record | None

    # ------------------------------------------------------------------ checks
    def _check_params(self, check_device: bool = True) -> None:
        for key in ("ny", "nu"):
            v = getattr(self, key)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or not 0 <= v <= MAX_LAG:
                raise ConfigError(f"{self.name}: {key}={v!r} must be an integer in [0, {MAX_LAG}]")
        if self.ny < 1:
            raise ConfigError(f"{self.name}: ny={self.ny} must be at least 1 (a NARX model feeds back past outputs)")
        nk = self.nk
        if not isinstance(nk, (int, np.integer)) or isinstance(nk, bool) or not 0 <= nk <= 100_000:
            raise ConfigError(f"{self.name}: nk={nk!r} must be an integer in [0, 100000] (input delay in samples)")
        hidden = list(self.hidden) if isinstance(self.hidden, (list, tuple)) else None
        if hidden is None or not all(
            isinstance(h, (int, np.integer)) and not isinstance(h, bool) and 1 <= h <= 65536 for h in hidden
        ):
            raise ConfigError(
                f"{self.name}: hidden={self.hidden!r} must be a list of layer widths ≥ 1, e.g. hidden=25-25-25-25"
            )
        self.hidden = [int(h) for h in hidden]
        if self.activation not in ACTIVATIONS:
            raise ConfigError(f"{self.name}: activation={self.activation!r} not one of: {', '.join(ACTIVATIONS)}")
        if not (isinstance(self.lr, (int, float)) and 0 < self.lr < 10):
            raise ConfigError(f"{self.name}: lr={self.lr!r} must be a positive number below 10")
        for key in ("batch_size", "epochs"):
            v = getattr(self, key)
            if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v < (1 if key == "batch_size" else 0):
                raise ConfigError(f"{self.name}: {key}={v!r} must be a positive integer")
        if not isinstance(self.seed, (int, np.integer)) or isinstance(self.seed, bool):
            raise ConfigError(f"{self.name}: seed={self.seed!r} must be an integer")
        if not isinstance(self.linear, (bool, np.bool_)):
            raise ConfigError(f"{self.name}: linear={self.linear!r} must be true or false")
        if not (
            isinstance(self.select_tail, (int, float))
            and not isinstance(self.select_tail, bool)
            and 0 <= self.select_tail < 0.5
        ):
            raise ConfigError(f"{self.name}: select_tail={self.select_tail!r} must be a fraction in [0, 0.5)")
        k = getattr(self, "ensemble", 1)
        if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or not 1 <= k <= MAX_ENSEMBLE:
            raise ConfigError(
                f"{self.name}: ensemble={k!r} must be an integer in [1, {MAX_ENSEMBLE}] (networks averaged)"
            )
        train_dtype(getattr(self, "dtype", "float32"), self.name)
        if check_device:  # a saved model trained on a GPU must still load (and predict) on a CPU machine
            select_device(self.device)

    # ------------------------------------------------------------------ fit
    def fit(self, data: Record | Sequence[Record]) -> _NeuralNARXBase:
        """Train on one Record or a list of them (no regressor spans two records). Returns self.

        With ``select_tail`` > 0 the last fraction of the last estimation record is held out of training and
        the weights kept are those (at the start of the selected training stage or after any of its epochs)
        with the best free-run R² on it — early stopping / model selection on estimation data only."""
        self._check_params()
        recs = as_record_list(data)
        self._tail = None
        self.selected_epoch_, self.selection_r2_ = None, None
        if self.select_tail:
            last = recs[-1]
            n_hold = int(round(self.select_tail * len(last)))
            lag = regressor_lag(self.ny, self.nu, self.nk)
            cut = len(last) - n_hold
            if n_hold < 1 or cut - lag < max(1, int(getattr(self, "window", 1))) or cut < lag + 1:
                raise DataError(
                    f"{self.name}: select_tail={self.select_tail} leaves {cut} training / {n_hold} "
                    f"held-out samples of {last.source}, need more than the lag {lag} and one window "
                    "in each"
                )
            self._tail = last[cut - lag :]  # the held-out samples with their lag of measured initial conditions
            recs = [*recs[:-1], last[:cut]]
        try:
            return self._fit(recs)
        finally:
            self._tail = None

    def _tail_r2(self, net: FlatMLP) -> float:
        """Free-run R² (normalised units; R² is scale-free) on the held-out tail, after the initial conditions."""
        from sysid.evaluation.metrics import r2

        ((un, yn),) = normalised_pairs([self._tail], self.normaliser_)
        yh, div = free_run_mlp(
            net.weights_np(),
            list(net.sizes),
            ACT_CODE[self.activation],
            yn,
            un,
            self.ny,
            self.nu,
            DIVERGENCE_BOUND,
            self.nk,
            self.linear,
        )
        lag = regressor_lag(self.ny, self.nu, self.nk)
        return -np.inf if div >= 0 or not np.isfinite(yh).all() else float(r2(yn, yh, lag))

    def member_seeds(self) -> list[int]:
        """Seeds of the ensemble's members: ``seed·k + i`` for i = 0 … k-1 (k = ``ensemble``), so that
        ``ensemble=1`` is the single network of seed ``seed`` and different base seeds never share a member."""
        k = int(getattr(self, "ensemble", 1))
        return [int(self.seed) * k + i for i in range(k)]

    def _fit(self, recs: list[Record]) -> _NeuralNARXBase:
        lag = regressor_lag(self.ny, self.nu, self.nk)
        nu, ny = check_channels(recs, lag, self.name)
        t0 = time.perf_counter()
        configure_threads()
        device = select_device(self.device)
        self.normaliser_ = fit_normaliser(recs)
        pairs = normalised_pairs(recs, self.normaliser_)
        dtype = train_dtype(getattr(self, "dtype", "float32"), self.name)
        data_t = LagData(pairs, self.ny, self.nu, device, dtype=dtype, nk=self.nk)
        lin = least_squares_linear(pairs, self.ny, self.nu, self.nk) if self.linear else None
        members, histories, selections = [], [], []
        for seed in self.member_seeds():
            torch.manual_seed(seed)
            gen = torch.Generator().manual_seed(seed)
            net = FlatMLP(data_t.n_in, self.hidden, ny, self.activation, gen, device, dtype=dtype, linear=self.linear)
            if self.linear:
                # The bypass is the least-squares ARX of the same regressor, kept fixed: the network (output layer
                # started at zero) learns the correction. Training L as well (quick data, free-run RMSE, L trained
                # vs fixed): one-step training worse on all three datasets tried (cascaded tanks 0.71 vs 0.67 V,
                # Wiener-Hammerstein 41.7 vs 36.2 mV, piezo 1.23 vs 1.16 um); simulation-error training worse on
                # three of four (cascaded tanks 5.9 vs 0.65 V, WH 170 vs 27 mV, Bouc-Wen multisine 1.6e-4 vs
                # 5.5e-5 m), better on the piezo (1.5 vs 4.4 um). RMSprop moves every weight by about lr per step
                # whatever its gradient, which shifts the poles of a finely sampled ARX that far.
                net.init_linear(*lin)
                net.freeze_linear()
            self.loss_history_ = []
            self.selected_epoch_, self.selection_r2_ = None, None
            self._train(net, data_t, gen)
            members.append(net.weights_np())
            histories.append(self.loss_history_)
            selections.append((self.selected_epoch_, self.selection_r2_))
        sizes = [data_t.n_in, *self.hidden, ny]
        if len(members) == 1:
            self.weights_, self.sizes_ = members[0], sizes
        else:
            self.weights_, self.sizes_ = merge_ensemble(members, sizes, self.linear)
            # per-epoch mean training loss of the members; per-member selections (held-out tail)
            self.loss_history_ = [float(np.mean(v)) for v in zip(*histories)]
            self.selected_epoch_ = [s[0] for s in selections] if self._tail is not None else None
            self.selection_r2_ = [s[1] for s in selections] if self._tail is not None else None
        self.n_inputs_, self.n_outputs_ = nu, ny
        self.max_lag_ = lag
        self.n_parameters_ = self._real_n_parameters(data_t.n_in, ny)
        self.device_used_ = str(device)
        self.fit_seconds_ = time.perf_counter() - t0
        self.diverged_at_ = None
        if not np.isfinite(self.weights_).all():
            warnings.warn(
                f"{self.name}: training diverged (non-finite weights); predictions will be nan",
                DivergenceWarning,
                stacklevel=2,
            )
        return self

    def _real_n_parameters(self, n_in: int, n_out: int) -> int:
        """Trained parameters: k × those of one member's dense layers, plus the linear bypass L once (it is the
        same least-squares ARX, fixed, in every member). The zeros between members in the merged network
        (:func:`merge_ensemble`) are not parameters and are not counted."""
        k = int(getattr(self, "ensemble", 1))
        return k * count_mlp_parameters(n_in, self.hidden, n_out, False) + (
            int(n_in) * int(n_out) if self.linear else 0
        )

    def _train_one_step(
        self,
        net: FlatMLP,
        data: LagData,
        gen: torch.Generator,
        epochs: int,
        lr: float,
        batch_size: int | None = None,
        select: bool = False,
    ) -> None:
        """Series-parallel training (eq. 2-14/2-15): shuffled mini-batches of regressor rows, MSE, RMSprop.
        ``select`` (with a held-out tail): keep the weights, initial or after an epoch, of best tail free-run R²."""
        best = (self._tail_r2(net), 0, net.flat.detach().clone()) if select and self._tail is not None else None
        opt = RMSprop(net.flat, lr)
        M, B = data.n_rows, int(self.batch_size if batch_size is None else batch_size)
        dev = data.device
        for ep in progress(range(int(epochs)), desc=f"{self.name} one-step", unit="epoch"):
            perm = torch.randperm(M, generator=gen).to(dev)
            losses: list[torch.Tensor] = []
            batches: Iterable[tuple[torch.Tensor, torch.Tensor]]
            if data.X is not None:
                batches = zip(data.X[perm].split(B), data.Y[perm].split(B))
            else:
                batches = ((data.x(idx), data.Y[idx]) for idx in perm.split(B))
            for xb, yb in batches:
                loss = net.mse_grad_(xb, yb)  # forward, MSE and hand-written back-propagation
                opt.step()
                losses.append(loss)
            # mean of the batch losses weighted by batch size; one device sync per epoch
            sizes = torch.full((len(losses),), float(B), device=dev)
            sizes[-1] = M - B * (len(losses) - 1)
            self.loss_history_.append(float((torch.stack(losses) * sizes).sum().item()) / M)
            if best is not None:
                score = self._tail_r2(net)
                if score > best[0]:
                    best = (score, ep + 1, net.flat.detach().clone())
        if best is not None:
            with torch.no_grad():
                net.flat.copy_(best[2])
            self.selection_r2_, self.selected_epoch_ = float(best[0]), int(best[1])

    def _train(self, net: FlatMLP, data: LagData, gen: torch.Generator) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    # ------------------------------------------------------------------ predict
    def _check_fitted(self) -> None:
        if not hasattr(self, "weights_"):
            raise ConfigError(f"{self.name}: model is not fitted; call fit() first")

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """One-step (``horizon=1``), k-step-ahead at every sample (``horizon=k``) or free-run (``None``).

        Returns an array shaped like ``record.y``; its first ``max_lag_`` samples are the measurement (initial
        conditions, eq. 2-29). A diverging free run is stopped: the rest is ``nan``, ``diverged_at_`` holds
        the index and a :class:`DivergenceWarning` is issued.
        """
        self._check_fitted()
        check_predict_input(self, record, horizon)
        lag = self.max_lag_
        n = len(record)
        ((un, yn),) = normalised_pairs([record], self.normaliser_)
        code = ACT_CODE[self.activation]
        self.diverged_at_ = None
        if horizon is None or horizon >= n - lag:
            yhat, div = free_run_mlp(
                self.weights_, self.sizes_, code, yn, un, self.ny, self.nu, DIVERGENCE_BOUND, self.nk, self.linear
            )
            if div >= 0:
                self.diverged_at_ = int(div)
                warnings.warn(
                    f"{self.name}: free-run simulation diverged at sample {div} of {n}; the rest is nan",
                    DivergenceWarning,
                    stacklevel=2,
                )
        elif horizon == 1:
            times = np.arange(lag, n)
            x = np.concatenate(
                [lag_matrix_np(yn, self.ny, times), lag_matrix_np(un, self.nu, times, first=self.nk)], axis=1
            )
            yhat = yn.copy()
            with np.errstate(over="ignore", invalid="ignore"):
                yhat[lag:] = mlp_forward_np(self.weights_, self.sizes_, code, x, self.linear)
        else:
            yhat = k_step_mlp(
                self.weights_,
                self.sizes_,
                code,
                yn,
                un,
                self.ny,
                self.nu,
                int(horizon),
                DIVERGENCE_BOUND,
                self.nk,
                self.linear,
            )
        if horizon is not None and not np.isfinite(yhat).all():
            bad = np.flatnonzero(~np.isfinite(yhat).all(axis=1))
            self.diverged_at_ = int(bad[0])
            yhat[bad] = np.nan
            warnings.warn(
                f"{self.name}: {bad.size} non-finite {horizon}-step predictions, first at sample {bad[0]}",
                DivergenceWarning,
                stacklevel=2,
            )
        out = self.normaliser_.inverse_y(yhat)
        out[:lag] = _as2d(record.y)[:lag]  # initial conditions copied exactly, not through the scaling round trip
        return out[:, 0] if record.y.ndim == 1 else out

    # ------------------------------------------------------------------ description / persistence
    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "weights_"):
            d.update(
                {
                    "structure": {
                        "inputs": self.sizes_[0],
                        "hidden": list(self.hidden),
                        "outputs": self.sizes_[-1],
                        "activation": self.activation,
                        "ny": self.ny,
                        "nu": self.nu,
                        "nk": self.nk,
                        "n_y": self.ny,
                        "n_u": self.nu,  # old key names, kept for readers of earlier output
                        "linear": bool(self.linear),
                        "ensemble": int(getattr(self, "ensemble", 1)),
                    },
                    "terms": [],
                    "max_lag": self.max_lag_,
                    "device": self.device_used_,
                    "final_loss": self.loss_history_[-1] if self.loss_history_ else None,
                    "epochs_run": len(self.loss_history_),
                }
            )
        return d

    def _state(self) -> dict[str, Any]:
        self._check_fitted()
        return {
            "weights": np.asarray(self.weights_, dtype=float).tolist(),
            "sizes": list(map(int, self.sizes_)),
            "normaliser": self.normaliser_.to_dict(),
            "n_inputs": int(self.n_inputs_),
            "n_outputs": int(self.n_outputs_),
            "loss_history": [float(v) for v in self.loss_history_],
            "device_used": self.device_used_,
            "fit_seconds": float(self.fit_seconds_),
        }

    def _load_state(self, state: dict[str, Any]) -> None:
        self._check_params(check_device=False)
        self.weights_ = np.asarray(state["weights"], dtype=np.float64)
        self.sizes_ = [int(s) for s in state["sizes"]]
        expected = count_mlp_parameters(self.sizes_[0], self.sizes_[1:-1], self.sizes_[-1], self.linear)
        if expected != self.weights_.size:
            raise DataError(
                f"{self.name}: saved weights ({self.weights_.size}) do not match layer sizes {self.sizes_}"
                f"{' with the linear bypass' if self.linear else ''} ({expected})"
            )
        self.normaliser_ = Normaliser.from_dict(state["normaliser"])
        self.n_inputs_, self.n_outputs_ = int(state["n_inputs"]), int(state["n_outputs"])
        self.loss_history_ = [float(v) for v in state.get("loss_history", [])]
        self.device_used_ = state.get("device_used", "cpu")
        self.fit_seconds_ = float(state.get("fit_seconds", float("nan")))
        k = int(getattr(self, "ensemble", 1))
        if self.sizes_[1:-1] != [k * h for h in self.hidden]:
            raise DataError(
                f"{self.name}: saved layer sizes {self.sizes_} do not match hidden={self.hidden} with "
                f"ensemble={k} (merged hidden widths are k × hidden)"
            )
        self.max_lag_ = regressor_lag(self.ny, self.nu, self.nk)
        self.n_parameters_ = self._real_n_parameters(self.sizes_[0], self.sizes_[-1])
        self.diverged_at_ = None


class NARXMLP(_NeuralNARXBase):
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


class NARXMLPSim(_NeuralNARXBase):
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
