"""Validation figures (dissertation §2.8, Figures 5.2 and 5.6 analogues), written as PNG files with matplotlib Agg.

- :func:`plot_residuals` — residual time series, histogram and spectrum;
- :func:`plot_correlation_tests` — the five correlation tests of eq. 2-32 with their 95 % bands (Fig. 5.6);
- :func:`plot_scatter` — measured vs predicted with the least-squares regression line and R² (Fig. 5.2);
- :func:`plot_horizon_residuals` — residual at several prediction horizons (1, k, free run);
- :func:`plot_compare` — measured vs predicted output of several models, whole record and a zoom (MATLAB
  ``compare``);
- :func:`identification_report` — all of the above for a fitted model on a record.
Each function returns the path it wrote.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any, Sequence

import numpy as np

os.environ.setdefault("MPLBACKEND", "Agg")
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from sysid.errors import DivergenceWarning  # noqa: E402
from sysid.residuals import correlation_tests, residual_spectrum  # noqa: E402

__all__ = ["plot_residuals", "plot_correlation_tests", "plot_scatter", "plot_horizon_residuals",
           "plot_compare", "identification_report"]


def _save(fig, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def plot_residuals(e: np.ndarray, fs: float, path, title: str = "one-step residuals", unit: str = "") -> Path:
    """Residual time series, histogram with the fitted normal density, and Welch spectrum."""
    e = np.asarray(e, float).ravel()
    t = np.arange(e.size) / fs
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.4))
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


def plot_correlation_tests(result: dict[str, Any], path, title: str = "residual correlation tests") -> Path:
    """Bar plots of φ(τ) for the five tests with the ±band (Figure 5.6 analogue); failing tests in red."""
    tests = result["tests"]
    fig, axes = plt.subplots(1, len(tests), figsize=(3.2 * len(tests), 3.0), sharey=True)
    for ax, t in zip(np.atleast_1d(axes), tests):
        lags = np.asarray(t["lags"])
        vals = np.asarray(t["values"])
        ax.bar(lags, vals, width=0.8, color="tab:blue" if t["passed"] else "tab:red")
        ax.axhline(t["band"], color="k", ls="--", lw=0.8)
        ax.axhline(-t["band"], color="k", ls="--", lw=0.8)
        ax.axhline(0, color="k", lw=0.5)
        ax.set(title=f"{t['name']} ({'pass' if t['passed'] else 'fail'})", xlabel="lag τ")
    np.atleast_1d(axes)[0].set_ylabel("φ(τ)")
    np.atleast_1d(axes)[0].set_ylim(-1, 1)
    fig.suptitle(f"{title}: band ±{result['band']:.3g} (95 %, N = {result['n']})", y=1.06)
    return _save(fig, path)


def plot_scatter(y: np.ndarray, y_hat: np.ndarray, path, title: str = "measured vs predicted", unit: str = "") -> Path:
    """Measured vs predicted with the least-squares regression line and R² (Figure 5.2 analogue)."""
    y = np.asarray(y, float).ravel()
    yh = np.asarray(y_hat, float).ravel()
    ok = np.isfinite(yh)
    y, yh = y[ok], yh[ok]
    fig, ax = plt.subplots(figsize=(4.6, 4.4))
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
    fig, axes = plt.subplots(len(horizons), 1, figsize=(10, 1.9 * len(horizons)), sharex=True)
    t = record.t
    L = int(getattr(model, "max_lag_", 0))
    for ax, h in zip(np.atleast_1d(axes), horizons):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DivergenceWarning)
            yh = np.asarray(model.predict(record, horizon=h)).reshape(np.shape(record.y))
        r = (record.y - yh)[L:]
        rms = np.sqrt(np.nanmean(r ** 2)) if np.isfinite(r).any() else np.nan
        ax.plot(t[L:], r if r.ndim == 1 else r[:, 0], lw=0.5)
        ax.set_ylabel("free run" if h is None else f"k = {h}")
        ax.set_title(f"RMS {rms:.3g}", fontsize=8, loc="right")
    np.atleast_1d(axes)[-1].set_xlabel("time [s]")
    fig.suptitle("residual at several prediction horizons")
    return _save(fig, path)


def plot_compare(t: np.ndarray, y: np.ndarray, predictions: Sequence[np.ndarray], labels: Sequence[str], path,
                 skip: int = 0, zoom: tuple[int, int] | None = None, title: str = "measured vs predicted",
                 unit: str = "") -> Path:
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
    fig, axes = plt.subplots(2, 1, figsize=(11, 6.2))
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
            correlation_tests(e, u[L:], max_lag=min(max_lag, e.size - 2)), out / "correlation_tests.png")
    files["scatter_one_step"] = plot_scatter(y[L:], y1[L:], out / "scatter_one_step.png", "one-step")
    files["scatter_free_run"] = plot_scatter(y[L:], yf[L:], out / "scatter_free_run.png", "free run")
    files["horizons"] = plot_horizon_residuals(model, record, out / "horizons.png")
    return {k: str(v) for k, v in files.items()}
