"""Figures of the cantilever case study (PNG files, drawn with :func:`sysid.report.plots.pyplot`).

- :func:`plot_sine_loops` — the analogue of dissertation Figure 4.3: normalised u–y loops, measured
  (blue) against the twin's free-run simulation (red), one panel per validation sine.
- :func:`plot_multisine_spectra` — the analogue of Figure 3.4: power spectra of the multisine input and
  of the measured output (dB), with the excited band and the twin's mode frequencies marked.
- :func:`twins.cantilever.lab.plot_lab_loops` — measured vs simulated loops of the TU/e actuator.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sysid.data.record import Record
from sysid.evaluation.metrics import r2
from sysid.report.plots import pyplot, save_and_close, whole_periods

__all__ = ["plot_sine_loops", "plot_multisine_spectra", "last_period", "loop_metrics"]


def last_period(seg_len: int, fs: float, freq_hz: float) -> slice:
    """Slice of the last whole period of a sine segment of ``seg_len`` samples (steady-state loop); the
    reports cut their loops with the same :func:`sysid.report.plots.whole_periods`."""
    return whole_periods(seg_len, fs, freq_hz)


def loop_metrics(u: np.ndarray, y: np.ndarray, freq_hz: float, fs: float) -> dict[str, float]:
    """Hysteresis measures of one period of a sine response.

    ``width_ratio``: largest vertical gap between the rising and falling branches ÷ output span (the H% of
    physics notes A.3); ``area``: loop area ∮y du normalised by (u span · y span); ``phase_deg``: lag of the
    output's fundamental behind the input's, in degrees (by projection on the sine/cosine at ``freq_hz``).
    """
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    t = np.arange(u.size) / fs
    c, s = np.cos(2 * np.pi * freq_hz * t), np.sin(2 * np.pi * freq_hz * t)
    pu = np.angle(np.sum(u * c) - 1j * np.sum(u * s))
    py = np.angle(np.sum(y * c) - 1j * np.sum(y * s))
    lag = np.degrees(np.angle(np.exp(1j * (pu - py))))
    du = np.gradient(u)
    span_y = float(np.ptp(y))
    span_u = float(np.ptp(u))
    lo, hi = u.min(), u.max()
    grid = np.linspace(lo + 0.05 * span_u, hi - 0.05 * span_u, 200)
    up, dn = du > 0, du < 0
    width = 0.0
    if up.sum() > 3 and dn.sum() > 3:
        iu, idn = np.argsort(u[up]), np.argsort(u[dn])
        yu = np.interp(grid, u[up][iu], y[up][iu])
        yd = np.interp(grid, u[dn][idn], y[dn][idn])
        width = float(np.max(np.abs(yd - yu)))
    area = abs(float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(u))))
    return {
        "width_ratio": width / span_y if span_y else float("nan"),
        "area": area / (span_u * span_y) if span_u and span_y else float("nan"),
        "phase_deg": float(lag),
    }


def plot_sine_loops(measured: Record, twin, path: str | Path, title: str = "") -> Path:
    """Figure 4.3 analogue: per thesis sine (``measured.meta['segments']``), the last period's u–y loop of
    the measurement (blue) and the twin's free run over the same input (red), both normalised as in the
    dissertation (zero mean, unit standard deviation of the measured segment). R² per panel."""
    plt = pyplot()
    segs = measured.meta.get("segments")
    if not segs:
        raise ValueError("plot_sine_loops: the record has no meta['segments'] (use the thesis-sines protocol)")
    y_sim = twin.simulate(measured.u, measured.fs)
    n = len(segs)
    cols = 4
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.9 * rows), squeeze=False)
    for ax, seg in zip(axes.ravel(), segs):
        a, b, f = int(seg["start"]), int(seg["stop"]), float(seg["freq_hz"])
        sl = last_period(b - a, measured.fs, f)
        u = measured.u[a:b][sl]
        ym = measured.output[a:b][sl]
        ys = y_sim[a:b][sl]
        u, ym, ys = (np.append(x, x[0]) for x in (u, ym, ys))  # close the loop
        un = (u - u.mean()) / (u.std() or 1.0)
        mu, sd = ym.mean(), ym.std() or 1.0
        ax.plot(un, (ym - mu) / sd, color="tab:blue", lw=1.0, label="measured")
        ax.plot(un, (ys - mu) / sd, color="tab:red", lw=0.9, ls="--", label="twin")
        ax.set_title(f"{f:g} Hz  R² = {r2(measured.output[a:b], y_sim[a:b]):.4f}", fontsize=9)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=7, loc="upper left")
    fig.supxlabel("u (normalised)")
    fig.supylabel("y (normalised)")
    fig.suptitle(title or "Cantilever: u–y loops per validation sine (cf. dissertation Figure 4.3)")
    fig.tight_layout()
    return save_and_close(fig, path, dpi=110)


def plot_multisine_spectra(record: Record, path: str | Path, twin=None, band_hz: float = 500.0) -> Path:
    """Figure 3.4 analogue: Welch power spectra (dB) of the multisine input u and the output y.

    Marks the excited band (≤ ``band_hz``) and, when ``twin`` is given, its f₁ and f₂ = mode_ratio·f₁.
    """
    from scipy.signal import welch

    plt = pyplot()
    record.require_output()
    nper = min(len(record), int(2 ** np.floor(np.log2(max(256, record.fs * 2)))))
    f, pu = welch(record.u, fs=record.fs, nperseg=nper)
    _, py = welch(record.y, fs=record.fs, nperseg=nper)
    fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for ax, p, lab, unit in ((axes[0], pu, "input u", "V²/Hz"), (axes[1], py, "output y", "µm²/Hz")):
        ax.plot(f, 10 * np.log10(np.maximum(p, 1e-30)), lw=0.7)
        ax.axvspan(0, band_hz, color="tab:green", alpha=0.08, label=f"excited band ≤ {band_hz:g} Hz")
        ax.set_ylabel(f"{lab} [dB re 1 {unit}]")
        ax.grid(alpha=0.3)
    if twin is not None:
        f1 = twin.params.f1_hz
        axes[1].axvline(f1, color="tab:red", ls=":", lw=1, label=f"f₁ = {f1:g} Hz")
        if twin.has("second_mode"):
            f2 = f1 * twin.params.mode_ratio
            if f2 < record.fs / 2:
                axes[1].axvline(f2, color="tab:purple", ls=":", lw=1, label=f"f₂ = {f2:.0f} Hz")
    axes[0].legend(fontsize=8)
    axes[1].legend(fontsize=8)
    axes[1].set_xlabel("frequency [Hz]")
    axes[1].set_xscale("log")
    axes[1].set_xlim(max(f[1], 0.1), record.fs / 2)
    fig.suptitle("Multisine: input and output power spectra (cf. dissertation Figure 3.4)")
    fig.tight_layout()
    return save_and_close(fig, path, dpi=110)
