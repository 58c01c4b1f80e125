"""What the neural sequence identifiers share around their networks: ``rnn``, ``ss-encoder`` and ``wh-net``.

:class:`SequenceIdentifier` holds the parts that are the same for the three: the option checks (integer ranges,
step sizes, hold-out fraction, clipping, seed, device), the set-up of a fit (threads, device, seeds, the
normaliser of the estimation records), the bookkeeping after it (training histories, channel counts, timings),
the conversion of a normalised prediction back to the record's units, and the histories in the saved state.
The training loops are in :mod:`sysid.neural.training`; each identifier keeps only its network, how the network
is built and read back, and its prediction.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from sysid.base import Identifier
from sysid.data.record import Normaliser, Record
from sysid.errors import ConfigError
from sysid.neural.device import configure_threads, select_device
from sysid.neural.persist import TorchFileSave
from sysid.neural.records import _as2d, fit_normaliser, normalised_pairs
from sysid.neural.training import SimTrainResult

__all__ = ["SequenceIdentifier"]


def _is_int(v: Any) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class SequenceIdentifier(TorchFileSave, Identifier):
    """Base of the neural sequence identifiers (see the module docstring). A subclass sets ``name`` and
    ``_fitted_attr`` (the learned attribute that marks a fitted model) and has ``seed`` and ``device`` options."""

    _fitted_attr = "weights_"

    # ------------------------------------------------------------------ checks
    def _check_int(self, key: str, lo: int, hi: int, none_ok: bool = False) -> None:
        """Option ``key`` is an integer in [lo, hi] (or ``None`` when ``none_ok``)."""
        v = getattr(self, key)
        if none_ok and v is None:
            return
        if not _is_int(v) or not lo <= v <= hi:
            raise ConfigError(f"{self.name}: {key}={v!r} must be an integer in [{lo}, {hi}]")

    def _check_step_size(self, key: str) -> None:
        """Option ``key`` is an Adam step size: a positive number below 10."""
        v = getattr(self, key)
        if not (_is_number(v) and 0 < v < 10):
            raise ConfigError(f"{self.name}: {key}={v!r} must be a positive number below 10")

    def _check_val_fraction(self) -> None:
        if not (_is_number(self.val_fraction) and 0 <= self.val_fraction <= 0.5):
            raise ConfigError(f"{self.name}: val_fraction={self.val_fraction!r} must be a fraction in [0, 0.5]")

    def _check_clip(self) -> None:
        if not (_is_number(self.clip) and self.clip >= 0):
            raise ConfigError(f"{self.name}: clip={self.clip!r} must be ≥ 0")

    def _check_seed_device(self, check_device: bool) -> None:
        """An integer seed and, when ``check_device``, a usable device (a saved model trained on a GPU must still
        load, and predict, on a CPU machine, so loading does not check it)."""
        if not _is_int(self.seed):
            raise ConfigError(f"{self.name}: seed={self.seed!r} must be an integer")
        if check_device:
            select_device(self.device)

    def _check_fitted(self) -> None:
        if not hasattr(self, self._fitted_attr):
            raise ConfigError(f"{self.name}: model is not fitted; call fit() first")

    # ------------------------------------------------------------------ fit
    def _start_fit(
        self, recs: Sequence[Record]
    ) -> tuple[torch.device, torch.Generator, list[tuple[np.ndarray, np.ndarray]]]:
        """Start the clocks, set the threads, pick the device, seed torch (the initial weights) and a generator
        (the order of the sections), and fit the normaliser on ``recs``: (device, generator, normalised pairs)."""
        self._clocks = (time.perf_counter(), time.process_time())
        configure_threads()
        device = select_device(self.device)
        torch.manual_seed(int(self.seed))
        gen = torch.Generator().manual_seed(int(self.seed))
        self.normaliser_ = fit_normaliser(recs)
        return device, gen, normalised_pairs(recs, self.normaliser_)

    def _end_fit(self, res: SimTrainResult, n_in: int, n_out: int, lag: int, device: torch.device) -> None:
        """Keep what training did (``res``) and what every fitted sequence model carries."""
        self.loss_history_ = res.loss_history
        self.val_history_ = res.val_history
        self.best_epoch_ = res.best_epoch
        self.n_inputs_, self.n_outputs_ = n_in, n_out
        self.max_lag_ = int(lag)
        self.device_used_ = str(device)
        self.cuda_graphs_ = bool(res.cuda_graphs)
        t0, c0 = self._clocks
        self.fit_seconds_ = time.perf_counter() - t0
        self.fit_cpu_seconds_ = time.process_time() - c0
        self.diverged_at_ = None

    # ------------------------------------------------------------------ predict
    def _in_units(self, yhat: np.ndarray, record: Record) -> np.ndarray:
        """A normalised prediction (N, ny) in the record's units and shape; the first ``max_lag_`` samples, which
        start the model, are the measurement."""
        out = self.normaliser_.inverse_y(yhat)
        y = record.output
        out[: self.max_lag_] = _as2d(y)[: self.max_lag_]
        return out[:, 0] if y.ndim == 1 else out

    # ------------------------------------------------------------------ description / persistence
    def _training_summary(self) -> dict[str, Any]:
        """The keys of :meth:`describe` about the training (epochs, kept epoch, last loss, best hold-out RMSE)."""
        return {
            "terms": [],
            "max_lag": self.max_lag_,
            "device": self.device_used_,
            "epochs_run": len(self.loss_history_),
            "best_epoch": self.best_epoch_,
            "final_loss": self.loss_history_[-1] if self.loss_history_ else None,
            "best_validation_rmse_normalised": min(self.val_history_) if self.val_history_ else None,
        }

    def _common_state(self) -> dict[str, Any]:
        """The saved-state entries every sequence model has besides its weights."""
        return {
            "normaliser": self.normaliser_.to_dict(),
            "n_inputs": int(self.n_inputs_),
            "n_outputs": int(self.n_outputs_),
            "loss_history": [float(v) for v in self.loss_history_],
            "val_history": [float(v) for v in self.val_history_],
            "best_epoch": None if self.best_epoch_ is None else int(self.best_epoch_),
            "device_used": self.device_used_,
            "fit_seconds": float(self.fit_seconds_),
        }

    def _load_common(self, state: dict[str, Any], lag: int) -> None:
        """Read back what :meth:`_common_state` wrote (older files may lack the histories)."""
        self.n_inputs_, self.n_outputs_ = int(state["n_inputs"]), int(state["n_outputs"])
        self.normaliser_ = Normaliser.from_dict(state["normaliser"])
        self.loss_history_ = [float(v) for v in state.get("loss_history", [])]
        self.val_history_ = [float(v) for v in state.get("val_history", [])]
        self.best_epoch_ = state.get("best_epoch")
        self.device_used_ = state.get("device_used", "cpu")
        self.fit_seconds_ = float(state.get("fit_seconds", float("nan")))
        self.max_lag_ = int(lag)
        self.diverged_at_ = None
