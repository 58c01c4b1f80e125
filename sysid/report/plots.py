"""Validation figures (dissertation §2.8, Figures 5.2 and 5.6 analogues), written as PNG files with matplotlib Agg.

- :func:`plot_residuals` — residual time series, histogram and spectrum;
- :func:`plot_correlation_tests` — the five correlation tests of eq. 2-32 with their 95 % bands (Fig. 5.6);
- :func:`plot_scatter` — measured vs predicted with the least-squares regression line and R² (Fig. 5.2);
- :func:`plot_horizon_residuals` — residual at several prediction horizons (1, k, free run);
- :func:`plot_measured_vs_predicted` — the whole record (every sample, or its min/max envelope) and a zoomed
  panel, so a report never shows only the start of a record;
- :func:`draw_correlation_test` — one test on given axes, y-axis scaled to the data, band shaded;
- :func:`whole_periods` — the samples of the last whole period(s) of a sine, for hysteresis loops;
- :func:`plot_frf`, :func:`plot_bla` — FRF magnitude/phase (coherence or std) and BLA with noise and distortion levels;
- :func:`plot_compare` — measured vs predicted output of several models, whole record and a zoom (MATLAB
  ``compare``);
- :func:`identification_report` — all of the above for a fitted model on a record.
Each function returns the path it wrote.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sysid.errors import DivergenceWarning
from sysid.evaluation.residuals import correlation_tests, residual_spectrum

__all__ = [
    "plot_residuals",
    "plot_correlation_tests",
    "plot_scatter",
    "plot_horizon_residuals",
    "plot_frf",
    "plot_bla",
    "plot_compare",
    "identification_report",
    "plot_measured_vs_predicted",
    "draw_correlation_test",
    "whole_periods",
    "BAND_COLOR",
    "ZOOM_COLOR",
    "pyplot",
    "save_and_close",
]

# Colours that mean one thing in every report (the browser test looks for them): the 95 % confidence band of
# a correlation test, and the span of the whole record that the zoomed panel shows.
BAND_COLOR = "#ffc04d"
ZOOM_COLOR = "#c6dbf7"
MEASURED_COLOR = "#000000"
PREDICTED_COLORS = ("#d62728", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")


def pyplot():
    """matplotlib.pyplot with the non-interactive Agg backend: the one plotting set-up of the project (every
    module that draws calls this instead of choosing a backend itself). matplotlib is imported here, on the
    first figure, so that importing a module that can draw costs nothing and never picks a backend for the
    user's own session."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot

    return matplotlib.pyplot


def save_and_close(fig, path, **savefig_kw) -> Path:
    """Write ``fig`` to ``path`` (format from the suffix; ``savefig_kw`` as for ``Figure.savefig``) and close
    it, also when writing fails. The file appears whole or not at all: a report or a browser never reads half
    a PNG under its final name. Returns the path."""
    from sysid.data.safeio import save_figure

    try:
        return save_figure(fig, path, **savefig_kw)
    finally:
        pyplot().close(fig)


def _save(fig, path) -> Path:
    return save_and_close(fig, path, dpi=110, bbox_inches="tight")


def plot_residuals(e: np.ndarray, fs: float, path, title: str = "one-step residuals", unit: str = "") -> Path:
    """Residual time series, histogram with the fitted normal density, and Welch spectrum."""
    e = np.asarray(e, float).ravel()
    t = np.arange(e.size) / fs
    fig, ax = pyplot().subplots(1, 3, figsize=(13, 3.4))
    ax[0].plot(t, e, lw=0.5)
    ax[0].set(xlabel="time [s]", ylabel=f"residual [{unit}]" if unit else "residual", title=title)
    ef = e[np.isfinite(e)]
    spread = float(np.ptp(ef)) if ef.size else 0.0
    if ef.size and spread > 1e-9 * max(1.0, float(np.abs(ef).max())):
        ax[1].hist(ef, bins=60, density=True, alpha=0.7)
        sd = float(ef.std())
        x = np.linspace(ef.min(), ef.max(), 200)
        ax[1].plot(x, np.exp(-0.5 * ((x - ef.mean()) / sd) ** 2) / (sd * np.sqrt(2 * np.pi)), "r-", lw=1)
        ax[1].set(xlabel="residual", ylabel="density", title="histogram vs normal")
    else:  # (numerically) constant residual: nothing to histogram
        ax[1].set(title=f"constant residual {ef.mean() if ef.size else float('nan'):.4g}")
    if ef.size < 8:
        return _save(fig, path)
    s = residual_spectrum(ef, fs)
    ax[2].semilogy(s["f_hz"], np.maximum(s["psd"], 1e-300), lw=0.8)
    ax[2].set(xlabel="frequency [Hz]", ylabel="PSD", title=f"spectrum (flatness {s['flatness']:.2f})")
    return _save(fig, path)


