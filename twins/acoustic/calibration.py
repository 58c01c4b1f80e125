"""Calibration of the acoustic twin's stack (PZT, epoxy, steel thicknesses, gain, …) to measured data.

The stack's transmission is a sharply resonant function of the thicknesses, so an output-error fit of a
100 MHz time record from a distant start is hopelessly multimodal. The fit is therefore done on the
log-magnitude response, which is what the dissertation measured with the VNA (Figure 3.9):

- a ``vna-sweep`` record (u = frequency [Hz], y = 20 log10|H| [dB]) is fitted directly;
- a time record (u = generator voltage, y = Rx voltage) is first reduced to its H1 estimate
  Ĥ(f) = S_uy/S_uu (Welch) over the band the input excites, and 20 log10|2 G_v H(f)| is fitted to it
  (the amplifier's gain G_v and the Thevenin factor 2 are in the model). Scores are then computed on the
  time record by free-run simulation (noise-free twin, R² and NRMSE).

Parameters that do not shape the magnitude response (a temperature or distance offset moves only the
phase; wall-echo, crosstalk and misalignment parameters are better seen in time) are fitted to a time record
by free-run output error of the noise-free twin instead (:func:`twins.calibration.calibrate`, bounded by the
parameters' documented ranges, started from their current values — which must lie within about a period
of the band centre, ≈ 1 µs of time of flight, of the answer).

Search: a coarse grid over the thickness parameters (the answer is non-unique, notes B.7: the grid picks
the family nearest the start), then bounded least squares (scipy) within ±``span`` of the start.
Standard errors: Gauss–Newton s²(JᵀJ)⁻¹ at the optimum, as in :mod:`twins.calibration`.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterable
from typing import Any

import numpy as np
from scipy import signal as sps
from scipy.optimize import least_squares

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.evaluation.metrics import nrmse, r2
from twins.acoustic.amplifier import voltage_gain
from twins.base import param_info
from twins.calibration import CalibrationResult, check_calibration_data

__all__ = ["calibrate_acoustic", "measured_response_db", "is_frequency_record"]

_THICKNESS = ("pzt_thickness_m", "steel_thickness_m")
#: parameters fitted on the log-magnitude response; any other name sends a time record to output error
MAGNITUDE_PARAMS = frozenset(
    {
        "pzt_thickness_m",
        "steel_thickness_m",
        "epoxy_thickness_m",
        "output_gain",
        "pzt_qm",
        "backing_rayl",
        "rx_load_ohm",
        "rx_load_capacitance_f",
        "source_resistance_ohm",
        "aperture_radius_m",
        "plate_width_m",
        "plate_height_m",
    }
)
_NOISE_EFFECTS = ("measurement_noise", "adc_quantization")


def is_frequency_record(rec: Record) -> bool:
    return rec.units.get("u") == "Hz" or rec.meta.get("kind") == "frequency_response"


def measured_response_db(
    rec: Record, amp_gain_db: float, nperseg: int | None = None, band: tuple[float, float] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(f, 20 log10|Ĥ_chain|) of a time record: H1 estimate of y/u divided by the amplifier's 2·G_v.

    Only frequencies where the input spectrum is within 20 dB of its maximum (or inside ``band``) are kept.
    """
    rec.require_output()
    n = len(rec)
    seg = nperseg or int(min(n, 1 << 14))
    f, puu = sps.welch(rec.u, rec.fs, nperseg=seg)
    _, puy = sps.csd(rec.u, rec.y, rec.fs, nperseg=seg)
    keep = puu > puu.max() * 1e-2
    if band is not None:
        keep &= (f >= band[0]) & (f <= band[1])
    keep &= f > 0
    if keep.sum() < 3:
        raise DataError(f"{rec.source}: the input excites fewer than 3 frequency bins; cannot estimate a response")
    h = puy[keep] / puu[keep] / (2.0 * voltage_gain(amp_gain_db))
    return f[keep], 20 * np.log10(np.abs(h) + 1e-300)


