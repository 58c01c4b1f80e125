"""Validation metrics (dissertation §2.8).

All functions take the measured ``y`` and the predicted ``y_hat`` (same shape) and an optional ``skip``: the
number of leading samples that are initial conditions copied from the measurement (a model's ``max_lag_``)
and must not be scored. Non-finite predictions (a diverged free run) give ``nan`` scores, never an exception.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["r2", "mse", "rmse", "nrmse", "fit_percent", "score"]


def _prep(y: Any, y_hat: Any, skip: int = 0) -> tuple[np.ndarray, np.ndarray]:
    y = np.asarray(y, dtype=float)
    y_hat = np.asarray(y_hat, dtype=float)
    if y.shape != y_hat.shape:
        raise ValueError(f"y and y_hat have different shapes {y.shape} and {y_hat.shape}")
    return y[skip:], y_hat[skip:]


def mse(y, y_hat, skip: int = 0) -> float:
    """Mean squared error."""
    y, y_hat = _prep(y, y_hat, skip)
    return float(np.mean((y - y_hat) ** 2))


def rmse(y, y_hat, skip: int = 0) -> float:
    """Root mean squared error, in the units of y."""
    return float(np.sqrt(mse(y, y_hat, skip)))


def r2(y, y_hat, skip: int = 0) -> float:
    """Coefficient of determination R² = 1 − Σ(y−ŷ)² / Σ(y−ȳ)² (dissertation eq. 2-31)."""
    y, y_hat = _prep(y, y_hat, skip)
    ss_res = float(np.sum((y - y_hat) ** 2))
    ss_tot = float(np.sum((y - y.mean(axis=0)) ** 2))
    if ss_tot == 0.0:
        return float("nan")
    return 1.0 - ss_res / ss_tot


def nrmse(y, y_hat, skip: int = 0) -> float:
    """RMSE normalised by the standard deviation of y (so NRMSE² = 1 − R² for the same samples)."""
    y, y_hat = _prep(y, y_hat, skip)
    sd = float(np.std(y))
    if sd == 0.0:
        return float("nan")
    return float(np.sqrt(np.mean((y - y_hat) ** 2)) / sd)


def fit_percent(y, y_hat, skip: int = 0) -> float:
    """MATLAB-style fit: 100·(1 − ‖y−ŷ‖ / ‖y−ȳ‖) %."""
    y, y_hat = _prep(y, y_hat, skip)
    den = float(np.linalg.norm(y - y.mean(axis=0)))
    if den == 0.0:
        return float("nan")
    return 100.0 * (1.0 - float(np.linalg.norm(y - y_hat)) / den)


def score(y, y_hat, skip: int = 0) -> dict[str, float]:
    """All metrics in one dict: ``r2, mse, rmse, nrmse, fit_percent`` (nan where the prediction is not finite)."""
    yy, yh = _prep(y, y_hat, skip)
    if yy.size == 0 or not np.isfinite(yh).all():
        nan = float("nan")
        return {"r2": nan, "mse": nan, "rmse": nan, "nrmse": nan, "fit_percent": nan}
    return {
        "r2": r2(yy, yh),
        "mse": mse(yy, yh),
        "rmse": rmse(yy, yh),
        "nrmse": nrmse(yy, yh),
        "fit_percent": fit_percent(yy, yh),
    }