def draw_correlation_test(ax, test: dict[str, Any], label: str = "") -> None:
    """One correlation test of :func:`sysid.evaluation.residuals.correlation_tests` on ``ax``.

    The 95 % band ±z/√N is a shaded strip (:data:`BAND_COLOR`) with dashed edges; the y-axis is scaled to the
    larger of the data and 1.5 × the band (never a fixed ±1, on which a band of ±0.01 is invisible); the
    title says pass/fail and the band's value.
    """
    lags = np.asarray(test["lags"], float)
    vals = np.asarray(test["values"], float)
    band = float(np.atleast_1d(test["band"])[0])
    finite = vals[np.isfinite(vals)]
    lim = 1.15 * max(float(np.max(np.abs(finite))) if finite.size else 0.0, 1.5 * band, 1e-12)
    lo, hi = (lags.min() - 1, lags.max() + 1) if lags.size else (-1, 1)
    ax.fill_between([lo, hi], -band, band, color=BAND_COLOR, lw=0, zorder=0, label="95 % band")
    ax.hlines([-band, band], lo, hi, colors="k", linestyles="--", lw=0.7, zorder=1)
    ax.axhline(0, color="k", lw=0.5, zorder=1)
    ax.vlines(lags, 0, vals, lw=1.2, color="tab:blue" if test["passed"] else "tab:red", zorder=2)
    ax.plot(lags, vals, ".", ms=3, color="tab:blue" if test["passed"] else "tab:red", zorder=3)
    ax.set_xlim(lo, hi)
    ax.set_ylim(-lim, lim)
    name = f"{test['name']} {label}".strip()
    ax.set_title(f"{name}: {'pass' if test['passed'] else 'fail'} (band ±{band:.2g})", fontsize=9)
    ax.set_xlabel("lag τ", fontsize=8)
    ax.tick_params(labelsize=7)


def plot_correlation_tests(result: dict[str, Any], path, title: str = "residual correlation tests") -> Path:
    """The five tests of eq. 2-32 (Figure 5.6 analogue), each on its own y-scale with the band visible."""
    tests = result["tests"]
    fig, axes = pyplot().subplots(1, len(tests), figsize=(3.2 * len(tests), 3.0))
    for ax, t in zip(np.atleast_1d(axes), tests):
        draw_correlation_test(ax, t)
    np.atleast_1d(axes)[0].set_ylabel("φ(τ)")
    fig.suptitle(f"{title}: band ±{result['band']:.3g} (95 %, N = {result['n']})", y=1.06)
    return _save(fig, path)


