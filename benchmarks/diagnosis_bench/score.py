"""Scores of the diagnosis benchmark: outcomes, confusion matrix, rates per stratum, detection limits,
parameter errors, the calibration of the stated confidence, CPU time.

Each case's answer is the first named catalog cause (by stated confidence), ``unexplained`` (the verdict, with
no catalog cause) or ``none``. Its outcome:

- a mechanism of the twin's catalog: ``right`` when the expected effect is the answer or in the answer's
  ambiguity group; ``missed`` when nothing was named (``none``, or ``unexplained`` alone); else ``wrong``;
- a mechanism outside the catalog: ``right`` when the verdict is ``unexplained`` and no cause is named with
  confidence ≥ 0.5, ``missed`` when the verdict is ``none``; else ``wrong``;
- no mechanism: ``right`` when the verdict is ``none``, else ``wrong`` (a false alarm).

Every named catalog cause is a probability statement: its confidence against whether it is right (the expected
effect or in its group, for a mechanism of the catalog; never for the others) gives the reliability table and
the Brier score (scikit-learn's ``calibration_curve`` bins, written out here: equal-width bins of the stated
confidence). The detection limit of a mechanism is the realised size at which a logistic fit of "something
named" against log size crosses ½ (the smallest detected size when every case was detected).
"""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from typing import Any

import numpy as np

from twins.discrepancy.confidence import CONFIDENT, attributed_verdict, calibrate_causes
from twins.discrepancy.unexplained import EXCESS_LIMIT

from .mechanisms import EXPECTED

__all__ = ["outcome", "score", "current", "CONFIDENT", "RELIABILITY_BINS"]

RELIABILITY_BINS = 10
#: strata of the sampling rate per family: the decade edges [Hz]
RATE_EDGES: dict[str, tuple[float, ...]] = {
    "cantilever": (1e3, 3e3, 10e3, 50e3),
    "acoustic": (5e6, 15e6, 40e6, 100e6),
    "user": (0.0, 1.0, 1e4, 1e6),
}


def current(row: dict[str, Any]) -> dict[str, Any]:
    """The row with its causes' confidence as the diagnosis states it now: the calibration
    (:func:`twins.discrepancy.confidence.calibrate_causes`) applied to each cause's stored raw ``score``, the
    causes re-sorted by it, and the verdict attributed by it
    (:func:`~twins.discrepancy.confidence.attributed_verdict`). A row written before the calibration was fitted
    (confidence = score) and a row written after it read the same; the stored file is not changed."""
    if "error" in row or not row.get("causes"):
        return row
    causes = [dict(c) for c in row["causes"]]
    calibrate_causes(causes, row.get("residual_vs_noise"), outside=_outside_residual(row))
    causes.sort(key=lambda c: -float(c["confidence"]))
    return dict(row, causes=causes, verdict=attributed_verdict(row["verdict"], causes))


def _outside_residual(row: dict[str, Any]) -> bool:
    """The residual verdict of a stored row: `unexplained` far above the noise (a row keeps the verdict after
    attribution, which also says `unexplained` for a residual near the noise that no cause states confidently)."""
    excess = row.get("residual_vs_noise")
    return row["verdict"] == "unexplained" and excess is not None and float(excess) > EXCESS_LIMIT


def _named(row: dict[str, Any]) -> list[dict[str, Any]]:
    return [c for c in row.get("causes", []) if c["effect"] != "unexplained"]


def _acceptable(row: dict[str, Any]) -> tuple[str, ...] | None:
    """The effects that name the case's mechanism right (None: outside the catalog or no mechanism)."""
    mech = row["case"]["mechanism"]
    return EXPECTED[row["case"]["family"]].get(mech) if mech else None


def _is_right(cause: dict[str, Any], acceptable: tuple[str, ...] | None) -> bool:
    if not acceptable:
        return False
    own = acceptable[0]
    return (
        cause["effect"] == own
        or own in cause.get("group", [])
        or (cause["effect"] in acceptable and own in cause.get("group", []))
    )


