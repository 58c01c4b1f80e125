"""Figures and an index.html for a diagnosis: residuals, spectra and correlation tests before and after.

``write_report(result, directory)`` needs the result of ``diagnose(..., keep_stages=True)`` (the stages hold
the predictions); it writes ``residuals.png``, ``spectra.png``, ``correlation_tests.png`` (and
``hysteresis.png`` when the validation record lists sine segments) plus ``index.html``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from sysid.plots import pyplot
from sysid.safeio import save_figure

__all__ = ["write_report"]

_CSS = "body{font-family:sans-serif;max-width:1100px;margin:auto}"




def _psd(x, fs):
    from scipy import signal as sps

    n = len(x)
    nper = int(min(n, max(256, 1 << int(np.log2(max(n // 8, 2))))))
    return sps.welch(np.asarray(x, float), fs=fs, nperseg=nper)


def write_report(result: dict[str, Any], directory: str | Path) -> Path:
    """Write the figures and ``index.html`` of ``result`` into ``directory``; return the index path."""
    st = result.get("_stages")
    if st is None:
        raise ValueError("write_report needs diagnose(..., keep_stages=True)")
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    plt = pyplot()
    val = st["val"]
    base, ext = st["baseline"], st["extended"]
    t = np.arange(val.n) / val.fs
    e0 = val.y - base.yhat_val
    e1 = val.y - ext.yhat_val
    files = []

    fig, ax = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    ax[0].plot(t, val.y, lw=0.6, label="measured")
    ax[0].plot(t, base.yhat_val, lw=0.6, label="baseline twin")
    ax[0].plot(t, ext.yhat_val, lw=0.6, ls="--", label="extended twin")
    ax[0].legend(fontsize=8)
    ax[0].set_ylabel(f"y [{val.units.get('y', '')}]")
    ax[1].plot(t, e0, lw=0.5, color="C1")
    ax[1].set_ylabel("residual before")
    ax[2].plot(t, e1, lw=0.5, color="C2")
    ax[2].set_ylabel("residual after")
    ax[2].set_xlabel("time [s]")
    fig.suptitle(f"validation: NRMSE {result['baseline']['nrmse_val']:.4g} → {result['extended']['nrmse_val']:.4g}")
    fig.tight_layout()
    save_figure(fig, d / "residuals.png", dpi=110)
    plt.close(fig)
    files.append("residuals.png")

    fig, ax = plt.subplots(figsize=(10, 4.5))
    for x, lab in ((val.y, "measured output"), (e0, "residual before"), (e1, "residual after"), (val.u, None)):
        if lab is None:
            continue
        f, p = _psd(x, val.fs)
        ax.semilogy(f, p + 1e-300, lw=0.8, label=lab)
    band = result["analysis"]["baseline"]["validation"]["bands"]["band_hz"]
    ax.axvspan(band[0], band[1], color="0.9", zorder=0, label="excited band")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("PSD")
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, d / "spectra.png", dpi=110)
    plt.close(fig)
    files.append("spectra.png")

    t0 = base.analysis_val["_tests_full"]["tests"]
    t1 = ext.analysis_val["_tests_full"]["tests"]
    from sysid.plots import draw_correlation_test

    fig, ax = plt.subplots(2, len(t0), figsize=(3.2 * len(t0), 5.4))
    for row, tests, lab in ((0, t0, "before"), (1, t1, "after")):
        for j, tt in enumerate(tests):
            vals = np.asarray(tt["values"], float)
            lags = tt.get("lags", np.arange(vals.size) - (vals.size // 2 if vals.size % 2 else 0))
            draw_correlation_test(ax[row, j], {**tt, "lags": lags}, lab)  # own y-scale, band shaded
    fig.tight_layout()
    save_figure(fig, d / "correlation_tests.png", dpi=110)
    plt.close(fig)
    files.append("correlation_tests.png")

    hy0 = result["analysis"]["baseline"]["validation"].get("hysteresis") or []
    hy1 = result["analysis"]["extended"]["validation"].get("hysteresis") or []
    if hy0:
        fig, ax = plt.subplots(1, 2, figsize=(10, 4))
        f = [h["freq_hz"] for h in hy0]
        ax[0].semilogx(f, [100 * h["width_measured"] for h in hy0], "ko-", label="measured")
        ax[0].semilogx(f, [100 * h["width_simulated"] for h in hy0], "s--", label="baseline twin")
        ax[0].semilogx(f, [100 * h["width_simulated"] for h in hy1], "^:", label="extended twin")
        ax[0].set_ylabel("loop width [% of span]")
        ax[1].semilogx(f, [h["lag_deg_measured"] for h in hy0], "ko-", label="measured")
        ax[1].semilogx(f, [h["lag_deg_simulated"] for h in hy0], "s--", label="baseline twin")
        ax[1].semilogx(f, [h["lag_deg_simulated"] for h in hy1], "^:", label="extended twin")
        ax[1].set_ylabel("phase lag [deg]")
        for a in ax:
            a.set_xlabel("frequency [Hz]")
            a.legend(fontsize=8)
        fig.tight_layout()
        save_figure(fig, d / "hysteresis.png", dpi=110)
        plt.close(fig)
        files.append("hysteresis.png")

    from sysid.provenance import collect
    from sysid.report import esc, image, table, write_page

    causes = table(["effect", "confidence", "evidence", "params"],
                   [[esc(c["effect"]), f"{c['confidence']:.2f}", esc(c["evidence"]), esc(json.dumps(c.get("params", {})))]
                    for c in result["causes"]])

    def tests_txt(s):
        return ", ".join(f"{t['name']}: {'pass' if t['passed'] else 'fail ' + str(t['n_failing'])}" for t in s["tests"]["tests"])

    b, x = result["baseline"], result["extended"]
    twin = result.get("twin", "")
    body = [f"<h1>Discrepancy diagnosis — twin {esc(twin)}</h1>",
            f"<p>Verdict: <b>{esc(result['verdict'])}</b>. Validation NRMSE {b['nrmse_val']:.4g} → {x['nrmse_val']:.4g} "
            f"(ratio {result['gain']['nrmse_ratio']:.3f}), R² {b['r2_val']:.5f} → {x['r2_val']:.5f}.</p>",
            f"<p>Effects before: {esc(', '.join(b['effects']) or 'none')}; after: {esc(', '.join(x['effects']) or 'none')}.</p>",
            f"<h2>Causes</h2>{causes}",
            f"<h2>Correlation tests (eq. 2-32), validation</h2><p>before: {esc(tests_txt(b))}<br>after: {esc(tests_txt(x))}</p>",
            f"<h2>Not explained</h2><p>{esc(result['unexplained']['description'])}</p>",
            "".join(f"<h2>{esc(f[:-4])}</h2>{image(f, style='max-width:100%')}" for f in files)]
    return write_page(d / "index.html", f"diagnosis: {twin}", body, css=_CSS,
                      provenance=collect(records=[r for r in (st.get("est"), val) if r is not None]))