def _envelope(t: np.ndarray, y: np.ndarray, max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """``(t, y)`` reduced to the min and max of each of ``max_points // 2`` bins, in time order: every
    extreme of the record stays visible (plain subsampling would drop peaks)."""
    n = y.size
    if n <= max_points:
        return t, y
    bins = max_points // 2
    edges = np.linspace(0, n, bins + 1).astype(int)
    tt, yy = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        seg = y[a:b]
        if not np.isfinite(seg).any():
            tt += [t[a], t[b - 1]]
            yy += [np.nan, np.nan]
            continue
        i, j = int(np.nanargmin(seg)), int(np.nanargmax(seg))
        for k in sorted((i, j)):
            tt.append(t[a + k])
            yy.append(seg[k])
    return np.asarray(tt), np.asarray(yy)


def plot_measured_vs_predicted(
    t: np.ndarray,
    y: np.ndarray,
    predictions: dict[str, np.ndarray],
    path,
    title: str = "measured vs predicted",
    unit: str = "",
    zoom_samples: int = 1000,
    zoom: tuple[int, int] | None = None,
    max_points: int = 20000,
) -> Path:
    """Two panels: the whole record (every sample up to ``max_points``, beyond that the min/max envelope of
    each bin) and a zoom of ``zoom_samples`` samples around the largest error of the first prediction (or the
    sample range ``zoom``), shaded in :data:`ZOOM_COLOR` on the whole-record panel.

    ``t`` [s], ``y`` and each prediction have the same length; non-finite predictions (a diverged free run)
    are left as gaps.
    """
    t = np.asarray(t, float)
    y = np.asarray(y, float).reshape(len(t), -1)[:, 0]
    preds = {k: np.asarray(v, float).reshape(len(t), -1)[:, 0] for k, v in predictions.items()}
    n = len(t)
    if zoom is None:
        w = max(2, min(int(zoom_samples), n))
        first = next(iter(preds.values()), None)
        err = np.abs(y - first) if first is not None else np.zeros(n)
        err = np.where(np.isfinite(err), err, -1.0)
        c = int(np.argmax(err)) if err.max() > 0 else n // 2
        a = int(np.clip(c - w // 2, 0, n - w))
        zoom = (a, a + w)
    a, b = int(zoom[0]), int(zoom[1])
    fig, ax = pyplot().subplots(2, 1, figsize=(10, 5.6), gridspec_kw={"height_ratios": [1.2, 1]})
    if b - a < n:
        ax[0].axvspan(t[a], t[b - 1], color=ZOOM_COLOR, lw=0, zorder=0, label="zoom below")
    ax[0].plot(*_envelope(t, y, max_points), color=MEASURED_COLOR, lw=0.7, label="measured", zorder=2)
    for (k, v), col in zip(preds.items(), PREDICTED_COLORS * 4):
        ax[0].plot(*_envelope(t, v, max_points), color=col, lw=0.6, label=k, zorder=3)
        ax[1].plot(t[a:b], v[a:b], color=col, lw=1.0, label=k, zorder=3)
    ax[1].plot(t[a:b], y[a:b], color=MEASURED_COLOR, lw=1.4, label="measured", zorder=2)
    ax[0].set_xlim(t[0], t[-1])
    ax[1].set_xlim(t[a], t[b - 1])
    ax[0].set_title(f"{title}: whole record, {n} samples", fontsize=10)
    ax[1].set_title(
        f"zoom: samples {a}–{b - 1}" + (" (largest error of the first model)" if predictions else ""), fontsize=9
    )
    for axis in ax:
        axis.set_ylabel(f"y [{unit}]" if unit else "y")
        axis.tick_params(labelsize=8)
    ax[1].set_xlabel("time [s]")
    ax[0].legend(fontsize=7, ncol=min(4, len(preds) + 2), loc="upper right")
    fig.tight_layout()
    return _save(fig, path)


def whole_periods(n: int, fs: float, freq_hz: float, periods: int = 1) -> slice:
    """The last ``periods`` whole periods of a sine of ``freq_hz`` in a segment of ``n`` samples at ``fs``
    (the whole segment when it is shorter): a hysteresis loop drawn from it is closed, never half a cycle."""
    per = int(round(fs / float(freq_hz))) if freq_hz and freq_hz > 0 else n
    want = max(1, int(periods)) * max(per, 1)
    return slice(max(0, n - want), n)


def plot_scatter(y: np.ndarray, y_hat: np.ndarray, path, title: str = "measured vs predicted", unit: str = "") -> Path:
    """Measured vs predicted with the least-squares regression line and R² (Figure 5.2 analogue)."""
    y = np.asarray(y, float).ravel()
    yh = np.asarray(y_hat, float).ravel()
    ok = np.isfinite(yh)
    y, yh = y[ok], yh[ok]
    fig, ax = pyplot().subplots(figsize=(4.6, 4.4))
    ax.plot(y, yh, ".", ms=1.5, alpha=0.4)
    if y.size > 1 and np.ptp(y) > 0:
        slope, icpt = np.polyfit(y, yh, 1)
        xs = np.array([y.min(), y.max()])
        ss = np.sum((y - y.mean()) ** 2)
        r2 = 1 - np.sum((y - yh) ** 2) / ss if ss > 0 else np.nan
        ax.plot(xs, slope * xs + icpt, "r-", lw=1.2, label=f"fit: ŷ = {slope:.3f} y + {icpt:.3g}")
        ax.plot(xs, xs, "k--", lw=0.8, label="ŷ = y")
        ax.set_title(f"{title} (R² = {r2:.4f})")
        ax.legend(loc="upper left", fontsize=8)
    lab = f" [{unit}]" if unit else ""
    ax.set(xlabel=f"measured{lab}", ylabel=f"predicted{lab}")
    return _save(fig, path)


def plot_horizon_residuals(model, record, path, horizons: Sequence[int | None] = (1, 5, 20, None)) -> Path:
    """Residual y − ŷ at several horizons (k-step ahead at every sample; None = free run), one row each."""
    fig, axes = pyplot().subplots(len(horizons), 1, figsize=(10, 1.9 * len(horizons)), sharex=True)
    t = record.t
    L = int(getattr(model, "max_lag_", 0))
    for ax, h in zip(np.atleast_1d(axes), horizons):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DivergenceWarning)
            yh = np.asarray(model.predict(record, horizon=h)).reshape(np.shape(record.y))
        r = (record.y - yh)[L:]
        rms = np.sqrt(np.nanmean(r**2)) if np.isfinite(r).any() else np.nan
        ax.plot(t[L:], r if r.ndim == 1 else r[:, 0], lw=0.5)
        ax.set_ylabel("free run" if h is None else f"k = {h}")
        ax.set_title(f"RMS {rms:.3g}", fontsize=8, loc="right")
    np.atleast_1d(axes)[-1].set_xlabel("time [s]")
    fig.suptitle("residual at several prediction horizons")
    return _save(fig, path)


def plot_compare(
    t: np.ndarray,
    y: np.ndarray,
    predictions: Sequence[np.ndarray],
    labels: Sequence[str],
    path,
    skip: int = 0,
    zoom: tuple[int, int] | None = None,
    title: str = "measured vs predicted",
    unit: str = "",
) -> Path:
    """Two panels: the whole record, and a zoom (default: 400 samples, or a twentieth of the record if longer,
    at its middle) on samples ``zoom = (start, stop)``. The first ``skip`` samples (initial conditions) are
    shaded."""
    t = np.asarray(t, float)
    y = np.asarray(y, float).ravel()
    n = y.size
    if zoom is None:
        width = min(n, max(400, n // 20))
        a = max(skip, n // 2 - width // 2)
        zoom = (a, min(n, a + width))
    fig, axes = pyplot().subplots(2, 1, figsize=(11, 6.2))
    lab = f" [{unit}]" if unit else ""
    for ax, (a, b) in zip(axes, ((0, n), zoom)):
        ax.plot(t[a:b], y[a:b], "-", color="0.55", lw=2.2, label="measured")
        for yh, label in zip(predictions, labels):
            ax.plot(t[a:b], np.asarray(yh, float).ravel()[a:b], lw=0.8, label=label)
        if skip > a:
            ax.axvspan(t[a], t[min(skip, b - 1)], color="0.9", zorder=0)
        ax.set(xlabel="time [s]", ylabel=f"y{lab}")
    axes[0].set_title(title)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[1].set_title(f"zoom: samples {zoom[0]}..{zoom[1]}", fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


def identification_report(model, record, out_dir, max_lag: int = 20) -> dict[str, str]:
    """Write residuals / correlation tests / scatter (one-step and free run) / horizons PNGs; return their paths.

    Uses the first output and first input for multichannel records.
    """
    out = Path(out_dir)
    L = int(getattr(model, "max_lag_", 0))
    y1 = np.asarray(model.predict(record, 1)).reshape(np.shape(record.y))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DivergenceWarning)
        yf = np.asarray(model.predict(record, None)).reshape(np.shape(record.y))
    y = record.y if record.y.ndim == 1 else record.y[:, 0]
    u = record.u if record.u.ndim == 1 else record.u[:, 0]
    y1 = y1 if y1.ndim == 1 else y1[:, 0]
    yf = yf if yf.ndim == 1 else yf[:, 0]
    e = (y - y1)[L:]
    files = {"residuals": plot_residuals(e, record.fs, out / "residuals.png", unit=record.units.get("y", ""))}
    if np.isfinite(e).all() and e.size > 3:  # a non-finite one-step residual has no correlation to test
        files["correlation_tests"] = plot_correlation_tests(
            correlation_tests(e, u[L:], max_lag=min(max_lag, e.size - 2)), out / "correlation_tests.png"
        )
    files["scatter_one_step"] = plot_scatter(y[L:], y1[L:], out / "scatter_one_step.png", "one-step")
    files["scatter_free_run"] = plot_scatter(y[L:], yf[L:], out / "scatter_free_run.png", "free run")
    files["horizons"] = plot_horizon_residuals(model, record, out / "horizons.png")
    return {k: str(v) for k, v in files.items()}


# ---------------------------------------------------------------------------------------------- FRF / BLA
def plot_frf(frf, path, title: str = "FRF", unit: str = "", reference: Any = None) -> Path:
    """Magnitude [dB] and phase [deg] of an :class:`sysid.linear.frf.FRF`, with its 1-σ band (``std``) or its
    coherence (H1 estimates); ``reference`` (complex array at ``frf.f_hz``) is drawn for comparison."""
    f = np.asarray(frf.f_hz)
    has_coh = frf.coherence is not None
    fig, ax = pyplot().subplots(3 if has_coh else 2, 1, figsize=(8, 8 if has_coh else 6), sharex=True)
    pos = f > 0
    ax[0].semilogx(f[pos], frf.magnitude_db[pos], lw=1, label="estimate")
    if frf.std is not None and not has_coh:
        with np.errstate(divide="ignore"):
            ax[0].semilogx(f[pos], 20 * np.log10(np.asarray(frf.std)[pos]), lw=0.8, label="std of G")
    if reference is not None:
        ref = np.asarray(reference)
        ax[0].semilogx(f[pos], 20 * np.log10(np.abs(ref[pos])), "k--", lw=0.8, label="reference")
        ax[1].semilogx(f[pos], np.degrees(np.unwrap(np.angle(ref)))[pos], "k--", lw=0.8)
    ax[0].set(ylabel=f"|G| [dB{' ' + unit if unit else ''}]", title=title)
    ax[0].legend(loc="best", fontsize=8)
    ax[1].semilogx(f[pos], frf.phase_deg[pos], lw=1)
    ax[1].set(ylabel="phase [deg]")
    if has_coh:
        ax[2].semilogx(f[pos], np.asarray(frf.coherence)[pos], lw=1)
        ax[2].set(ylabel="coherence", ylim=(0, 1.05))
    ax[-1].set(xlabel="frequency [Hz]")
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
    return _save(fig, path)


def plot_bla(bla, path, title: str = "Best Linear Approximation", unit: str = "") -> Path:
    """G_BLA magnitude with the noise and nonlinear-distortion standard deviations [dB], its phase, and the
    output power at the odd / even detection lines against the noise floor."""
    f = np.asarray(bla.f_hz)
    fig, ax = pyplot().subplots(3, 1, figsize=(8, 9))
    with np.errstate(divide="ignore", invalid="ignore"):
        ax[0].plot(f, 20 * np.log10(np.abs(bla.G)), lw=1, label="G_BLA")
        ax[0].plot(f, 10 * np.log10(bla.var_noise), ".", ms=2, label="noise std")
        if np.isfinite(bla.var_distortion).any():
            ax[0].plot(f, 10 * np.log10(bla.var_distortion), ".", ms=2, label="distortion std")
    ax[0].set(ylabel=f"[dB{' ' + unit if unit else ''}]", title=title)
    ax[0].legend(loc="best", fontsize=8)
    ax[1].plot(f, np.degrees(np.unwrap(np.angle(bla.G))), lw=1)
    ax[1].set(ylabel="phase [deg]")
    det = bla.detection
    nl = bla.nonlinearity
    if det and np.size(det.get("f_hz", [])):
        kinds = np.asarray(det["kind"])
        with np.errstate(divide="ignore"):
            for kind, mark in (("odd", "o"), ("even", "s"), ("any", "o")):
                sel = kinds == kind
                if sel.any():
                    ax[2].plot(
                        det["f_hz"][sel],
                        10 * np.log10(det["level"][sel]),
                        mark,
                        ms=3,
                        mfc="none",
                        label=f"output at {kind} detection lines",
                    )
            ax[2].plot(det["f_hz"], 10 * np.log10(det["noise"]), ".", ms=2, color="gray", label="noise variance")
        ax[2].legend(loc="best", fontsize=8)
    txt = f"verdict: {nl.get('verdict')}"
    for k in ("odd", "even"):
        v = nl.get(f"{k}_db")
        if v is not None:
            txt += f", {k} {v:.1f} dB"
    ax[2].set(xlabel="frequency [Hz]", ylabel="output power [dB]", title=txt)
    fig.tight_layout()
    for a in ax:
        a.grid(True, alpha=0.3)
    return _save(fig, path)