def outcome(row: dict[str, Any]) -> dict[str, Any]:
    """The case's answer and outcome (module docstring), and the confident wrong names."""
    if "error" in row:
        return {"answer": "error", "outcome": "error", "confident_wrong": False}
    named = _named(row)
    acc = _acceptable(row)
    mech = row["case"]["mechanism"]
    answer = named[0]["effect"] if named else ("unexplained" if row["verdict"] == "unexplained" else "none")
    confident_wrong = any(c["confidence"] >= CONFIDENT and not _is_right(c, acc) for c in named)
    if mech is None:
        result = "right" if row["verdict"] == "none" else "wrong"
    elif acc is None:
        result = (
            "missed"
            if row["verdict"] == "none"
            else ("right" if row["verdict"] == "unexplained" and not confident_wrong else "wrong")
        )
    elif not named:
        result = "missed"
    else:
        result = "right" if _is_right(named[0], acc) else "wrong"
    return {"answer": answer, "outcome": result, "confident_wrong": confident_wrong}


def _size(row: dict[str, Any]) -> float:
    return float(max(row.get("size_est") or 0.0, row.get("size_val") or 0.0))


def detection_limit(sizes: list[float], detected: list[bool]) -> float | None:
    """Realised size at which P(detected) = ½ by a logistic fit in log size; None without any detection."""
    s = np.log(np.maximum(np.asarray(sizes, float), 1e-12))
    d = np.asarray(detected, bool)
    if not d.any():
        return None
    if d.all():
        return float(np.exp(s.min()))
    if s[d].min() > s[~d].max():  # separable: midway between the largest miss and the smallest detection
        return float(np.exp(0.5 * (s[d].min() + s[~d].max())))
    from scipy.optimize import minimize

    def nll(theta: np.ndarray) -> float:
        z = theta[0] + theta[1] * s
        return float(np.sum(np.logaddexp(0.0, z) - d * z) + 1e-3 * theta[1] ** 2)

    res = minimize(nll, np.array([0.0, 1.0]), method="Nelder-Mead")
    a, b = res.x
    return float(np.exp(-a / b)) if b > 0 else None


def _rate(rows: list[dict[str, Any]], key: str = "right") -> dict[str, Any]:
    n = len(rows)
    k = sum(r["_o"]["outcome"] == key for r in rows)
    return {"n": n, "k": k, "rate": (k / n) if n else None, "se": math.sqrt(k * (n - k) / n**3) if n else None}


def _stratum(row: dict[str, Any]) -> dict[str, str]:
    c = row["case"]
    edges = RATE_EDGES[c["family"]]
    i = int(np.searchsorted(edges, c["fs"], side="right")) - 1
    rate = f"{edges[max(i, 0)]:g}–{edges[min(max(i, 0) + 1, len(edges) - 1)]:g} Hz"
    return {
        "family": c["family"],
        "model": c["model"],
        "est_kind": c["est_kind"],
        "val_kind": c["val_kind"],
        "rate": f"{c['family']} {rate}",
    }


