"""Encoder state-space identifier (registry id ``ss-encoder``): SUBNET trained on simulation error.

The model is :class:`sysid.neural.subnet.SubnetModel` (x(k+1) = f(x, u), y = h(x), initial state from the
encoder ψ over the ``lag = max(ny, nu)`` samples before it), trained by :func:`sysid.neural.training.train_simulation`
on the truncated T-step simulation loss (Beintema, Tóth & Schoukens, Automatica 2023) in normalised units, with
Adam and early stopping on the free-run RMSE of a held-out tail of the estimation data (``val_fraction``).

Prediction (float64 numpy on the CPU, from the saved weights):

- ``predict(record, None)`` — free run: the encoder estimates x(lag) from the record's first ``lag`` samples
  (the benchmark's initialisation window when ``lag`` ≤ it), then f/h simulate the rest on the input alone.
  The first ``lag`` samples of the result are the measurement (``max_lag_ = lag``).
- ``predict(record, k)`` — at every t ≥ lag: the state x(t-k+1) is encoded from the samples before it and
  simulated k steps (fewer at the record start); ``k = 1`` is ŷ(t) = h(ψ(past of t)).
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from sysid.base import as_record_list
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError, DivergenceWarning
from sysid.neural.persist import saved_array
from sysid.neural.records import (
    DIVERGENCE_BOUND,
    MAX_LAG,
    check_channels,
    check_predict_input,
    hidden_widths,
    normalised_pairs,
)
from sysid.neural.sequence import SequenceIdentifier
from sysid.neural.subnet import SubnetModel, encode_np, export_weights, simulate_np
from sysid.neural.training import train_simulation

__all__ = ["SSEncoder"]

_LOG = logging.getLogger(__name__)  # per-epoch progress at INFO (the library configures no handler)
_ACT_NP = {"tanh": np.tanh, "relu": lambda a: np.maximum(a, 0.0), "sigmoid": lambda a: 1.0 / (1.0 + np.exp(-a))}


class SSEncoder(SequenceIdentifier):
    """SUBNET encoder state-space model trained on truncated simulation error.

    Parameters
    ----------
    nx : int
        State dimension (the paper: 4–8 on Silverbox).
    ny, nu : int
        Past outputs and inputs read by the encoder (the papers' n_a, n_b); ``max_lag_ = max(ny, nu)`` samples start
        every free run.
    f_hidden, h_hidden, e_hidden : list of int
        Hidden widths of f, h and the encoder (the paper: one layer of 64 tanh units each); ``0`` / ``[]``: linear.
    activation : str
        ``tanh`` (the paper), ``relu`` or ``sigmoid``; ``feedthrough``: output map h(x, u) instead of h(x).
    T : int
        Simulated steps per section of the truncated simulation loss (the papers: tens of steps).
    batch_size, epochs, lr, lr_min : int, int, float, float or None
        Sections per Adam step, passes over all sections, step size, and the last step size of a cosine decay
        over ``epochs`` (``None``: constant; at a constant 1e-3 the validation error oscillates 2–3× between epochs).
    val_fraction, patience : float, int
        Last share (0 … 0.5) of the last record held out for early stopping (0: the last epoch is kept), and epochs
        without a better validation RMSE before stopping (0: none).
    clip : float
        Gradient-norm clipping (0: off).
    seed, device :
        Seeds weights and section order; ``auto`` | ``cpu`` | ``cuda`` (:mod:`sysid.neural.device`).
    cuda_graphs : bool
        On a CUDA device, replay each training step and hold-out run as a CUDA graph
        (:mod:`sysid.neural.cuda_graphs`; the same model to float rounding); ignored on the CPU.
    """

    name = "ss-encoder"

    def __init__(
        self,
        nx: int = 4,
        ny: int = 20,
        nu: int = 20,
        f_hidden: Sequence[int] = (64,),
        h_hidden: Sequence[int] = (64,),
        e_hidden: Sequence[int] = (64,),
        activation: str = "tanh",
        feedthrough: bool = False,
        T: int = 50,
        batch_size: int = 256,
        epochs: int = 50,
        lr: float = 1e-3,
        lr_min: float | None = None,
        val_fraction: float = 0.2,
        patience: int = 0,
        clip: float = 0.0,
        seed: int = 0,
        device: str = "auto",
        cuda_graphs: bool = True,
    ):
        self.nx = nx
        self.ny = ny
        self.nu = nu
        self.f_hidden = list(f_hidden) if isinstance(f_hidden, tuple) else f_hidden
        self.h_hidden = list(h_hidden) if isinstance(h_hidden, tuple) else h_hidden
        self.e_hidden = list(e_hidden) if isinstance(e_hidden, tuple) else e_hidden
        self.activation = activation
        self.feedthrough = feedthrough
        self.T = T
        self.batch_size = batch_size
        self.epochs = epochs
        self.lr = lr
        self.lr_min = lr_min
        self.val_fraction = val_fraction
        self.patience = patience
        self.clip = clip
        self.seed = seed
        self.device = device
        self.cuda_graphs = cuda_graphs

    # ------------------------------------------------------------------ checks
    def _check_params(self, check_device: bool = True) -> None:
        self._check_int("nx", 1, 4096)
        self._check_int("ny", 0, MAX_LAG)
        self._check_int("nu", 0, MAX_LAG)
        if self.ny + self.nu < 1:
            raise ConfigError(f"{self.name}: ny + nu must be at least 1 (the encoder needs a past window)")
        self._check_int("T", 1, 100_000)
        self._check_int("batch_size", 1, 1_000_000)
        self._check_int("epochs", 0, 1_000_000)
        self._check_int("patience", 0, 1_000_000)
        for key in ("f_hidden", "h_hidden", "e_hidden"):
            setattr(self, key, hidden_widths(getattr(self, key), key, self.name))
        if self.activation not in _ACT_NP:
            raise ConfigError(f"{self.name}: activation={self.activation!r} not one of: {', '.join(_ACT_NP)}")
        for key in ("feedthrough", "cuda_graphs"):
            if not isinstance(getattr(self, key), (bool, np.bool_)):
                raise ConfigError(f"{self.name}: {key}={getattr(self, key)!r} must be true or false")
        self._check_step_size("lr")
        if self.lr_min is not None and not (
            isinstance(self.lr_min, (int, float)) and not isinstance(self.lr_min, bool) and 0 <= self.lr_min <= self.lr
        ):
            raise ConfigError(f"{self.name}: lr_min={self.lr_min!r} must be a number in [0, lr={self.lr}]")
        self._check_val_fraction()
        self._check_clip()
        self._check_seed_device(check_device)

    @property
    def lag(self) -> int:
        return max(int(self.ny), int(self.nu))

    def _build(self, n_in: int, n_out: int) -> SubnetModel:
        return SubnetModel(
            self.nx,
            n_in,
            n_out,
            self.ny,
            self.nu,
            self.f_hidden,
            self.h_hidden,
            self.e_hidden,
            self.activation,
            bool(self.feedthrough),
        )

    # ------------------------------------------------------------------ fit
    def fit(self, data: Record | Sequence[Record]) -> SSEncoder:
        """Train on one Record or a list (separate experiments). Returns self."""
        self._check_params()
        recs = as_record_list(data)
        lag, T = self.lag, int(self.T)
        n_in, n_out = check_channels(recs, lag, self.name)  # channels (not lags)
        val_recs: list[Record] = []
        if self.val_fraction:
            last = recs[-1]
            cut = len(last) - int(round(self.val_fraction * len(last)))
            if cut < lag + T or len(last) - cut < 1:
                raise DataError(
                    f"{self.name}: val_fraction={self.val_fraction} leaves {cut} training samples of "
                    f"{last.source}, need lag + T = {lag + T}; lower val_fraction, T or ny/nu"
                )
            val_recs = [last[cut - lag :]]  # the held-out tail with its encoder window
            recs = [*recs[:-1], last[:cut]]
        device, gen, pairs = self._start_fit(recs)
        if not any(u.shape[0] >= lag + T for u, _ in pairs):
            raise DataError(f"{self.name}: no estimation record has lag + T = {lag + T} samples; lower T or ny/nu")
        model = self._build(n_in, n_out).to(device)
        res = train_simulation(
            model,
            pairs,
            lag,
            T,
            int(self.epochs),
            int(self.batch_size),
            float(self.lr),
            val=normalised_pairs(val_recs, self.normaliser_) if val_recs else None,
            patience=int(self.patience),
            clip=float(self.clip),
            generator=gen,
            device=device,
            lr_min=None if self.lr_min is None else float(self.lr_min),
            log=lambda msg: _LOG.info("%s: %s", self.name, msg),
            cuda_graphs=bool(self.cuda_graphs),
        )
        self.weights_ = export_weights(model)
        self.n_parameters_ = int(sum(p.numel() for p in model.parameters()))
        self._end_fit(res, n_in, n_out, lag, device)
        return self

    # ------------------------------------------------------------------ predict
    def initial_state(self, record: Record, at: int | None = None) -> np.ndarray:
        """The encoder's state estimate x(at) (normalised-model coordinates) from the ``lag`` samples before
        ``at`` (default: ``at = lag``, the first simulated sample of a free run)."""
        self._check_fitted()
        lag = self.max_lag_
        at = lag if at is None else int(at)
        if not lag <= at <= len(record):
            raise DataError(f"{record.source}: state at sample {at} needs {lag} samples before it")
        ((un, yn),) = normalised_pairs([record], self.normaliser_)
        return encode_np(
            self.weights_, yn[None, at - lag : at], un[None, at - lag : at], self.ny, self.nu, _ACT_NP[self.activation]
        )[0]

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """Free run (``None``) or k-step-ahead at every sample (``horizon=k``). Shaped like ``record.y``."""
        self._check_fitted()
        check_predict_input(self, record, horizon)
        lag, n = self.max_lag_, len(record)
        ((un, yn),) = normalised_pairs([record], self.normaliser_)
        act = _ACT_NP[self.activation]
        yhat = yn.copy()
        self.diverged_at_ = None
        if horizon is None or horizon >= n - lag:
            x0 = encode_np(self.weights_, yn[None, :lag], un[None, :lag], self.ny, self.nu, act)
            out, div = simulate_np(self.weights_, x0, un[None, lag:], bool(self.feedthrough), DIVERGENCE_BOUND, act)
            yhat[lag:] = out[0]
            if div >= 0:
                self.diverged_at_ = lag + div
                warnings.warn(
                    f"{self.name}: free-run simulation diverged at sample {lag + div} of {n}; the rest is nan",
                    DivergenceWarning,
                    stacklevel=2,
                )
        else:
            k = int(horizon)
            targets = np.arange(lag, n)
            t0 = np.maximum(targets - k + 1, lag)  # first simulated sample of each target's run
            steps = targets - t0  # index of the target in its run (< k)
            chunk = max(1, 2_000_000 // max(1, k * (int(self.nx) + 64)))
            for a in range(0, targets.size, chunk):
                sl = slice(a, a + chunk)
                s0 = t0[sl]
                past = s0[:, None] + np.arange(-lag, 0)[None, :]
                x = encode_np(self.weights_, yn[past], un[past], self.ny, self.nu, act)
                idx = np.clip(s0[:, None] + np.arange(k)[None, :], 0, n - 1)
                out, _ = simulate_np(self.weights_, x, un[idx], bool(self.feedthrough), np.inf, act)
                yhat[targets[sl]] = out[np.arange(out.shape[0]), steps[sl]]
            bad = ~(np.isfinite(yhat).all(axis=1) & (np.abs(yhat) <= DIVERGENCE_BOUND).all(axis=1))
            if bad.any():
                first = int(np.flatnonzero(bad)[0])
                self.diverged_at_ = first
                yhat[bad] = np.nan
                warnings.warn(
                    f"{self.name}: {int(bad.sum())} non-finite {k}-step predictions, first at sample {first}",
                    DivergenceWarning,
                    stacklevel=2,
                )
        return self._in_units(yhat, record)  # the encoder window is the measurement

    # ------------------------------------------------------------------ description / persistence
    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "weights_"):
            d.update(
                {
                    "structure": {
                        "nx": self.nx,
                        "ny": self.ny,
                        "nu": self.nu,
                        "f_hidden": list(self.f_hidden),
                        "h_hidden": list(self.h_hidden),
                        "e_hidden": list(self.e_hidden),
                        "activation": self.activation,
                        "feedthrough": bool(self.feedthrough),
                    },
                    **self._training_summary(),
                }
            )
        return d

    def _state(self) -> dict[str, Any]:
        self._check_fitted()
        flat = {}
        for part, g in self.weights_.items():
            flat[f"{part}.W"], flat[f"{part}.b"] = g["W"], g["b"]
            for i, (W, b) in enumerate(g["layers"]):
                flat[f"{part}.{i}.W"], flat[f"{part}.{i}.b"] = W, b
        return {"weights": flat, **self._common_state()}

    def _load_state(self, state: dict[str, Any]) -> None:
        self._check_params(check_device=False)
        self._load_common(state, self.lag)
        ref = export_weights(self._build(self.n_inputs_, self.n_outputs_))
        flat = state["weights"]

        def get(key: str, like: np.ndarray) -> np.ndarray:
            return saved_array(self.name, flat, key, like.shape)

        self.weights_ = {
            part: {
                "W": get(f"{part}.W", g["W"]),
                "b": get(f"{part}.b", g["b"]),
                "layers": [(get(f"{part}.{i}.W", W), get(f"{part}.{i}.b", b)) for i, (W, b) in enumerate(g["layers"])],
            }
            for part, g in ref.items()
        }
        self.n_parameters_ = int(
            sum(
                g["W"].size + g["b"].size + sum(W.size + b.size for W, b in g["layers"]) for g in self.weights_.values()
            )
        )
