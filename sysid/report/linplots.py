"""Figures of the linear models' uncertainty: the simulated output with its confidence band and the
frequency response with its standard deviation. PNG files via :mod:`sysid.report.plots` (matplotlib Agg).

- :func:`plot_simulation_band`: measured output, free-run simulation and the band ± ``z`` std per sample
  (``model.simulation_band``: Monte Carlo over the parameter covariance for OE/BJ, jackknife for n4sid);
- :func:`plot_bode_with_std`: |G| in dB and phase in degrees with a ± 2 std band on |G| (``model.frequency_response``);
- :func:`linear_report`: both, for a model that has them (returns {name: path}).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.report.plots import _save, pyplot

__all__ = ["plot_simulation_band", "plot_bode_with_std", "linear_report"]


def plot_simulation_band(
    model, record: Record, path, z: float = 2.0, n_draws: int = 100, seed: int = 0, max_points: int = 1000
) -> Path:
    mean, std = model.simulation_band(record, n_draws=n_draws, seed=seed)
    y = np.asarray(record.y, float).reshape(len(record), -1)
    sim = np.asarray(model.predict(record, None), float).reshape(len(record), -1)
    std = np.asarray(std, float).reshape(len(record), -1)
    n = min(len(record), max_points)
    t = record.t[:n]
    fig, axes = pyplot().subplots(y.shape[1], 1, figsize=(7.5, 2.8 * y.shape[1]), squeeze=False)
    for o, ax in enumerate(axes[:, 0]):
        ax.plot(t, y[:n, o], color="0.6", lw=0.8, label="measured")
        ax.plot(t, sim[:n, o], color="C0", lw=0.9, label="free run")
        ax.fill_between(
            t,
            sim[:n, o] - z * std[:n, o],
            sim[:n, o] + z * std[:n, o],
            color="C0",
            alpha=0.3,
            label=f"± {z:g} std (model uncertainty)",
        )
        ax.set_ylabel(f"y{o + 1}" if y.shape[1] > 1 else "y")
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    axes[0, 0].set_title(f"{model.name}: simulated output with confidence band")
    return _save(fig, path)


def plot_bode_with_std(model, fs: float, path, n_freq: int = 400) -> Path:
    f = np.linspace(fs / (2 * n_freq), fs / 2, n_freq)
    r = model.frequency_response(f, fs)
    G = np.asarray(r["G"])
    std = None if r["std"] is None else np.asarray(r["std"])
    G = G.reshape(len(f), -1)
    std = None if std is None else std.reshape(len(f), -1)
    fig, (a1, a2) = pyplot().subplots(2, 1, figsize=(7.0, 5.0), sharex=True)
    for k in range(G.shape[1]):
        mag = np.abs(G[:, k])
        (line,) = a1.semilogx(
            f, 20 * np.log10(np.maximum(mag, 1e-300)), lw=1.0, label=None if G.shape[1] == 1 else f"G{k + 1}"
        )
        if std is not None:
            lo = np.maximum(mag - 2 * std[:, k], 1e-300 * np.ones_like(mag))
            a1.fill_between(
                f, 20 * np.log10(lo), 20 * np.log10(mag + 2 * std[:, k]), color=line.get_color(), alpha=0.25
            )
        a2.semilogx(f, np.degrees(np.unwrap(np.angle(G[:, k]))), lw=1.0, color=line.get_color())
    a1.set_ylabel("|G| [dB] (± 2 std)")
    a2.set_ylabel("phase [°]")
    a2.set_xlabel("frequency [Hz]")
    a1.set_title(f"{model.name}: frequency response")
    return _save(fig, path)


def linear_report(model, record: Record, out_dir) -> dict[str, Any]:
    out: dict[str, Any] = {}
    out_dir = Path(out_dir)
    if hasattr(model, "simulation_band"):
        out["simulation_band"] = str(plot_simulation_band(model, record, out_dir / "simulation_band.png"))
    if hasattr(model, "frequency_response"):
        out["bode"] = str(plot_bode_with_std(model, record.fs, out_dir / "bode.png"))
    return out
