"""Warnings a practitioner would give about an identified model (``identify`` prints them, ``--json`` key
``warnings``). Each is one line; none stops anything.

- **Unstable / integrating poles**: a pole with |p| ≥ 1 − ``POLE_TOL`` (on or outside the unit circle), except
  the complex poles of a lightly damped resonance inside the circle — damping ratio ζ = −ln|p| / |ln p| (the
  continuous pole s = ln(p)/T, ζ = −Re s/|s|) of at least ``MIN_RESONANCE_ZETA``: a structure's mode at 0.5 %
  damping sampled 40 times faster than it oscillates has |p| = 0.9992 and is neither an integrator nor a sign of
  feedback. The
  usual cause in measured data is feedback: the record was taken in closed loop, and u is then correlated with
  the past of y. The check (Ljung, *System Identification*, 2nd ed., §13.4 and §16.6): prewhiten u by a long AR
  model, ε_u = A_u(q) u; in open loop ε_u(t) is uncorrelated with y(t − k), k ≥ 1, and each sample correlation has
  standard deviation 1/√N (Bartlett); a value beyond ``CORR_SIGMAS``/√N names closed-loop data as suspected.
- **One-step fit far above free-run fit**: one-step R² ≥ 0.5 while the free-run R² is lower by more than
  ``GAP_R2`` and its error variance (1 − R²) is over ``GAP_RATIO`` × the one-step one — a one-step score that says
  nothing about simulation (the issue's ARX with one-step 0.99995, free run 0.44).
- **Automatic order on the corner of its grid, or short of the FIR**: the order chosen on the hold-out is the
  largest the search tried (``order_search["corner"]``), or no order came near the least-squares FIR's hold-out
  error (``order_search["below_reference"]``): a larger ``max_order`` or another structure may simulate better.
- **Validation outside the estimation amplitude range**: a validation input or output exceeding the estimation
  range by more than ``RANGE_TOL`` of that range: the model extrapolates.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.evaluation.residuals import ar_prewhiten

__all__ = ["practitioner_warnings", "closed_loop_correlation"]

POLE_TOL = 1e-3
MIN_RESONANCE_ZETA = 1e-3
CORR_SIGMAS = 4.0
CORR_LAGS = 20
AR_ORDER = 20
GAP_R2 = 0.1
GAP_RATIO = 5.0
RANGE_TOL = 0.1


def _recs(data) -> list[Record]:
    return [data] if isinstance(data, Record) else list(data)


def closed_loop_correlation(
    data: Record | Sequence[Record], max_lag: int = CORR_LAGS, ar_order: int = AR_ORDER
) -> dict[str, Any]:
    """Largest |corr(ε_u(t), y(t − k))|, k = 1..max_lag, over input/output pairs (module docstring), its lag and the
    threshold CORR_SIGMAS/√N."""
    best: dict[str, Any] = {"rho": 0.0, "lag": None, "threshold": math.inf}
    for rec in _recs(data):
        u = rec.u.reshape(len(rec), -1)
        y = rec.output.reshape(len(rec), -1)
        N = len(rec)
        p = min(ar_order, max(N // 10, 1))
        if N <= p + max_lag + 10:
            continue
        thr = CORR_SIGMAS / math.sqrt(N - p - max_lag)
        for i in range(u.shape[1]):
            eps = ar_prewhiten(u[:, i], p, select=False)[0]
            for o in range(y.shape[1]):
                yy = y[p:, o] - y[p:, o].mean()
                se, sy = float(np.std(eps)), float(np.std(yy))
                if se == 0.0 or sy == 0.0:
                    continue
                for k in range(1, max_lag + 1):
                    r = float(np.mean((eps[k:] - eps[k:].mean()) * (yy[:-k] - yy[:-k].mean()))) / (se * sy)
                    if abs(r) / thr > abs(best["rho"]) / best["threshold"]:
                        best = {"rho": r, "lag": k, "threshold": thr}
    return best


def _resonance(p: dict[str, Any]) -> bool:
    """A complex pole inside the unit circle with damping ratio ≥ MIN_RESONANCE_ZETA (module docstring)."""
    z = complex(p["re"], p["im"])
    if abs(z.imag) == 0.0 or not 0.0 < abs(z) < 1.0:
        return False
    s = complex(math.log(abs(z)), math.atan2(z.imag, z.real))  # ln p (times 1/T: the continuous pole)
    return -s.real / abs(s) >= MIN_RESONANCE_ZETA


def _pole_warning(model, est) -> str | None:
    poles = getattr(model, "poles", None)
    if poles is None:
        return None
    try:
        ps = poles()
    except Exception:  # noqa: BLE001 - a model without usable poles (e.g. MIMO ARX) simply gets no pole warning
        return None
    bad = [p for p in ps if p["abs"] >= 1.0 - POLE_TOL and not _resonance(p)]
    if not bad:
        return None
    p = max(bad, key=lambda q: q["abs"])
    kind = (
        "integrator (or near-integrator)"
        if abs(p["abs"] - 1.0) < 1e-3
        else ("unstable" if p["abs"] > 1.0 else "marginal")
    )
    msg = f"pole at {p['re']:.5f}{p['im']:+.5f}j (|p| = {p['abs']:.5f}) on or outside the unit circle: {kind} model"
    cl = closed_loop_correlation(est)
    if cl["lag"] is not None and abs(cl["rho"]) > cl["threshold"]:
        msg += (
            f"; u correlates with past y (rho = {cl['rho']:.2f} at lag {cl['lag']}, open-loop limit "
            f"{cl['threshold']:.2f}): closed-loop data suspected, consider an instrumental-variable or "
            "direct-PEM model with a noise model (bj)"
        )
    return msg


def _gap_warning(scores: dict[str, Any] | None, part: str) -> str | None:
    if not scores:
        return None
    os_, fr = scores.get("one_step", {}).get("r2"), scores.get("free_run", {}).get("r2")
    if os_ is None or not np.isfinite(os_) or os_ < 0.5:
        return None
    if fr is None or not np.isfinite(fr):
        return (
            f"{part}: one-step R² {os_:.5f} but the free run diverged: the model predicts one step from "
            "measured outputs and does not simulate the system"
        )
    if os_ - fr > GAP_R2 and (1.0 - fr) > GAP_RATIO * max(1.0 - os_, 1e-12):
        return (
            f"{part}: one-step R² {os_:.5f} far above free-run R² {fr:.5f}: one-step prediction leans on the "
            "measured outputs; judge the model by its free run (try oe / n4sid, or other orders)"
        )
    return None


def _range_warnings(est, val) -> list[str]:
    out = []
    E, V = _recs(est), _recs(val)
    for name in ("u", "y"):
        e = np.concatenate([getattr(r, name).reshape(len(r), -1) for r in E])
        v = np.concatenate([getattr(r, name).reshape(len(r), -1) for r in V])
        for ch in range(min(e.shape[1], v.shape[1])):
            lo, hi = float(e[:, ch].min()), float(e[:, ch].max())
            span = max(hi - lo, 1e-300)
            vlo, vhi = float(v[:, ch].min()), float(v[:, ch].max())
            beyond = max(lo - vlo, vhi - hi, 0.0) / span
            if beyond > RANGE_TOL:
                label = name if e.shape[1] == 1 else f"{name}{ch + 1}"
                out.append(
                    f"validation {label} spans [{vlo:.4g}, {vhi:.4g}], beyond the estimation range "
                    f"[{lo:.4g}, {hi:.4g}] by {100 * beyond:.0f} % of it: the model extrapolates there"
                )
    return out


def practitioner_warnings(model, est, val=None, summary: dict[str, Any] | None = None) -> list[str]:
    """The warnings of the module docstring for a fitted ``model`` (``summary``: the identify scores)."""
    out = []
    w = _pole_warning(model, est)
    if w:
        out.append(w)
    for part in ("estimation", "validation"):
        w = _gap_warning((summary or {}).get(part), part)
        if w:
            out.append(w)
    search = (summary or {}).get("order_search") or getattr(model, "order_search_", None)
    if isinstance(search, dict) and (search.get("corner") or search.get("below_reference")):
        chosen = ", ".join(f"{k}={v}" for k, v in ((summary or {}).get("chosen_orders") or {}).items())
        top = max(search.get("grid") or [search.get("grid_max", 0)])
        if search.get("corner"):
            out.append(
                f"automatic order ({chosen}) is the largest of its grid (the corner, up to {top}): a larger "
                "max_order may simulate the hold-out better"
            )
        ref = search.get("reference") or {}
        if search.get("below_reference") and ref.get("holdout_nrmse") is not None:
            out.append(
                f"no automatic order up to {top} simulates the hold-out as well as a least-squares FIR "
                f"({ref.get('nb')} taps): try a larger max_order, another structure, or the fir identifier"
            )
    if val is not None:
        out += _range_warnings(est, val)
    return out
