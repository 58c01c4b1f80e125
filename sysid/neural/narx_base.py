"""What the neural NARX identifiers share (``narx-mlp``, ``narx-mlp-sim``): options and their checks, the regressor of
eq. 2-14 on normalised records, ensembles, one-step training (eq. 2-25 … 2-27), prediction on the CPU in float64
from the trained weights (the free run compiled by numba, so a saved model predicts the same on any machine),
and the saved state. The two identifiers differ only in their ``_train``.
"""

from __future__ import annotations

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

__all__ = ["NeuralNARXBase", "MAX_ENSEMBLE"]

# Most members of an ensemble (``ensemble=k``): k trainings, and a merged network k times as wide.
MAX_ENSEMBLE = 64


def _check_storage(net: FlatMLP) -> None:
    """Once per epoch: the layer gradients must still be the slices of the flat buffer the optimiser reads."""
    if not net.check_grad_storage():  # pragma: no cover - would be a torch behaviour change
        raise RuntimeError("neural training: layer gradients left the flat buffer; the optimiser would not see them")


class NeuralNARXBase(TorchFileSave, Identifier):
    """Shared fit/predict/persistence of the two NARX-MLP identifiers (training differs)."""

    name = "narx-mlp-base"
    hidden: Sequence[int]
    loss_history_: list[float]
    # one per ensemble member after an ensemble fit (None for a member that selected nothing)
    selected_epoch_: int | list[int | None] | None
    selection_r2_: float | list[float | None] | None
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
    def fit(self, data: Record | Sequence[Record]) -> NeuralNARXBase:
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

        if self._tail is None:
            raise RuntimeError("no held-out tail: select_tail is 0")
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

    def _fit(self, recs: list[Record]) -> NeuralNARXBase:
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
            if lin is not None:
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
        y = record.output
        out[:lag] = _as2d(y)[:lag]  # initial conditions copied exactly, not through the scaling round trip
        return out[:, 0] if y.ndim == 1 else out

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
