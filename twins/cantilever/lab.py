"""The measured TU/e piezo actuator and the twin calibrated to it.

The record: u = drive voltage [V], y = displacement [µm], 5 kHz, 10 s: 3.26 s at 0 V, then a jump to −87 V
into a 150 V, 1 Hz sine (Chandra et al. 2023, MIT licence). This module does not know where the file is kept:
the caller passes the measured record in (the benchmark package serves it from its dataset registry as
``piezo-tue``, with its licence and provenance), so the twin works the same on a user's own copy.
The check this configuration is built for: calibrate on the first 5 s, free-run R² on the last 5 s ≥ 0.995 (a
static line u → y reaches 0.977). The last 5 s are scored as the continuation of the free run over the whole
input (see :func:`twins.cantilever.calibration.continues`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sysid.data.io import read_record
from sysid.data.record import Record
from sysid.errors import DataError
from sysid.evaluation.metrics import r2

__all__ = ["load_lab_record", "lab_split", "static_line_r2", "lab_twin", "calibrate_lab", "plot_lab_loops"]

SPLIT_S = 5.0


def load_lab_record(source: Record | str | Path) -> Record:
    """The measurement as a Record (u [V], y [µm], fs = 5000 Hz): ``source`` is the Record itself (checked)
    or a Record file (``.npz``) to read."""
    rec = source if isinstance(source, Record) else read_record(source, require_y=True)
    if rec.y is None:
        raise DataError(f"{rec.source or 'record'}: the lab record needs a measured output y")
    return rec


def lab_split(rec: Record, split_s: float = SPLIT_S) -> tuple[Record, Record]:
    """(first ``split_s`` seconds, the rest) of the measured record; the second continues the first
    (``meta['t0']``)."""
    rec = load_lab_record(rec)
    return rec.split(index=int(round(split_s * rec.fs)))


def static_line_r2(est: Record, val: Record) -> float:
    """R² on ``val`` of the least-squares line y = a·u + b fitted on ``est`` (the no-hysteresis baseline)."""
    a, b = np.polyfit(est.u, est.output, 1)
    return r2(val.y, a * val.u + b)


def lab_twin(hysteresis: str = "bouc-wen"):
    """Starting twin for the TU/e actuator: ±150 V amplifier, creep; the sensor and second mode are unknown
    for this bench and left out, noise and quantisation do not enter the free-run fit."""
    from twins.cantilever import CantileverTwin

    return CantileverTwin(effects=["creep"]).with_params(hysteresis=hysteresis, amp_limit_v=150.0, pi_r_max_v=150.0)


def calibrate_lab(
    hysteresis: str = "bouc-wen",
    est: Record | None = None,
    val: Record | None = None,
    substep_s: float | None = 5e-5,
    max_nfev: int = 60,
    rec: Record | None = None,
):
    """Calibrate :func:`lab_twin` on ``est`` and score ``val``; without them, on the first 5 s and the last
    5 s of the measured record ``rec``."""
    if est is None or val is None:
        if rec is None:
            raise ValueError("calibrate_lab needs est and val, or the measured record rec to split")
        est, val = lab_split(rec)
    return lab_twin(hysteresis).calibrate(est, val=val, substep_s=substep_s, max_nfev=max_nfev)


def plot_lab_loops(twin, path: str | Path, rec: Record, split_s: float = SPLIT_S) -> Path:
    """One PNG: measured and simulated u–y loops (left), and the time series with the residual (right)."""
    from sysid.report.plots import pyplot, save_and_close

    plt = pyplot()
    rec = load_lab_record(rec)
    y_sim = twin.noise_free().simulate(rec.u, rec.fs)
    k = int(round(split_s * rec.fs))
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4.8))
    a1.plot(rec.u[k:], rec.output[k:], lw=0.6, color="tab:blue", label="measured (last 5 s)")
    a1.plot(rec.u[k:], y_sim[k:], lw=0.8, ls="--", color="tab:red", label="twin, free run")
    a1.set_xlabel("voltage u [V]")
    a1.set_ylabel("displacement y [µm]")
    a1.set_title(f"TU/e actuator, validation R² = {r2(rec.output[k:], y_sim[k:]):.5f}")
    a1.legend(loc="upper left")
    a1.grid(alpha=0.3)
    t = rec.t
    a2.plot(t, rec.y, lw=0.5, label="measured")
    a2.plot(t, y_sim, lw=0.5, label="twin")
    a2.plot(t, rec.y - y_sim, lw=0.5, label="residual")
    a2.axvline(split_s, color="k", lw=0.8, ls=":")
    a2.set_xlabel("t [s]")
    a2.set_ylabel("y [µm]")
    a2.set_title("estimation | validation")
    a2.legend(loc="lower left", fontsize=8)
    a2.grid(alpha=0.3)
    fig.tight_layout()
    return save_and_close(fig, path, dpi=110)