def _bounds(twin, names: list[str], span: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    info = param_info(type(twin.params))
    lo, hi, x0 = [], [], []
    for n in names:
        if n not in info:
            raise ConfigError(f"cannot fit unknown parameter {n!r}; valid: {', '.join(info)}")
        v = getattr(twin.params, n)
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            raise ConfigError(f"cannot fit non-numeric parameter {n!r}")
        a, b = info[n].range
        a = -np.inf if a is None else float(a)
        b = np.inf if b is None else float(b)
        v = float(v)
        if n == "output_gain" or n.endswith("_gain"):
            la, lb = v / 30.0, v * 30.0
        elif n == "epoxy_thickness_m":
            la, lb = 0.0, max(3.0 * v, 50e-6)
        elif v != 0:
            la, lb = v * (1 - span), v * (1 + span)
            la, lb = min(la, lb), max(la, lb)
        else:
            la, lb = a, b
        lo.append(max(a, la))
        hi.append(min(b, lb))
        x0.append(min(max(v, lo[-1]), hi[-1]))
    return np.array(lo), np.array(hi), np.array(x0)


def calibrate_acoustic(
    twin,
    data: Record,
    val: Record | None = None,
    names: Iterable[str] | None = None,
    span: float = 0.15,
    grid: int = 21,
    max_nfev: int = 200,
    **_: Any,
) -> CalibrationResult:
    """Fit ``names`` (default ``twin.CALIBRATION_PARAMS``) of ``twin`` to ``data`` (see module docstring)."""
    names = list(names) if names is not None else list(twin.CALIBRATION_PARAMS)
    check_calibration_data(data, names, "acoustic calibration")
    if data.u.ndim != 1 or data.output.ndim != 1:
        raise ConfigError("acoustic calibration: data must be SISO (one drive voltage, one received voltage)")
    freq_mode = is_frequency_record(data)
    if not freq_mode and not set(names) <= MAGNITUDE_PARAMS:
        from twins.calibration import calibrate as output_error

        clean = twin.with_effects(twin.effects - set(_NOISE_EFFECTS))
        res = output_error(clean, data, names, val=val, max_nfev=max_nfev)
        fitted = twin.with_params(**{n: getattr(res.twin.params, n) for n in names})
        res.twin = fitted
        res.message = f"time-domain output error (noise-free twin): {res.message}"
        return res
    if freq_mode:
        f, target = np.asarray(data.u, float), np.asarray(data.y, float)
        gated = bool(data.meta.get("protocol_options", {}).get("gated", False))
        model_gain = 1.0
    else:
        f, target = measured_response_db(data, twin.params.amp_gain_db)
        gated = False
        model_gain = 1.0  # measured_response_db already divides by the amplifier's 2·G_v
    if np.any(f <= 0):
        raise DataError(f"{data.source}: frequency record has non-positive frequencies")
    lo, hi, x0 = _bounds(twin, names, span)
    scale = np.where(np.isfinite(hi - lo) & (hi > lo), hi - lo, np.maximum(np.abs(x0), 1.0))
    count = [0]
    sd = float(np.std(target)) or 1.0

    def build(x):
        return twin.with_params(**{n: (type(getattr(twin.params, n))(v)) for n, v in zip(names, x)})

    def model_db(tw) -> np.ndarray:
        h = tw.frequency_response(f, include_amplifier=not freq_mode, direct_only=gated)
        return 20 * np.log10(np.abs(h * model_gain) + 1e-300)

    def residual(z):
        count[0] += 1
        r = (model_db(build(x0 + z * scale)) - target) / sd
        return np.where(np.isfinite(r), r, 1e3)

    t0 = time.perf_counter()
    # coarse grid over the resonance-setting thicknesses (non-unique optimum: start from the best cell)
    start = np.zeros(len(names))
    thick = [i for i, n in enumerate(names) if n in _THICKNESS]
    if thick and grid > 1:
        axes = [np.linspace((lo[i] - x0[i]) / scale[i], (hi[i] - x0[i]) / scale[i], grid) for i in thick]
        best = (np.inf, start)
        for cell in itertools.product(*axes):
            z = start.copy()
            z[thick] = cell
            cost = float(np.sum(residual(z) ** 2))
            if cost < best[0]:
                best = (cost, z)
        start = best[1]
    res = least_squares(residual, start, bounds=((lo - x0) / scale, (hi - x0) / scale), max_nfev=max_nfev, x_scale=1.0)
    x = x0 + res.x * scale
    fitted = build(x)
    J = res.jac / scale[None, :] * sd
    dof = max(target.size - len(names), 1)
    s2 = float(np.sum((res.fun * sd) ** 2)) / dof
    try:
        cov = s2 * np.linalg.pinv(J.T @ J)
        stderr = {n: float(np.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(names)}
    except np.linalg.LinAlgError:
        stderr = {n: float("nan") for n in names}
    scores = {"estimation": _score(fitted, data, model_db if freq_mode else None, target)}
    if val is not None:
        scores["validation"] = _score(fitted, val, None, None)
    return CalibrationResult(
        twin=fitted,
        fitted={n: float(v) for n, v in zip(names, x)},
        stderr=stderr,
        scores=scores,
        n_evaluations=count[0],
        seconds=time.perf_counter() - t0,
        message=f"log-magnitude fit ({'VNA record' if freq_mode else 'H1 estimate'}, "
        f"{f.size} frequencies): {res.message}",
    )


def _score(tw, rec: Record, model_db, target) -> dict[str, Any]:
    if is_frequency_record(rec):
        gated = bool(rec.meta.get("protocol_options", {}).get("gated", False))
        yh = 20 * np.log10(np.abs(tw.frequency_response(rec.u, include_amplifier=False, direct_only=gated)) + 1e-300)
        return {"r2": r2(rec.y, yh), "nrmse": nrmse(rec.y, yh), "domain": "frequency (dB)"}
    clean = tw.with_effects(tw.effects - set(_NOISE_EFFECTS))
    yh = clean.simulate(rec.u, rec.fs)
    return {"r2": r2(rec.y, yh), "nrmse": nrmse(rec.y, yh), "domain": "time (free run)"}
