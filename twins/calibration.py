"""Calibration of a twin's parameters by free-run output error (scipy.optimize.least_squares).

Generic over twins: the parameters to fit are named fields of the twin's parameter dataclass; each is
scaled to its documented range so the optimiser sees unit-sized steps, and bounded by that range.
Standard errors come from the Gauss–Newton covariance s²(JᵀJ)⁻¹ at the optimum (J of the residual with
respect to the physical parameters), which is the usual asymptotic estimate for output-error fits.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.optimize import least_squares

from sysid.errors import ConfigError, DataError
from sysid.metrics import nrmse, r2
from sysid.record import Record
from twins.paramfields import param_info

if TYPE_CHECKING:  # annotations only: twins.base calls calibrate() from Twin.calibrate
    from twins.base import Twin

__all__ = ["CalibrationResult", "calibrate", "check_calibration_data"]


@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate`: the fitted twin, parameter values with standard errors and scores."""

    twin: Twin
    fitted: dict[str, float]
    stderr: dict[str, float]
    scores: dict[str, dict[str, float]] = field(default_factory=dict)  # {"estimation": {r2, nrmse}, "validation": ...}
    n_evaluations: int = 0
    seconds: float = 0.0
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        info = param_info(type(self.twin.params))
        return {
            "twin": self.twin.name,
            "effects": sorted(self.twin.effects),
            "parameters": {
                k: {"value": v, "stderr": self.stderr.get(k), "unit": info[k].unit} for k, v in self.fitted.items()
            },
            "scores": self.scores,
            "n_evaluations": self.n_evaluations,
            "seconds": self.seconds,
            "message": self.message,
        }


def check_calibration_data(data: Record, names: Sequence[str], what: str = "calibration") -> None:
    """Refuse a fit that cannot be made: no output, no parameter named, no more samples than parameters (no
    residual degrees of freedom for the standard errors), or a constant output (nothing to fit, R² undefined)."""
    data.require_output()
    if not names:
        raise ConfigError(f"{what}: no parameters to fit")
    if len(data) <= len(names):
        raise DataError(f"{data.source}: {len(data)} samples are too few to fit {len(names)} parameters")
    if np.any(np.ptp(data.output, axis=0) == 0):
        raise DataError(f"{data.source}: output y is constant; nothing to fit")


def _bounds(twin: Twin, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    info = param_info(type(twin.params))
    lo, hi = [], []
    for n in names:
        if n not in info:
            raise ConfigError(f"cannot fit unknown parameter {n!r}; valid: {', '.join(info)}")
        a, b = info[n].range
        a = -np.inf if a is None else float(a)
        b = np.inf if b is None else float(b)
        lo.append(a)
        hi.append(b)
    return np.array(lo), np.array(hi)


def calibrate(
    twin: Twin,
    data: Record,
    names: Sequence[str],
    val: Record | None = None,
    skip: int = 0,
    x0: dict[str, float] | None = None,
    simulate: Callable[[Twin, Record], np.ndarray] | None = None,
    max_nfev: int = 200,
    **lsq_options: Any,
) -> CalibrationResult:
    """Fit ``names`` of ``twin.params`` to ``data`` by free-run output error; score on ``data`` and ``val``.

    ``simulate(twin, record)`` defaults to ``twin.simulate(record.u, record.fs)``; pass a noise-free variant
    to fit against a deterministic simulation. ``skip`` leading samples are not scored (transients).
    """
    names = list(names)
    check_calibration_data(data, names)
    sim = simulate or (lambda tw, rec: tw.simulate(rec.u, rec.fs))
    lo, hi = _bounds(twin, names)
    start = np.array([float((x0 or {}).get(n, getattr(twin.params, n))) for n in names])
    start = np.clip(start, lo, hi)
    finite = np.isfinite(lo) & np.isfinite(hi)
    scale = np.where(finite, hi - lo, np.maximum(np.abs(start), 1.0))
    y = np.asarray(data.y, dtype=float)[skip:]
    ysd = float(np.std(y)) or 1.0
    count = [0]

    def build(x: np.ndarray) -> Twin:
        return twin.with_params(**{n: float(v) for n, v in zip(names, x)})

    def residual(z: np.ndarray) -> np.ndarray:
        count[0] += 1
        yh = sim(build(start + z * scale), data)[skip:]
        r = (yh - y) / ysd
        if not np.all(np.isfinite(r)):
            return np.full(r.shape, 1e3)
        return r.ravel()

    t0 = time.perf_counter()
    zlo, zhi = (lo - start) / scale, (hi - start) / scale
    res = least_squares(residual, np.zeros(len(names)), bounds=(zlo, zhi), x_scale=1.0, max_nfev=max_nfev,
                        **lsq_options)
    x = start + res.x * scale
    fitted_twin = build(x)
    # Standard errors: covariance of the physical parameters from the scaled Jacobian.
    stderr: dict[str, float] = {}
    J = res.jac / scale[None, :] * ysd  # d(yhat)/d(param) in output units
    dof = max(y.size - len(names), 1)
    s2 = float(np.sum((res.fun * ysd) ** 2)) / dof
    try:
        cov = s2 * np.linalg.pinv(J.T @ J)
        for i, n in enumerate(names):
            stderr[n] = float(np.sqrt(max(cov[i, i], 0.0)))
    except np.linalg.LinAlgError:
        stderr = {n: float("nan") for n in names}
    scores = {"estimation": _score(fitted_twin, data, sim, skip)}
    if val is not None:
        scores["validation"] = _score(fitted_twin, val, sim, skip)
    return CalibrationResult(
        twin=fitted_twin,
        fitted={n: float(v) for n, v in zip(names, x)},
        stderr=stderr,
        scores=scores,
        n_evaluations=count[0],
        seconds=time.perf_counter() - t0,
        message=str(res.message),
    )


def _score(twin: Twin, rec: Record, sim: Callable, skip: int) -> dict[str, float]:
    rec.require_output()
    yh = sim(twin, rec)
    return {"r2": r2(rec.y, yh, skip), "nrmse": nrmse(rec.y, yh, skip)}
