"""Delay estimation and order selection for the linear identifiers (``arx``, ``oe``, ``bj``, ``n4sid``).

- :func:`delay_estimate` (MATLAB's ``delayest`` in spirit): a least-squares FIR model with lags 0 … M per input
  (Ljung, *System Identification*, 2nd ed., §7.3); the delay of input i is the largest k ≤ ``max_delay`` such
  that dropping its first j taps, for every j ≤ k, does not raise the residual sum of squares significantly (F test
  of the nested least-squares models at level ``alpha``; Seber & Lee, *Linear Regression Analysis*, §4.3). A joint
  test, unlike per-tap t-ratios, still works for band-limited inputs, whose individual FIR taps are poorly
  determined while their sum is not (measured: Wiener–Hammerstein input, every |t| < 1). The normal equations are
  accumulated in chunks, so memory is O(M²) whatever N.
- :func:`order_table`: fit an identifier over a grid of orders and score each fit by the information criteria on
  the estimation data (AIC = N ln V + 2p, BIC = N ln V + p ln N, V the mean squared one-step prediction error;
  Ljung §16.4, eq. 16.33) and by the free-run error on validation data (cross-validation, §16.5) — the table a
  practitioner reads; :func:`plot_order_table` draws it.
- :func:`select_oe_orders`, :func:`select_arx_orders`: what an identifier run without orders does — hold out the
  last ``HOLDOUT`` of each estimation record, fit each order of the grid on the rest, and take the smallest order
  whose hold-out free-run NRMSE is within ``TOLERANCE`` of the best (the search stops after ``PATIENCE`` grid
  points without improvement).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sysid.errors import ConfigError, DataError, DivergenceWarning
from sysid.record import Record
from sysid.registry import get_identifier

__all__ = ["delay_estimate", "order_table", "plot_order_table", "select_oe_orders", "select_arx_orders",
           "ORDER_GRID"]

ORDER_GRID = (1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64, 80, 100, 128)
HOLDOUT = 0.3
TOLERANCE = 0.01
PATIENCE = 3
CHUNK = 100_000


def delay_estimate(data: Record | Sequence[Record], max_delay: int = 30, n_extra: int = 10,
                   alpha: float = 1e-3) -> list[int]:
    """Delay (samples) of each input from a least-squares FIR model with lags 0 … max_delay + n_extra."""
    recs = [data] if isinstance(data, Record) else list(data)
    m = recs[0].n_inputs
    M = int(max_delay) + int(n_extra) + 1
    p = m * M
    G = np.zeros((p, p))
    g = np.zeros(p)
    yy, n = 0.0, 0
    for rec in recs:
        u = rec.u.reshape(len(rec), -1)
        y = rec.output.reshape(len(rec), -1)[:, 0]
        if len(rec) <= M:
            raise DataError(f"{rec.source}: {len(rec)} samples are too few for a delay estimate over {M} lags")
        for t0 in range(M - 1, len(rec), CHUNK):
            t1 = min(t0 + CHUNK, len(rec))
            X = np.empty((t1 - t0, p))
            for i in range(m):
                for k in range(M):
                    X[:, i * M + k] = u[t0 - k:t1 - k, i]
            G += X.T @ X
            g += X.T @ y[t0:t1]
            yy += float(y[t0:t1] @ y[t0:t1])
            n += t1 - t0
    from scipy.stats import f as f_dist

    def rss(keep):
        Gk = G[np.ix_(keep, keep)]
        th = np.linalg.lstsq(Gk, g[keep], rcond=1e-12)[0]
        return max(yy - float(th @ g[keep]), 0.0)

    full = list(range(p))
    rss0 = max(rss(full), 1e-300 * max(yy, 1e-300))
    dof = max(n - p, 1)
    out = []
    for i in range(m):
        k_ok = 0
        for k in range(1, int(max_delay) + 1):
            keep = [j for j in full if not (i * M <= j < i * M + k)]
            F = ((rss(keep) - rss0) / k) / (rss0 / dof)
            if F > f_dist.ppf(1.0 - alpha, k, dof):
                break
            k_ok = k
        out.append(k_ok)
    return out


def _split(records: list[Record], holdout: float) -> tuple[list[Record], list[Record]]:
    est, val = [], []
    for r in records:
        cut = int(round(len(r) * (1.0 - holdout)))
        a, b = r.split(index=cut)
        est.append(a)
        val.append(b)
    return est, val


def _nrmse_free_run(model, recs: list[Record]) -> float:
    from sysid.evaluate import evaluate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DivergenceWarning)
        s = evaluate(model, recs, horizons={"free_run": None})["free_run"]
    v = s["nrmse"]
    return math.inf if v is None or not np.isfinite(v) else float(v)


def _search(make, records: list[Record], grid: Sequence[int], what: str) -> tuple[int, list[dict[str, Any]]]:
    est, val = _split(records, HOLDOUT)
    rows: list[dict[str, Any]] = []
    best, since = math.inf, 0
    for n in grid:
        try:
            model = make(n).fit(est if len(est) > 1 else est[0])
        except (DataError, ConfigError, np.linalg.LinAlgError) as exc:
            rows.append({"order": n, "error": str(exc)})
            break
        err = _nrmse_free_run(model, val)
        rows.append({"order": n, "n_parameters": int(model.n_parameters_), "holdout_nrmse": err})
        if err < best * (1.0 - 1e-3):
            best, since = err, 0
        else:
            since += 1
            if since >= PATIENCE:
                break
    scored = [r for r in rows if "holdout_nrmse" in r and np.isfinite(r["holdout_nrmse"])]
    if not scored:
        raise DataError(f"{what}: no order of the grid {list(grid)} could be fitted and simulated on the hold-out "
                        "part of the estimation data; give the orders explicitly")
    best = min(r["holdout_nrmse"] for r in scored)
    chosen = min(r["order"] for r in scored if r["holdout_nrmse"] <= best * (1.0 + TOLERANCE))
    for r in rows:
        r["chosen"] = r["order"] == chosen
    return chosen, rows


def select_oe_orders(records: list[Record], nk: list[int], max_order: int = 12, nb=None, nf=None
                     ) -> tuple[int, list[dict[str, Any]]]:
    """Order n (nb = nf = n unless given) of an OE model by hold-out free-run error (module docstring)."""
    OE = get_identifier("oe")  # through the registry: sysid.pem calls this module when its orders are open
    grid = [n for n in ORDER_GRID if n <= int(max_order)] or [1]
    return _search(lambda n: OE(nb=nb if nb is not None else n, nf=nf if nf is not None else n, nk=nk,
                                max_iter=50), records, grid, "oe order selection")


def select_arx_orders(records: list[Record], nk: int, max_order: int = 100, probe=None
                      ) -> tuple[int, list[dict[str, Any]]]:
    """Order n (ny = nu = n) of an ARX model by hold-out free-run error (module docstring). ``probe``: an ARX
    whose other options (intercept) the candidates copy."""
    ARX = get_identifier("arx")  # through the registry: sysid.linear calls this module for orders="auto"
    grid = [n for n in ORDER_GRID if n <= int(max_order)] or [1]
    intercept = bool(getattr(probe, "intercept", False))
    return _search(lambda n: ARX(ny=n, nu=n, nk=nk, intercept=intercept), records, grid, "arx order selection")


_ORDER_KEYS = {"arx": ("ny", "nu"), "armax": ("ny", "nu", "ne"), "oe": ("nb", "nf"), "bj": ("nb", "nf", "nc", "nd"),
               "n4sid": ("nx",)}


def order_table(identifier: str, est: Record | Sequence[Record], val: Record | Sequence[Record] | None = None,
                grid: Sequence[int] = (1, 2, 3, 4, 6, 8, 10, 12), options: dict[str, Any] | None = None
                ) -> list[dict[str, Any]]:
    """One row per order n (every order key of ``identifier`` set to n): n_parameters, AIC, BIC (estimation data,
    one-step errors) and free-run R² / NRMSE on ``val`` (or None). ``options`` are further constructor options."""
    from sysid.evaluate import evaluate

    if identifier not in _ORDER_KEYS:
        raise ConfigError(f"order table: identifier {identifier!r} has no order grid; valid: {', '.join(_ORDER_KEYS)}")
    cls = get_identifier(identifier)
    est_l = [est] if isinstance(est, Record) else list(est)
    rows = []
    for n in grid:
        model = cls(**{**(options or {}), **{k: int(n) for k in _ORDER_KEYS[identifier]}})
        try:
            model.fit(est_l if len(est_l) > 1 else est_l[0])
        except (DataError, ConfigError, np.linalg.LinAlgError) as exc:
            rows.append({"order": int(n), "error": str(exc)})
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DivergenceWarning)
            skip = int(model.max_lag_)
            e = np.concatenate(
                [
                    (np.asarray(r.y, float) - np.asarray(model.predict(r, 1), float)).reshape(len(r), -1)[skip:]
                    for r in est_l
                ]
            )
        N, p = e.shape[0], int(model.n_parameters_)
        V = float(np.mean(e ** 2)) if np.isfinite(e).all() else math.inf
        row = {"order": int(n), "n_parameters": p,
               "aic": N * math.log(max(V, 1e-300)) + 2 * p if np.isfinite(V) else None,
               "bic": N * math.log(max(V, 1e-300)) + p * math.log(N) if np.isfinite(V) else None}
        if val is not None:
            fr = evaluate(model, val, horizons={"free_run": None})["free_run"]
            row.update(val_r2=fr["r2"], val_nrmse=fr["nrmse"])
        rows.append(row)
    return rows


def plot_order_table(rows: list[dict[str, Any]], path: str | Path, title: str = "order selection") -> Path:
    """AIC/BIC (left axis) and validation free-run R² (right axis) against the order; PNG."""
    from sysid.plots import _save, pyplot

    ok = [r for r in rows if "error" not in r]
    fig, ax = pyplot().subplots(figsize=(6.4, 3.6))
    n = [r["order"] for r in ok]
    for key, style in (("aic", "o-"), ("bic", "s--")):
        ax.plot(n, [np.nan if r.get(key) is None else r[key] for r in ok], style, label=key.upper())
    ax.set_xlabel("order n")
    ax.set_ylabel("information criterion")
    if any("val_r2" in r for r in ok):
        ax2 = ax.twinx()
        ax2.plot(n, [np.nan if r.get("val_r2") is None else r["val_r2"] for r in ok], "k^-", label="validation R²")
        ax2.set_ylabel("validation free-run R²")
        ax2.legend(loc="center right")
    ax.legend(loc="upper center")
    ax.set_title(title)
    return _save(fig, path)
