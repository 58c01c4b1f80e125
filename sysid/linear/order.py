"""Delay estimation and order selection for the linear identifiers (``arx``, ``oe``, ``bj``, ``n4sid``).

- :func:`delay_estimate` (MATLAB's ``delayest`` in spirit): a least-squares FIR of lags 0 … M per input (Ljung,
  *System Identification*, 2nd ed., §7.3); the delay of input i is the largest k ≤ ``max_delay`` such that
  dropping its first j ≤ k taps raises the residual sum of squares not significantly (F test of nested models
  at level ``alpha``; Seber & Lee, §4.3). A joint test still works for band-limited inputs, whose single taps
  are poorly determined while their sum is not. Normal equations from :mod:`sysid.linear.fir`: O(M²) memory.
- :func:`order_table`: an identifier over a grid of orders, each fit scored by AIC and BIC on the estimation data
  (Ljung §16.4, eq. 16.33) and by the free-run error on validation data (§16.5); :func:`plot_order_table`.
- :func:`select_arx_orders`, :func:`select_oe_orders`, :func:`select_n4sid_order`: what the identifiers do without
  orders — each order of the grid fitted without the last ``HOLDOUT`` of each record (its first
  ``SEARCH_MAX_SAMPLES``), its free run scored there (NRMSE), the smallest order within ``TOLERANCE`` of the best
  kept (or within the NRMSE's own std on a short hold-out). The reference is the system's memory, measured
  first (:func:`reference_fir`, the FIR chosen on the same hold-out); the search stops early (``PATIENCE``) only
  once a candidate is within ``REF_MARGIN_R2`` of it, since a lightly damped system's low orders can all simulate
  badly. A choice on the grid's end (``corner``) or short of the FIR (``below_reference``) raises an
  :class:`OrderSearchWarning`. The table is the model's ``order_table_`` (JSON ``order_selection``), the rest its
  ``order_search_`` (JSON ``order_search``).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError, DivergenceWarning, OrderSearchWarning
from sysid.registry import get_identifier

__all__ = [
    "delay_estimate",
    "order_table",
    "plot_order_table",
    "select_oe_orders",
    "select_arx_orders",
    "select_n4sid_order",
    "reference_fir",
    "OrderSearchWarning",
    "ORDER_GRID",
]

ORDER_GRID = (1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 40, 48, 64, 80, 100, 128)
HOLDOUT = 0.3
PATIENCE = 3
REF_MARGIN_R2 = 0.005
FIR_MAX_ORDER = 2048
SEARCH_MAX_SAMPLES = 32_768
DELAY_MIN_EXTRA = 10
DELAY_MAX_EXTRA = 512


def delay_estimate(
    data: Record | Sequence[Record], max_delay: int = 30, n_extra: int | None = None, alpha: float = 1e-3
) -> list[int]:
    """Delay (samples) of each input from a least-squares FIR model with lags 0 … max_delay + n_extra (module
    docstring). ``n_extra=None``: the memory of the data (the tap count of :func:`reference_fir`, at least
    ``DELAY_MIN_EXTRA``, at most ``DELAY_MAX_EXTRA``), so that a long impulse response is not left in the residual,
    where it would make the F test blind to the first taps.

    Cost: the normal equations come from :func:`sysid.linear.fir.fir_normal_equations`; per input, the parameters are
    ordered with that input's lags last and reversed, so dropping its first k lags leaves a leading block, and one
    Cholesky factor G = LLᵀ with z = L⁻¹g gives every nested residual sum of squares, RSS = yᵀy − Σ_{j<q} z_j²."""
    from scipy.linalg import solve_triangular
    from scipy.stats import f as f_dist

    from sysid.linear.fir import _cholesky, fir_normal_equations

    recs = [data] if isinstance(data, Record) else list(data)
    m = recs[0].n_inputs
    if n_extra is None:
        ref = reference_fir(recs, 0)
        n_extra = DELAY_MIN_EXTRA if ref is None else min(max(ref["nb"], DELAY_MIN_EXTRA), DELAY_MAX_EXTRA)
    M = int(max_delay) + int(n_extra) + 1
    pairs = []
    yy = 0.0
    for rec in recs:
        if len(rec) <= M:
            raise DataError(f"{rec.source}: {len(rec)} samples are too few for a delay estimate over {M} lags")
        y = rec.output.reshape(len(rec), -1)[:, :1].astype(float)
        pairs.append((rec.u.reshape(len(rec), -1).astype(float), y))
        yy += float(y[M - 1 :, 0] @ y[M - 1 :, 0])
    G, g, n = fir_normal_equations(pairs, M)
    p = m * M
    dof = max(n - p, 1)
    out = []
    for i in range(m):
        perm = [k * m + j for j in range(m) if j != i for k in range(M)] + [k * m + i for k in reversed(range(M))]
        z = solve_triangular(_cholesky(G[np.ix_(perm, perm)]), g[perm, 0], lower=True, check_finite=False)
        cum = np.cumsum(z**2)
        rss0 = max(yy - float(cum[-1]), 1e-300 * max(yy, 1e-300))
        k_ok = 0
        for k in range(1, int(max_delay) + 1):
            F = ((max(yy - float(cum[p - k - 1]), 0.0) - rss0) / k) / (rss0 / dof)
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
    from sysid.evaluation.evaluate import evaluate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DivergenceWarning)
        s = evaluate(model, recs, horizons={"free_run": None})["free_run"]
    v = s["nrmse"]
    return math.inf if v is None or not np.isfinite(v) else float(v)


def reference_fir(records: list[Record], nk: int | Sequence[int]) -> dict[str, Any] | None:
    """The memory and reference level of the data: the least-squares FIR with its tap count chosen on the same
    hold-out as the order searches (:func:`sysid.linear.fir.holdout_fir_search`); ``{identifier, nb, holdout_nrmse,
    memory_samples, corner}``. ``None`` when the record is too short for it."""
    from sysid.linear.fir import holdout_fir_search

    k = int(min(nk)) if isinstance(nk, (list, tuple)) else int(nk)  # type: ignore[arg-type]
    try:
        nb, _, search = holdout_fir_search(_budget(records), k, FIR_MAX_ORDER, HOLDOUT)
    except DataError:
        return None
    return {
        "identifier": "fir",
        "nb": int(nb),
        "holdout_nrmse": float(search["best_holdout_nrmse"]),
        "memory_samples": int(search["memory_samples"]),
        "corner": bool(search["corner"]),
    }


def _budget(records: list[Record]) -> list[Record]:
    """The first ``SEARCH_MAX_SAMPLES`` of each record: what the order searches fit and score (the chosen model is
    then fitted on all the data); bounds their cost on long records."""
    return [r if len(r) <= SEARCH_MAX_SAMPLES else r.split(index=SEARCH_MAX_SAMPLES)[0] for r in records]


def _close_to(err: float, ref: dict[str, Any] | None) -> bool:
    """Whether a hold-out NRMSE is within REF_MARGIN_R2 (in R²) of the FIR reference (no reference: always)."""
    return ref is None or err**2 <= ref["holdout_nrmse"] ** 2 + REF_MARGIN_R2


def _search(
    make, records: list[Record], grid: Sequence[int], what: str, ref: dict[str, Any] | None = None
) -> tuple[int, list[dict[str, Any]], dict[str, Any]]:
    est, val = _split(_budget(records), HOLDOUT)
    rows: list[dict[str, Any]] = []
    best, since, stopped = math.inf, 0, False
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
            if since >= PATIENCE and _close_to(best, ref):
                stopped = True
                break
    scored = [r for r in rows if "holdout_nrmse" in r and np.isfinite(r["holdout_nrmse"])]
    if not scored:
        raise DataError(
            f"{what}: no order of the grid {list(grid)} could be fitted and simulated on the hold-out "
            "part of the estimation data; give the orders explicitly"
        )
    best = min(r["holdout_nrmse"] for r in scored)
    from sysid.linear.fir import (
        holdout_tolerance,  # here: sysid.linear.fir loads scipy, which the CLI's start-up must not
    )

    tol = holdout_tolerance(sum(len(r) for r in val))
    chosen = min(r["order"] for r in scored if r["holdout_nrmse"] <= best * (1.0 + tol))
    for r in rows:
        r["chosen"] = r["order"] == chosen
    corner = len(grid) > 1 and chosen == max(grid)
    short = not _close_to(best, ref)
    search = {
        "criterion": "hold-out free-run NRMSE",
        "holdout": HOLDOUT,
        "tolerance": tol,
        "grid": [int(n) for n in grid],
        "stopped_early": stopped,
        "corner": bool(corner),
        "below_reference": bool(short),
        "reference": ref,
        "memory_samples": None if ref is None else ref["memory_samples"],
    }
    if corner:
        warnings.warn(
            f"{what}: the chosen order {chosen} is the largest of the grid (raise max_order: a larger "
            "order may simulate the hold-out better)",
            OrderSearchWarning,
            stacklevel=4,
        )
    if short and ref is not None:
        warnings.warn(
            f"{what}: no order up to {max(grid)} simulates the hold-out as well as a least-squares FIR "
            f"(hold-out R² {1 - best**2:.4f} against {1 - ref['holdout_nrmse'] ** 2:.4f}); try a larger "
            "max_order or another structure",
            OrderSearchWarning,
            stacklevel=4,
        )
    return chosen, rows, search


def select_oe_orders(
    records: list[Record], nk: list[int], max_order: int = 12, nb=None, nf=None
) -> tuple[int, list[dict[str, Any]], dict[str, Any]]:
    """Order n (nb = nf = n unless given) of an OE model by hold-out free-run error (module docstring):
    ``(n, table, search)``."""
    OE = get_identifier("oe")  # through the registry: sysid.linear.pem calls this module when its orders are open
    grid = [n for n in ORDER_GRID if n <= int(max_order)] or [1]
    ref = reference_fir(records, nk)
    return _search(
        lambda n: OE(nb=nb if nb is not None else n, nf=nf if nf is not None else n, nk=nk, max_iter=50),
        records,
        grid,
        "oe order selection",
        ref,
    )


def select_arx_orders(
    records: list[Record], nk: int, max_order: int = 100, probe=None
) -> tuple[int, list[dict[str, Any]], dict[str, Any]]:
    """Order n (ny = nu = n) of an ARX model by hold-out free-run error (module docstring): ``(n, table,
    search)``. ``probe``: an ARX whose other options (intercept) the candidates copy."""
    ARX = get_identifier("arx")  # through the registry: sysid.linear calls this module for orders="auto"
    grid = [n for n in ORDER_GRID if n <= int(max_order)] or [1]
    intercept = bool(getattr(probe, "intercept", False))
    ref = reference_fir(records, nk)
    return _search(lambda n: ARX(ny=n, nu=n, nk=nk, intercept=intercept), records, grid, "arx order selection", ref)


def select_n4sid_order(
    records: list[Record], options: dict[str, Any], max_order: int, extra: Sequence[int] = ()
) -> tuple[int, list[dict[str, Any]], dict[str, Any]]:
    """State dimension nx of N4SID by hold-out free-run error (module docstring) over the grid up to ``max_order``
    and the orders in ``extra`` (the singular-value choice); candidates take ``options`` (block rows, focus) with
    the fewest jackknife segments (their uncertainty is not used)."""
    N4SID = get_identifier("n4sid")  # through the registry: sysid.linear.subspace calls this module when nx is open
    grid = sorted({n for n in ORDER_GRID if n <= int(max_order)} | {int(n) for n in extra if 1 <= n <= max_order})
    ref = reference_fir(records, 0)
    return _search(
        lambda n: N4SID(**{**options, "nx": n, "segments": 2}), records, grid or [1], "n4sid order selection", ref
    )


_ORDER_KEYS = {
    "arx": ("ny", "nu"),
    "armax": ("ny", "nu", "ne"),
    "oe": ("nb", "nf"),
    "bj": ("nb", "nf", "nc", "nd"),
    "n4sid": ("nx",),
}


def order_table(
    identifier: str,
    est: Record | Sequence[Record],
    val: Record | Sequence[Record] | None = None,
    grid: Sequence[int] = (1, 2, 3, 4, 6, 8, 10, 12),
    options: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """One row per order n (every order key of ``identifier`` set to n): n_parameters, AIC, BIC (estimation data,
    one-step errors) and free-run R² / NRMSE on ``val`` (or None). ``options`` are further constructor options."""
    from sysid.evaluation.evaluate import evaluate

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
        V = float(np.mean(e**2)) if np.isfinite(e).all() else math.inf
        row = {
            "order": int(n),
            "n_parameters": p,
            "aic": N * math.log(max(V, 1e-300)) + 2 * p if np.isfinite(V) else None,
            "bic": N * math.log(max(V, 1e-300)) + p * math.log(N) if np.isfinite(V) else None,
        }
        if val is not None:
            fr = evaluate(model, val, horizons={"free_run": None})["free_run"]
            row.update(val_r2=fr["r2"], val_nrmse=fr["nrmse"])
        rows.append(row)
    return rows


def plot_order_table(rows: list[dict[str, Any]], path: str | Path, title: str = "order selection") -> Path:
    """AIC/BIC (left axis) and validation free-run R² (right axis) against the order; PNG."""
    from sysid.report.plots import _save, pyplot

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
