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

from sysid.report.plots import pyplot, save_and_close

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
    val, base, ext = st["val"], st["baseline"], st["extended"]
    e0, e1 = val.y - base.yhat_val, val.y - ext.yhat_val
    files = [
        _residuals_png(result, val, base, ext, d / "residuals.png"),
        _spectra_png(result, val, e0, e1, d / "spectra.png"),
        _tests_png(
            base.analysis_val["_tests_full"]["tests"],
            ext.analysis_val["_tests_full"]["tests"],
            d / "correlation_tests.png",
        ),
    ]
    hy0 = result["analysis"]["baseline"]["validation"].get("hysteresis") or []
    hy1 = result["analysis"]["extended"]["validation"].get("hysteresis") or []
    if hy0:
        files.append(_hysteresis_png(hy0, hy1, d / "hysteresis.png"))
    return _write_index(result, [p.name for p in files], [r for r in (st.get("est"), val) if r is not None], d)


def _residuals_png(result, val, base, ext, path: Path) -> Path:
    t = np.arange(val.n) / val.fs
    fig, ax = pyplot().subplots(3, 1, figsize=(10, 7), sharex=True)
    ax[0].plot(t, val.y, lw=0.6, label="measured")
    ax[0].plot(t, base.yhat_val, lw=0.6, label="baseline twin")
    ax[0].plot(t, ext.yhat_val, lw=0.6, ls="--", label="extended twin")
    ax[0].legend(fontsize=8)
    ax[0].set_ylabel(f"y [{val.units.get('y', '')}]")
    ax[1].plot(t, val.y - base.yhat_val, lw=0.5, color="C1")
    ax[1].set_ylabel("residual before")
    ax[2].plot(t, val.y - ext.yhat_val, lw=0.5, color="C2")
    ax[2].set_ylabel("residual after")
    ax[2].set_xlabel("time [s]")
    fig.suptitle(f"validation: NRMSE {result['baseline']['nrmse_val']:.4g} → {result['extended']['nrmse_val']:.4g}")
    fig.tight_layout()
    return save_and_close(fig, path, dpi=110)


def _spectra_png(result, val, e0, e1, path: Path) -> Path:
    fig, ax = pyplot().subplots(figsize=(10, 4.5))
    for x, lab in ((val.y, "measured output"), (e0, "residual before"), (e1, "residual after")):
        f, p = _psd(x, val.fs)
        ax.semilogy(f, p + 1e-300, lw=0.8, label=lab)
    band = result["analysis"]["baseline"]["validation"]["bands"]["band_hz"]
    ax.axvspan(band[0], band[1], color="0.9", zorder=0, label="excited band")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("PSD")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_and_close(fig, path, dpi=110)


def _tests_png(before: list[dict[str, Any]], after: list[dict[str, Any]], path: Path) -> Path:
    from sysid.report.plots import draw_correlation_test

    fig, ax = pyplot().subplots(2, len(before), figsize=(3.2 * len(before), 5.4))
    for row, tests, lab in ((0, before, "before"), (1, after, "after")):
        for j, tt in enumerate(tests):
            vals = np.asarray(tt["values"], float)
            lags = tt.get("lags", np.arange(vals.size) - (vals.size // 2 if vals.size % 2 else 0))
            draw_correlation_test(ax[row, j], {**tt, "lags": lags}, lab)  # own y-scale, band shaded
    fig.tight_layout()
    return save_and_close(fig, path, dpi=110)


def _hysteresis_png(hy0: list[dict[str, Any]], hy1: list[dict[str, Any]], path: Path) -> Path:
    fig, ax = pyplot().subplots(1, 2, figsize=(10, 4))
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
    return save_and_close(fig, path, dpi=110)


def _tests_txt(part: dict[str, Any]) -> str:
    return ", ".join(
        f"{t['name']}: {'pass' if t['passed'] else 'fail ' + str(t['n_failing'])}" for t in part["tests"]["tests"]
    )


def _write_index(result: dict[str, Any], figures: list[str], records: list[Any], d: Path) -> Path:
    from sysid.report.html import esc, image, table, write_page
    from sysid.report.provenance import collect

    from .hybrid import hybrid_text

    causes = table(
        ["effect", "confidence", "evidence", "params"],
        [
            [esc(c["effect"]), f"{c['confidence']:.2f}", esc(c["evidence"]), esc(json.dumps(c.get("params", {})))]
            for c in result["causes"]
        ],
    )
    b, x = result["baseline"], result["extended"]
    twin = result.get("twin", "")
    body = [
        f"<h1>Discrepancy diagnosis — twin {esc(twin)}</h1>",
        f"<p>Verdict: <b>{esc(result['verdict'])}</b>. Validation NRMSE {b['nrmse_val']:.4g} → {x['nrmse_val']:.4g} "
        f"(ratio {result['gain']['nrmse_ratio']:.3f}), R² {b['r2_val']:.5f} → {x['r2_val']:.5f}.</p>",
        f"<p>Effects before: {esc(', '.join(b['effects']) or 'none')}; "
        f"after: {esc(', '.join(x['effects']) or 'none')}.</p>",
        f"<h2>Causes</h2>{causes}",
        "<h2>Correlation tests (eq. 2-32), validation</h2>"
        f"<p>before: {esc(_tests_txt(b))}<br>after: {esc(_tests_txt(x))}</p>",
        f"<h2>Not explained</h2><p>{esc(result['unexplained']['description'])}</p>",
        (f"<h2>Hybrid twin</h2><p>{esc(hybrid_text(result['hybrid']))}</p>" if result.get("hybrid") else ""),
        "".join(f"<h2>{esc(f[:-4])}</h2>{image(f, style='max-width:100%')}" for f in figures),
    ]
    return write_page(d / "index.html", f"diagnosis: {twin}", body, css=_CSS, provenance=collect(records=records))
