"""The result of a diagnosis, typed, and its one dict view (the JSON of ``piezotwin diagnose --json``)."""

from __future__ import annotations

import dataclasses
from typing import Any

from sysid.data.record import Record
from twins.base import Twin

from .prediction import unpredictable
from .trials import Stage

__all__ = ["Diagnosis"]


@dataclasses.dataclass
class Diagnosis:
    """What :func:`twins.discrepancy.run_diagnosis` found.

    ``baseline`` is the configuration as given (calibrated), ``extended`` the one with the causes added; both
    hold their predictions and residual analyses. ``causes``, ``rounds`` and the other dict-valued fields are
    JSON-ready records (see :meth:`to_dict` for their place in the output).
    """

    verdict: str
    causes: list[dict[str, Any]]
    baseline: Stage
    extended: Stage
    twin: Twin  # the configuration diagnosed (its ranges adjusted to the records)
    calibration: dict[str, Any]
    saturation: dict[str, Any]
    rounds: list[dict[str, Any]]
    unexplained: dict[str, Any]
    residual_vs_noise: dict[str, Any]
    split: dict[str, Any]
    ranges: list[str]
    defaults: list[dict[str, Any]]
    at_bound: list[dict[str, Any]]
    est: Record
    val: Record
    seconds: float
    hybrid: dict[str, Any] | None = None  # the hybrid twin's block (:mod:`.hybrid`), with an ``unexplained`` verdict
    hybrid_twin: Any = None  # the fitted :class:`twins.hybrid.HybridTwin` itself (not in the dict view)
    sparse_term: dict[str, Any] | None = None  # a model given by its equations: the sparse term found inside them
    sparse_model: Any = None  # that term as the model's integrator takes it (not in the dict view)

    def to_dict(self, keep_stages: bool = False) -> dict[str, Any]:
        """The result as a dict: ``verdict``, ``causes``, ``baseline``, ``extended``, ``gain`` and the details
        (every trial under ``rounds``, ``unexplained``, the residual ``analysis`` of both stages, …). Analysis
        entries whose key starts with ``_`` (full correlation-test curves) are left out; ``keep_stages`` adds
        the stages and records themselves under ``_stages`` (for :func:`twins.discrepancy.report.write_report`)."""
        base, ext = self.baseline, self.extended
        kept = set(self.twin.effects) & unpredictable(self.twin)  # noise/quantisation as configured
        out = {
            "verdict": self.verdict,
            "causes": self.causes,
            "baseline": base.summary(kept),
            "extended": ext.summary(kept),
            "gain": {
                "nrmse_ratio": ext.nrmse_val / base.nrmse_val if base.nrmse_val > 0 else 1.0,
                "r2_delta": ext.r2_val - base.r2_val,
            },
            "twin": self.twin.name,
            "calibration": self.calibration,
            "saturation": self.saturation,
            "params_final": dataclasses.asdict(ext.twin.params),
            "rounds": self.rounds,
            "unexplained": self.unexplained,
            "residual_vs_noise": self.residual_vs_noise,
            "split": self.split,
            "ranges": self.ranges,
            "defaults": self.defaults,
            "at_bound": self.at_bound,
            "analysis": {
                "baseline": {"estimation": _public(base.analysis_est), "validation": _public(base.analysis_val)},
                "extended": {"estimation": _public(ext.analysis_est), "validation": _public(ext.analysis_val)},
            },
            "seconds": self.seconds,
        }
        if self.hybrid is not None:
            out["hybrid"] = self.hybrid
        if self.sparse_term is not None:
            out["sparse_term"] = self.sparse_term
        if keep_stages:
            out["_stages"] = {"baseline": base, "extended": ext, "est": self.est, "val": self.val}
        return out


def _public(a: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in a.items() if not k.startswith("_")}
