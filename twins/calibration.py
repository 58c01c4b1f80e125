"""Calibration of a twin's parameters by free-run output error (scipy.optimize.least_squares).

Generic over twins: the parameters to fit are named fields of the twin's parameter dataclass; each is
scaled to its documented range so the optimiser sees unit-sized steps, and bounded by that range.
Standard errors come from the Gauss–Newton covariance s²(JᵀJ)⁻¹ at the optimum (J of the residual with
respect to the physical parameters), which is the usual asymptotic estimate for output-error fits.

Parameters that enter the output additively and linearly — a twin lists them in ``OUTPUT_LINEAR_PARAMS`` and
gives their basis with ``output_basis(name, n, fs)`` (e.g. the coefficients of a slow drift) — are not searched:
for every value of the other parameters they are solved by linear least squares on the residual of the simulation
without them (variable projection, Golub & Pereyra 1973), so the search sees only the nonlinear parameters. A
parameter that shapes only that basis (``OUTPUT_BASIS_SHAPE_PARAMS``, e.g. the period of a slow cycle) starts from
the best point of a log grid over its range: the simulation without the linear terms does not depend on it, so the
grid costs one simulation and a small least-squares solve per point (its cost has many local minima).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, Generic, Protocol, Self, TypeVar

import numpy as np

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.evaluation.metrics import nrmse, r2
from twins.paramfields import param_info


class Calibratable(Protocol):
    """What a calibration needs of a twin (:class:`twins.base.Twin` is one): its name, effects and parameter
    dataclass, a copy with some parameters changed, and a simulation of an input at a rate ``fs`` [Hz]."""

    name: ClassVar[str]
    params: Any

    @property
    def effects(self) -> frozenset[str]: ...

    def with_params(self, **changes: Any) -> Self: ...

    def simulate(self, u: np.ndarray, fs: float) -> np.ndarray: ...


Twin = TypeVar("Twin", bound=Calibratable)

__all__ = ["CalibrationResult", "calibrate", "check_calibration_data"]


@dataclass
class CalibrationResult(Generic[Twin]):
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
) -> CalibrationResult[Twin]:
    """Fit ``names`` of ``twin.params`` to ``data`` by free-run output error; score on ``data`` and ``val``.

    ``simulate(twin, record)`` defaults to ``twin.simulate(record.u, record.fs)``; pass a noise-free variant
    to fit against a deterministic simulation. ``skip`` leading samples are not scored (transients).
    """
    names = list(names)
    check_calibration_data(data, names)
    sim = simulate or (lambda tw, rec: tw.simulate(rec.u, rec.fs))
    lin = _linear_params(twin, names, data)
    if lin:
        return _calibrate_projected(twin, data, names, lin, val, skip, x0, sim, max_nfev, **lsq_options)
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
    from scipy.optimize import least_squares  # here: twins.base imports this module, and the CLI starts without scipy

    res = least_squares(
        residual, np.zeros(len(names)), bounds=(zlo, zhi), x_scale=1.0, max_nfev=max_nfev, **lsq_options
    )
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


def _linear_params(twin: Twin, names: Sequence[str], data: Record) -> list[str]:
    """The ``names`` the twin declares additive and linear in its output, where their basis acts (single output)."""
    declared = getattr(type(twin), "OUTPUT_LINEAR_PARAMS", ())
    basis = getattr(twin, "output_basis", None)
    if not declared or not callable(basis) or data.n_outputs != 1:
        return []
    return [n for n in names if n in declared and basis(n, 2, data.fs) is not None]


def _calibrate_projected(
    twin: Twin,
    data: Record,
    names: list[str],
    lin: list[str],
    val: Record | None,
    skip: int,
    x0: dict[str, float] | None,
    sim: Callable,
    max_nfev: int,
    **lsq_options: Any,
) -> CalibrationResult:
    """:func:`calibrate` with the linear parameters ``lin`` solved by least squares inside every evaluation
    (module docstring); the solution is clipped to their documented ranges."""
    nl = [n for n in names if n not in lin]
    y = np.asarray(data.output, dtype=float).reshape(-1)[skip:]
    ysd = float(np.std(y)) or 1.0
    lo_l, hi_l = _bounds(twin, lin)
    zero = {n: float(np.clip(0.0, a, b)) for n, a, b in zip(lin, lo_l, hi_l)}
    count = [0]

    def project(tw: Twin) -> tuple[Twin, np.ndarray, np.ndarray]:
        """The twin with the linear parameters solved, its residual (scaled) and the basis."""
        count[0] += 1
        base = tw.with_params(**zero)
        yh0 = np.asarray(sim(base, data), dtype=float).reshape(-1)[skip:]
        B = _basis(base, lin, data, skip)
        r0 = y - yh0
        if not (np.all(np.isfinite(r0)) and np.all(np.isfinite(B))):
            return base, np.full(y.shape, 1e3), B
        c = np.linalg.lstsq(B, r0 - B @ np.array([zero[n] for n in lin]), rcond=None)[0]
        c = np.clip(c + np.array([zero[n] for n in lin]), lo_l, hi_l)
        fitted = base.with_params(**{n: float(v) for n, v in zip(lin, c)})
        return fitted, (B @ (c - np.array([zero[n] for n in lin])) - r0) / ysd, B

    t0 = time.perf_counter()
    x0 = _shape_grid_start(twin, data, nl, lin, zero, x0, sim, y, skip)
    if nl:
        lo, hi = _bounds(twin, nl)
        start = np.clip(np.array([float((x0 or {}).get(n, getattr(twin.params, n))) for n in nl]), lo, hi)
        finite = np.isfinite(lo) & np.isfinite(hi)
        scale = np.where(finite, hi - lo, np.maximum(np.abs(start), 1.0))

        def build(z: np.ndarray) -> Twin:
            return twin.with_params(**{n: float(v) for n, v in zip(nl, start + z * scale)})

        from scipy.optimize import least_squares

        res = least_squares(
            lambda z: project(build(z))[1],
            np.zeros(len(nl)),
            bounds=((lo - start) / scale, (hi - start) / scale),
            x_scale=1.0,
            max_nfev=max_nfev,
            **lsq_options,
        )
        fitted_twin, r, B = project(build(res.x))
        jac = res.jac / scale[None, :] * ysd
        message = str(res.message)
    else:
        fitted_twin, r, B = project(twin)
        jac, message = np.zeros((y.size, 0)), "linear least squares"
    J = np.column_stack([jac, B])  # d(yhat)/d(param), nonlinear then linear
    s2 = float(np.sum((r * ysd) ** 2)) / max(y.size - len(names), 1)
    try:
        cov = s2 * np.linalg.pinv(J.T @ J)
        stderr = {n: float(np.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(nl + lin)}
    except np.linalg.LinAlgError:
        stderr = {n: float("nan") for n in names}
    scores = {"estimation": _score(fitted_twin, data, sim, skip)}
    if val is not None:
        scores["validation"] = _score(fitted_twin, val, sim, skip)
    return CalibrationResult(
        twin=fitted_twin,
        fitted={n: float(getattr(fitted_twin.params, n)) for n in names},
        stderr=stderr,
        scores=scores,
        n_evaluations=count[0],
        seconds=time.perf_counter() - t0,
        message=message,
    )


def _basis(twin: Twin, lin: list[str], data: Record, skip: int) -> np.ndarray:
    """Columns d ŷ/d p for the linear parameters ``lin`` after ``skip`` samples (the twin's ``output_basis``)."""
    basis: Callable[[str, int, float], Any] = getattr(twin, "output_basis", None) or (lambda n, k, fs: np.zeros(k))
    return np.column_stack([np.asarray(basis(n, len(data), data.fs), dtype=np.float64)[skip:] for n in lin])


def _shape_grid_start(
    twin: Twin,
    data: Record,
    nl: list[str],
    lin: list[str],
    zero: dict[str, float],
    x0: dict[str, float] | None,
    sim: Callable,
    y: np.ndarray,
    skip: int,
    points: int = 60,
) -> dict[str, float] | None:
    """``x0`` with each basis-shape parameter among ``nl`` set to the best point of a log grid over its range (the
    other parameters at ``x0``); unchanged when the twin declares none."""
    shape = [n for n in nl if n in getattr(type(twin), "OUTPUT_BASIS_SHAPE_PARAMS", ())]
    if not shape:
        return x0
    start = {n: float((x0 or {}).get(n, getattr(twin.params, n))) for n in nl}
    base = twin.with_params(**{**start, **zero})
    r0 = y - np.asarray(sim(base, data), dtype=float).reshape(-1)[skip:]
    if not np.all(np.isfinite(r0)):
        return x0
    out = dict(x0 or {})
    for name in shape:
        lo_s, hi_s = _bounds(twin, [name])
        a, b = float(lo_s[0]), float(hi_s[0])
        grid = np.geomspace(a, b, points) if a > 0 and np.isfinite(b) else np.linspace(a, b, points)
        best, best_cost = start[name], np.inf
        for v in [start[name], *grid]:
            tw = base.with_params(**{name: float(v)})
            B = _basis(tw, lin, data, skip)
            c = np.linalg.lstsq(B, r0, rcond=None)[0]
            cost = float(np.sum((r0 - B @ c) ** 2))
            if cost < best_cost:
                best, best_cost = float(v), cost
        out[name] = start[name] = best
        base = base.with_params(**{name: best})
    return out


def _score(twin: Twin, rec: Record, sim: Callable, skip: int) -> dict[str, float]:
    rec.require_output()
    yh = sim(twin, rec)
    return {"r2": r2(rec.y, yh, skip), "nrmse": nrmse(rec.y, yh, skip)}
