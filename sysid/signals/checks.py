"""Argument checks shared by the signal generators and the preprocessing functions: an array of floats with
time along axis 0, finite samples, an integer parameter, and the whole number of samples a duration spans."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sysid.errors import ConfigError, DataError


def _as_float(x: Any, name: str = "x") -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim not in (1, 2) or arr.shape[0] == 0:
        raise DataError(f"{name}: expected a non-empty 1-D or 2-D (samples x channels) array, got shape {arr.shape}")
    return arr


def _finite(x: np.ndarray, name: str) -> None:
    if not np.isfinite(x).all():
        raise DataError(f"{name}: has non-finite samples; fill missing samples first (fill_missing)")


def _int_param(name: str, value: Any, lo: int) -> int:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be an integer, got {value!r}") from None
    if not math.isfinite(v) or v != int(v) or v < lo:
        raise ConfigError(f"{name} must be an integer >= {lo}, got {value!r}")
    return int(v)


def _n_samples(fs: float, duration: float, what: str = "duration") -> int:
    n = fs * duration
    k = int(round(n))
    if k < 1:
        raise ConfigError(f"{what} {duration} s at fs={fs:g} Hz gives no samples")
    if abs(n - k) > 1e-6 * max(1.0, n):
        raise ConfigError(f"{what} {duration} s is not a whole number of samples at fs={fs:g} Hz ({n:g})")
    return k


def _integer_ratio(a: float, b: float, what: str) -> int:
    """``a / b`` as an integer, or a ConfigError."""
    r = a / b
    k = int(round(r))
    if k < 1 or abs(r - k) > 1e-9 * max(1.0, r):
        raise ConfigError(f"{what}: {a:g}/{b:g} = {r:.10g} is not an integer")
    return k
