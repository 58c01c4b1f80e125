"""Fitting the diagnosis's confidence (:mod:`twins.discrepancy.confidence`) on the benchmark's rows.

Every named catalog cause of a row whose confidence the logistic model states is one example: its covariates
(:func:`twins.discrepancy.confidence.features`, from the cause as stored) and whether it was right
(:func:`.score._is_right`). A cause a cap states for (:func:`twins.discrepancy.confidence.capped`) is left out:
whatever the model says of it, it states the cap, and fitted with them the model was pulled toward classes it does
not speak for (700 cases, ten folds held out: the largest gap in a bin of ≥ 20 causes 0.12 fitted on every cause,
0.08 on the uncapped ones). A logistic regression with a small ridge (L2, λ = 1) is fitted by Newton's method;
it is judged held out by ten folds of cases (a case's causes are predicted by the model fitted on the cases of the
other nine folds, seed mod 10: all causes of one case stay in one fold), then refitted on all rows for the
coefficients the diagnosis uses. ``python -m benchmarks.diagnosis_bench.calibrate ROWS.jsonl`` prints both and
the coefficient tuple.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import numpy as np

from twins.discrepancy.confidence import FEATURES, capped, features

from .run import read_rows
from .score import _acceptable, _is_right, _named, _outside_residual

__all__ = ["examples", "fit", "held_out"]


def examples(rows: list[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(covariates, right, seed) of every named catalog cause of the rows that ran that no cap states for."""
    xs, ys, seeds = [], [], []
    for r in rows:
        if "error" in r:
            continue
        acc = _acceptable(r)
        for c in _named(r):
            if capped(c, _outside_residual(r)):
                continue
            xs.append(features(c, r.get("residual_vs_noise")))
            ys.append(1.0 if _is_right(c, acc) else 0.0)
            seeds.append(r["case"]["seed"])
    return np.array(xs).reshape(-1, len(FEATURES)), np.array(ys), np.array(seeds)


def fit(x: np.ndarray, y: np.ndarray, ridge: float = 1.0) -> np.ndarray:
    """Intercept and weights of the ridge-penalised logistic regression (Newton–Raphson)."""
    a = np.column_stack([np.ones(len(x)), x])
    w = np.zeros(a.shape[1])
    pen = np.full(a.shape[1], ridge)
    pen[0] = 0.0
    for _ in range(100):
        p = 1.0 / (1.0 + np.exp(-np.clip(a @ w, -35, 35)))
        grad = a.T @ (p - y) + pen * w
        hess = (a * (p * (1 - p))[:, None]).T @ a + np.diag(pen)
        step = np.linalg.solve(hess, grad)
        w -= step
        if np.max(np.abs(step)) < 1e-10:
            break
    return w


def _predict(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.clip(w[0] + x @ w[1:], -35, 35)))


def held_out(x: np.ndarray, y: np.ndarray, seeds: np.ndarray, bins: int = 10, folds: int = 10) -> dict[str, Any]:
    """Cross-validated Brier score and reliability table: the causes of the cases with ``seed % folds == k`` are
    predicted by the model fitted on the other folds (module docstring)."""
    fold = np.asarray(seeds) % folds
    if len(np.unique(fold)) < 2:
        return {"n": int(len(y)), "folds": folds, "brier": None, "bins": []}
    p = np.empty(len(y))
    for k in np.unique(fold):
        test = fold == k
        p[test] = _predict(x[test], fit(x[~test], y[~test]))
    edges = np.linspace(0, 1, bins + 1)
    idx = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, bins - 1)
    table = [
        {
            "lo": float(edges[b]),
            "n": int((idx == b).sum()),
            "stated": float(p[idx == b].mean()),
            "observed": float(y[idx == b].mean()),
        }
        for b in range(bins)
        if (idx == b).any()
    ]
    return {"n": int(len(y)), "folds": folds, "brier": float(np.mean((p - y) ** 2)), "bins": table}


if __name__ == "__main__":  # pragma: no cover - a maintainer's tool
    rows = read_rows(sys.argv[1])
    x, y, seeds = examples(rows)
    print(json.dumps(held_out(x, y, seeds), indent=1))
    print("COEFFICIENTS =", tuple(round(float(v), 6) for v in fit(x, y)))
