"""The stated confidence of a named cause: the probability that it is right, calibrated on the diagnosis benchmark.

The rounds rank causes by a heuristic score (:func:`.ranking._confidence`: significance, separation from the
runner-up, clarity of the signature). A score is not a probability: on the benchmark's cases
(docs/diagnosis-benchmark.md) its bins disagree with the observed rate of right names. Here the final
``confidence`` of each catalog cause is a logistic model (Platt scaling with covariates) of what the diagnosis
knows when it concludes: the score, the F-test's p-value, the validation gain, the round, whether the cause is a
mis-sized default or a joint pair, the size of its ambiguity group, whether it is a quantiser judged by its lattice,
the verdict and how far the final residual stays above the noise. :data:`COEFFICIENTS` were fitted on one half of
the benchmark's cases and judged on the other (:mod:`benchmarks.diagnosis_bench.calibrate`); the raw score stays
under ``score``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["FEATURES", "COEFFICIENTS", "features", "calibrate_causes"]

#: the covariates, in the order of :data:`COEFFICIENTS` (after the intercept)
FEATURES = (
    "logit_score",
    "log10_p",
    "gain",
    "later_round",
    "retest",
    "joint",
    "grouped",
    "quantization",
    "unexplained",
    "log10_excess",
)
#: intercept, then one weight per feature; None: not fitted (the confidence is the score)
COEFFICIENTS: tuple[float, ...] | None = None


def features(cause: dict[str, Any], verdict: str, excess: float | None) -> np.ndarray:
    """The covariates of one named cause (:data:`FEATURES`); ``excess``: final residual variance / noise."""
    score = float(cause.get("score", cause.get("confidence", 0.0)))
    s = min(max(score, 0.01), 0.99)
    p = cause.get("p_value")
    log_p = min(-math.log10(max(float(p), 1e-300)), 30.0) if p is not None else 30.0
    before, after = cause.get("nrmse_val_before"), cause.get("nrmse_val_after")
    gain = 1.0 - float(after) / float(before) if before and after is not None and float(before) > 0 else 0.0
    return np.array(
        [
            math.log(s / (1.0 - s)),
            log_p / 10.0,
            min(max(gain, 0.0), 1.0),
            1.0 if int(cause.get("round", 1) or 0) >= 2 else 0.0,
            1.0 if cause.get("kind") == "mis-sized default" else 0.0,
            1.0 if cause.get("joint_with") else 0.0,
            1.0 if len(cause.get("group", [])) > 1 else 0.0,
            1.0 if cause.get("family") == "quantization" else 0.0,
            1.0 if verdict == "unexplained" else 0.0,
            math.log10(min(max(float(excess or 1.0), 1e-3), 1e6)),
        ]
    )


def _probability(x: np.ndarray, coef: Sequence[float]) -> float:
    z = float(coef[0] + np.dot(coef[1:], x))
    return float(1.0 / (1.0 + math.exp(-z))) if z > -700 else 0.0


def calibrate_causes(causes: list[dict[str, Any]], verdict: str, excess: float | None) -> None:
    """Replace each catalog cause's ``confidence`` by the calibrated probability (the score kept as ``score``),
    in place; the ``unexplained`` entry keeps its own."""
    for c in causes:
        if c["effect"] == "unexplained":
            continue
        c.setdefault("score", float(c["confidence"]))
        if COEFFICIENTS is not None:
            c["confidence"] = _probability(features(c, verdict, excess), COEFFICIENTS)
