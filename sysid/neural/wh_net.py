"""Block-oriented Wiener–Hammerstein network (registry id ``wh-net``) trained on simulation error.

The model is :class:`sysid.neural.blocknet.BlockNet` (dynoNet, Forgione & Piga 2021):

    ŷ(t) = G2(q) F(G1(q) u(t)) [+ G0(q) u(t)],   G(q) = q^{-nk} B(q)/A(q) per input–output pair,

with G1 (input → ``channels``), the static network F (``channels`` → ``hidden`` tanh → ``channels``) and G2
(``channels`` → output) differentiable IIR layers (:mod:`sysid.neural.iir`), trained by
:func:`sysid.neural.training.train_records` on the free-run MSE of the whole normalised estimation records
(full batch, Adam with a cosine learning-rate schedule, early stopping on a held-out tail).

Initial state and prediction. Every record is simulated from rest: the filters' states start at zero at the
record's first sample (normalised units, i.e. at the estimation data's mean input and output). That start is a
transient, so the first ``warmup`` samples of each record are left out of the training loss, and ``max_lag_ =
warmup``: a prediction copies the first ``warmup`` measured outputs, and the benchmark scores a test from
``max(init window, warmup)`` on. With ``warmup`` equal to the benchmark's initialisation window (50 samples for
Wiener–Hammerstein), the filters run over the window's measured input from rest and the transient of the zero
initial state falls in the samples that are not scored.

The model is output-error: it never reads the measured output, so ``predict(record, k)`` for any horizon ``k``
(one step included) is the free run ``predict(record, None)``. Predictions are computed in float64 on the CPU.

``device``: the static network and the optimiser run on the chosen device; the IIR filtering is ``scipy.signal.lfilter``
on the CPU in any case (a sequential recursion over time), so a GPU gains little here.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from sysid._blas import blas_threads
from sysid.base import as_record_list
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.neural.blocknet import BlockNet
from sysid.neural.device import configure_threads
from sysid.neural.persist import saved_array
from sysid.neural.records import check_channels, check_predict_input, hidden_widths, normalised_pairs
from sysid.neural.sequence import SequenceIdentifier
from sysid.neural.training import train_records

__all__ = ["WHNet"]

_LOG = logging.getLogger(__name__)  # training progress at INFO (the library configures no handler)
_ACTIVATIONS = ("tanh", "relu", "sigmoid")
MAX_ORDER = 64


class WHNet(SequenceIdentifier):
    """dynoNet-style G1 → F → G2 block network trained on the free-run (simulation) error.

    Parameters
    ----------
    channels : int
        Outputs of G1 = inputs and outputs of F = inputs of G2 (the paper: a few to 16).
    hidden : list of int
        Hidden widths of the static network F (``0`` / ``[]``: F is affine).
    nb, na, nb2, na2 : int, int, int or None, int or None
        Numerator b_0 … b_{nb-1} and denominator a_1 … a_na of every pair of G1 and of the linear path, and of G2
        (``None``: as G1).
    nk : int
        Input delay of G1 and the linear path [samples] (0: direct feedthrough); ``linear``: add G0(q) u in parallel.
    activation : str
        ``tanh`` (the paper), ``relu`` or ``sigmoid``.
    warmup : int
        Leading samples of every record treated as the zero-start transient: out of the loss, copied from the
        measurement in predictions (``max_lag_``); the benchmark's initialisation window.
    epochs, lr, lr_min : int, float, float
        Adam epochs and the cosine schedule's first and last step sizes.
    val_fraction, patience : float, int
        Last share (0 … 0.5) of the last record held out for early stopping, and epochs without a better hold-out
        RMSE before stopping (0: none).
    window, batch : int
        0: one full-batch step per epoch; ``window > warmup``: per epoch as many steps as cover the training samples,
        each on ``batch`` random sections of ``window`` samples simulated from rest.
    seed, device :
        Seeds the initial weights; ``auto`` | ``cpu`` | ``cuda`` (:mod:`sysid.neural.device`).
    """

    name = "wh-net"
    _fitted_attr = "model_"

    def __init__(
        self,
        channels: int = 8,
        hidden: Sequence[int] = (16,),
        nb: int = 8,
        na: int = 8,
        nb2: int | None = None,
        na2: int | None = None,
        nk: int = 0,
        linear: bool = False,
        activation: str = "tanh",
        warmup: int = 50,
        epochs: int = 2000,
        lr: float = 1e-2,
        lr_min: float = 1e-4,
        val_fraction: float = 0.1,
        patience: int = 0,
        window: int = 0,
        batch: int = 16,
        seed: int = 0,
        device: str = "auto",
    ):
        self.channels = channels
        self.hidden = list(hidden) if isinstance(hidden, tuple) else hidden
        self.nb = nb
        self.na = na
        self.nb2 = nb2
        self.na2 = na2
        self.nk = nk
        self.linear = linear
        self.activation = activation
        self.warmup = warmup
        self.epochs = epochs
        self.lr = lr
        self.lr_min = lr_min
        self.val_fraction = val_fraction
        self.patience = patience
        self.window = window
        self.batch = batch
        self.seed = seed
        self.device = device

    # ------------------------------------------------------------------ checks
    def _check_params(self, check_device: bool = True) -> None:
        self._check_int("channels", 1, 1024)
        self._check_int("nb", 1, MAX_ORDER)
        self._check_int("na", 0, MAX_ORDER)
        self._check_int("nb2", 1, MAX_ORDER, none_ok=True)
        self._check_int("na2", 0, MAX_ORDER, none_ok=True)
        self._check_int("nk", 0, MAX_ORDER)
        self._check_int("warmup", 0, 1_000_000)
        self._check_int("epochs", 0, 10_000_000)
        self._check_int("patience", 0, 10_000_000)
        self._check_int("window", 0, 100_000_000)
        self._check_int("batch", 1, 100_000)
        if self.window and self.window <= self.warmup:
            raise ConfigError(
                f"{self.name}: window={self.window} must exceed warmup={self.warmup} (or be 0: full batch)"
            )
        self.hidden = hidden_widths(self.hidden, "hidden", self.name)
        if self.activation not in _ACTIVATIONS:
            raise ConfigError(f"{self.name}: activation={self.activation!r} not one of: {', '.join(_ACTIVATIONS)}")
        if not isinstance(self.linear, (bool, np.bool_)):
            raise ConfigError(f"{self.name}: linear={self.linear!r} must be true or false")
        self._check_step_size("lr")
        self._check_step_size("lr_min")
        if self.lr_min > self.lr:
            raise ConfigError(f"{self.name}: lr_min={self.lr_min!r} must not exceed lr={self.lr!r}")
        self._check_val_fraction()
        self._check_seed_device(check_device)

    def _build(self, n_in: int, n_out: int, generator: torch.Generator | None = None) -> BlockNet:
        nb2 = self.nb if self.nb2 is None else self.nb2
        na2 = self.na if self.na2 is None else self.na2
        return BlockNet(
            n_in,
            n_out,
            int(self.channels),
            int(self.channels),
            self.hidden,
            int(self.nb),
            int(self.na),
            int(nb2),
            int(na2),
            int(self.nk),
            bool(self.linear),
            self.activation,
            generator,
        )

    # ------------------------------------------------------------------ fit
    def fit(self, data: Record | Sequence[Record]) -> WHNet:
        """Train on one Record or a list (separate experiments, each simulated from rest). Returns self."""
        self._check_params()
        recs = as_record_list(data)
        warmup = int(self.warmup)
        n_in, n_out = check_channels(recs, warmup, self.name)
        last = len(recs[-1])
        cut = last - int(round(self.val_fraction * last))
        if self.val_fraction and (last - cut < 1 or sum(len(r) for r in recs[:-1]) + cut <= warmup * len(recs)):
            raise DataError(
                f"{self.name}: val_fraction={self.val_fraction} leaves no training samples after the "
                f"warm-up of {warmup} in {recs[-1].source}; lower val_fraction or warmup"
            )
        device, gen, pairs = self._start_fit(recs)
        model = self._build(n_in, n_out, gen).to(device)
        with blas_threads():
            res = train_records(
                model,
                pairs,
                warmup,
                int(self.epochs),
                float(self.lr),
                float(self.lr_min),
                float(self.val_fraction),
                int(self.patience),
                device=device,
                log=lambda msg: _LOG.info("%s: %s", self.name, msg),
                log_every=100,
                window=int(self.window),
                batch=int(self.batch),
                seed=int(self.seed),
            )
        self._set_weights(model.to("cpu"))
        self.restarts_ = res.restarts
        self._end_fit(res, n_in, n_out, warmup, device)
        return self

    def _set_weights(self, model: BlockNet) -> None:
        self.model_ = model.eval()
        for p in model.parameters():
            p.requires_grad_(False)
        self.n_parameters_ = int(sum(p.numel() for p in model.parameters()))

    # ------------------------------------------------------------------ predict
    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """Free-run simulation from rest, for every ``horizon`` (an output-error model: see the module docstring).
        Shaped like ``record.y``; the first ``max_lag_`` samples are the measurement."""
        self._check_fitted()
        check_predict_input(self, record, horizon)
        ((un, _),) = normalised_pairs([record], self.normaliser_)
        configure_threads()
        with torch.no_grad(), blas_threads():
            yn = self.model_(torch.as_tensor(un, dtype=torch.float64)[None])[0].numpy()
        self.diverged_at_ = None
        return self._in_units(yn, record)

    # ------------------------------------------------------------------ description / persistence
    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "model_"):
            d.update(
                {
                    "structure": {
                        "channels": int(self.channels),
                        "hidden": list(self.hidden),
                        "nb": self.nb,
                        "na": self.na,
                        "nb2": self.nb2,
                        "na2": self.na2,
                        "nk": self.nk,
                        "linear": bool(self.linear),
                        "activation": self.activation,
                    },
                    **self._training_summary(),
                }
            )
        return d

    def _state(self) -> dict[str, Any]:
        self._check_fitted()
        weights = {k: v.detach().cpu().numpy().astype(np.float64) for k, v in self.model_.state_dict().items()}
        return {"weights": weights, **self._common_state()}

    def _load_state(self, state: dict[str, Any]) -> None:
        self._check_params(check_device=False)
        self._load_common(state, int(self.warmup))
        model = self._build(self.n_inputs_, self.n_outputs_)
        model.load_state_dict(
            {
                key: torch.as_tensor(saved_array(self.name, state["weights"], key, tuple(like.shape)))
                for key, like in model.state_dict().items()
            }
        )
        self._set_weights(model)
        self.restarts_ = 0
