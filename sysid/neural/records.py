"""What every neural identifier does with its records before and after the network: scale them (one mean and
SD per channel over all estimation records), turn them into 2-D arrays, and check them — for fitting (channels,
finite values, length against the lags) and for prediction (the fitted channel counts, a valid horizon).
Shared by :mod:`sysid.neural.narx_mlp`, :mod:`sysid.neural.rnn` and :mod:`sysid.neural.ss_encoder`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sysid.base import Identifier, check_records
from sysid.data.record import Normaliser, Record
from sysid.errors import ConfigError, DataError

__all__ = [
    "MAX_LAG",
    "DIVERGENCE_BOUND",
    "normalised_pairs",
    "fit_normaliser",
    "check_channels",
    "check_predict_input",
    "hidden_widths",
]

MAX_LAG = 1024
# A simulated output beyond this many standard deviations of the estimation output is a divergence.
DIVERGENCE_BOUND = 1e3


def _as2d(a: np.ndarray) -> np.ndarray:
    return a[:, None] if a.ndim == 1 else a


def normalised_pairs(recs: Sequence[Record], norm: Normaliser | None) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    for r in recs:
        u = norm.transform_u(r.u) if norm is not None else r.u
        y = norm.transform_y(r.output) if norm is not None else r.output
        out.append((_as2d(np.asarray(u, dtype=float)), _as2d(np.asarray(y, dtype=float))))
    return out


def fit_normaliser(recs: Sequence[Record]) -> Normaliser:
    """Scale from all estimation records together (one mean and SD per channel)."""
    return Normaliser().fit(list(recs))


def check_channels(recs: Sequence[Record], max_lag: int, what: str) -> tuple[int, int]:
    """The shared identifier data checks (channels, NaN/inf, length vs lags, constant input/output), then
    the numbers of inputs and outputs."""
    check_records(recs, max_lag, 1, what)
    return recs[0].n_inputs, recs[0].n_outputs


def check_predict_input(model: Identifier, record: Record, horizon: int | None) -> None:
    """Checks shared by the neural models' ``predict``: an output to compare with, the fitted channel counts,
    more samples than the model's lag, and a horizon that is a positive integer or ``None`` (free run)."""
    record.require_output()
    if (record.n_inputs, record.n_outputs) != (model.n_inputs_, model.n_outputs_):
        raise DataError(
            f"{record.source}: {record.n_inputs} inputs / {record.n_outputs} outputs, model has "
            f"{model.n_inputs_} / {model.n_outputs_}"
        )
    if len(record) <= model.max_lag_:
        raise DataError(f"{record.source}: {len(record)} samples, need more than the model's lag {model.max_lag_}")
    if horizon is not None and (not isinstance(horizon, (int, np.integer)) or isinstance(horizon, bool) or horizon < 1):
        raise ConfigError(f"{model.name}: horizon must be a positive integer or None (free run), got {horizon!r}")


def hidden_widths(v, key: str, name: str) -> list[int]:
    """Hidden layer widths of a network option ``key`` of identifier ``name``: an int (``0``: none), a list, or
    ``[0]`` (what ``--set key=0`` gives) for none; each width 1 … 65536."""
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        v = [v] if v > 0 else []
    if isinstance(v, (list, tuple)) and len(v) == 1 and isinstance(v[0], (int, np.integer)) and v[0] == 0:
        v = []
    if not isinstance(v, (list, tuple)) or not all(
        isinstance(w, (int, np.integer)) and not isinstance(w, bool) and 1 <= w <= 65536 for w in v
    ):
        raise ConfigError(f"{name}: {key}={v!r} must be a list of hidden widths (e.g. 64 or 64-64; 0 or [] for none)")
    return [int(w) for w in v]