def score(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Every figure of the benchmark page from the rows of a run (module docstring)."""
    rows = [current(r) for r in rows]
    rows = [dict(r, _o=outcome(r)) for r in rows]
    ok = [r for r in rows if r["_o"]["outcome"] != "error"]
    confusion: dict[str, Counter] = defaultdict(Counter)
    for r in ok:
        truth = f"{r['case']['family']}:{r['case']['mechanism'] or 'none'}"
        confusion[truth][r["_o"]["answer"]] += 1
    limits, per_mech = {}, {}
    for fam, table in EXPECTED.items():
        for mech in list(table) + _outside(fam):
            sel = [r for r in ok if r["case"]["family"] == fam and r["case"]["mechanism"] == mech]
            if not sel:
                continue
            dl = detection_limit([_size(r) for r in sel], [r["_o"]["outcome"] != "missed" for r in sel])
            limits[f"{fam}:{mech}"] = dl
            above = [r for r in sel if dl is not None and _size(r) >= 3 * dl]
            per_mech[f"{fam}:{mech}"] = {
                "all": _rate(sel),
                "above_3dl": _rate(above),
                "in_catalog": mech in table,
                "wrong": _rate(sel, "wrong"),
                "missed": _rate(sel, "missed"),
            }
    in_cat = [r for r in ok if _acceptable(r) and _size(r) >= 3 * (limits.get(_key(r)) or math.inf)]
    strata: dict[str, dict[str, Any]] = {}
    for dim in ("family", "model", "est_kind", "val_kind", "rate"):
        groups: dict[str, list] = defaultdict(list)
        for r in in_cat:
            groups[_stratum(r)[dim]].append(r)
        strata[dim] = {k: _rate(v) for k, v in sorted(groups.items())}
    none_rows = [r for r in ok if r["case"]["mechanism"] is None]
    outside = [r for r in ok if r["case"]["mechanism"] and not _acceptable(r) and r["verdict"] != "none"]
    return {
        "cases": len(rows),
        "errors": len(rows) - len(ok),
        "outcomes": dict(Counter(r["_o"]["outcome"] for r in ok)),
        "confusion": {k: dict(v) for k, v in sorted(confusion.items())},
        "detection_limits": limits,
        "per_mechanism": per_mech,
        "right_above_3dl": _rate(in_cat),
        "strata": strata,
        "confident_wrong": {"n": len(ok), "k": sum(r["_o"]["confident_wrong"] for r in ok)},
        "none_right": _rate(none_rows),
        "outside_unexplained": _rate(outside),
        "calibration": calibration(ok),
        "parameter_errors": parameter_errors(ok),
        "cpu_s": {fam: _quantiles([r["cpu_s"] for r in ok if r["case"]["family"] == fam]) for fam in EXPECTED},
    }


def _key(row: dict[str, Any]) -> str:
    return f"{row['case']['family']}:{row['case']['mechanism']}"


def _outside(family: str) -> list[str]:
    from .mechanisms import TWIN_MECHANISMS

    return [m for m in TWIN_MECHANISMS[family] if m not in EXPECTED[family]]


def _quantiles(v: list[float]) -> dict[str, float | int | None]:
    if not v:
        return {"n": 0, "median": None, "p90": None, "max": None}
    a = np.asarray(v, float)
    return {"n": int(a.size), "median": float(np.median(a)), "p90": float(np.quantile(a, 0.9)), "max": float(a.max())}


def calibration(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Reliability table and Brier score of every named catalog cause's confidence."""
    conf, hit = [], []
    for r in rows:
        acc = _acceptable(r)
        for c in _named(r):
            conf.append(float(c["confidence"]))
            hit.append(1.0 if _is_right(c, acc) else 0.0)
    if not conf:
        return {"n": 0, "brier": None, "bins": []}
    p, y = np.asarray(conf), np.asarray(hit)
    edges = np.linspace(0.0, 1.0, RELIABILITY_BINS + 1)
    idx = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, RELIABILITY_BINS - 1)
    bins = []
    for b in range(RELIABILITY_BINS):
        m = idx == b
        if m.any():
            bins.append(
                {
                    "lo": float(edges[b]),
                    "hi": float(edges[b + 1]),
                    "n": int(m.sum()),
                    "stated": float(p[m].mean()),
                    "observed": float(y[m].mean()),
                }
            )
    return {"n": int(p.size), "brier": float(np.mean((p - y) ** 2)), "bins": bins}


#: mechanism → (truth key, the fitted parameters that estimate it, how the truth maps onto them)
PARAM_CHECKS: dict[str, tuple[str, tuple[str, ...], Any]] = {
    "delay": ("delay_s", ("input_delay_s", "generic_input_delay_s"), lambda v: v),
    "drive_lowpass": ("corner_hz", ("amp_bandwidth_hz",), lambda v: v),
    "sensor_lowpass": ("corner_hz", ("sensor_bandwidth_hz", "generic_sensor_bandwidth_hz"), lambda v: v),
    "quantization": ("step", ("quant_um", "quant_step", "generic_quant_step"), lambda v: v),
    "second_mode": ("share", ("mode2_share",), lambda v: v),
    "creep": ("rate", ("creep_per_decade",), lambda v: v),
    "temperature": ("delta", ("temperature_offset_k",), lambda v: v),
    "gap": ("delta", ("distance_offset_m",), lambda v: v),
    "offset": ("offset", ("sensor_offset", "generic_sensor_offset"), lambda v: v),
}


def parameter_errors(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Relative error of the fitted parameter of right names, per mechanism (median, 90th percentile)."""
    out: dict[str, list[float]] = defaultdict(list)
    for r in rows:
        mech = r["case"]["mechanism"]
        if mech not in PARAM_CHECKS or r["_o"]["outcome"] != "right":
            continue
        key, names, fn = PARAM_CHECKS[mech]
        cause = _named(r)[0]
        got = next((cause["params"][n] for n in names if n in cause.get("params", {})), None)
        truth = r["params"].get(key)
        if got is None or truth is None or not isinstance(got, (int, float)):
            continue
        truth = fn(truth)
        if truth:
            out[f"{r['case']['family']}:{mech}"].append(abs(float(got) - float(truth)) / abs(float(truth)))
    return {k: _quantiles(v) for k, v in sorted(out.items())}
