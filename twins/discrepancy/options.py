"""The settings of a diagnosis, as one typed object."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["DiagnoseOptions"]


@dataclasses.dataclass
class DiagnoseOptions:
    """Settings of :func:`twins.discrepancy.diagnose` (its keyword arguments).

    candidates
        Catalog effects to try (default: every effect not in the configuration, except noise).
    calibrate_baseline
        Refit the configuration as given before anything is added.
    calibration_params
        Core parameters refitted with every trial (default ``twin.CALIBRATION_PARAMS``).
    alpha, min_rel_gain
        Significance level (Bonferroni over the candidates) and minimum relative validation NRMSE reduction.
    trial_nfev, scan_nfev, scan_points, refine
        Budgets: least-squares evaluations of a full trial (effect + core parameters) and of the first-stage
        fit (effect parameters only, core held), points of each parameter pre-scan, and how many of the best
        first-stage candidates get the full refit.
    max_lag, max_echo_s
        Lags of the correlation tests and nonlinear correlations; longest echo delay searched [s].
    skip
        Leading samples not scored (initial transient).
    split
        Estimation share of ``data`` when no validation record is given.
    generic_lags
        FIR length of the generic residual model (what no catalog effect explains).
    keep_stages
        Attach the predictions (``_stages``) to the dict result, for :func:`twins.discrepancy.report.write_report`.
    retest_defaults
        Re-test the deterministic effects that are on (their own parameters refitted).
    follow_ranges
        Adjust the twin's amplitude limit, time constants and integration step to the records.
    starts
        With ``starts > 1`` every candidate gets the full refit (its parameters with the core), from its first-stage
        fit and from ``starts − 1`` points spread over its parameters' ranges, the best estimation fit kept
        (:func:`.rounds.refine_trials`). For models whose effects pay only once the core moves with them (a
        sensor offset under a square-root outflow law: no gain with the core held); about ``starts`` × the
        candidates full fits per round, so meant for models that simulate in milliseconds.
    pairs
        When a round's leader is not significant alone and the residual is still far above the noise, try it
        jointly with each other candidate (:mod:`.pairs`): two effects that mask each other are named together
        when their joint gain is significant with both effects' parameters counted (Bonferroni over every
        single and joint trial).
    progress
        Callable taking one message per step, or None.
    hybrid
        With an ``unexplained`` verdict, fit the hybrid twin (the final configuration plus a black-box remainder,
        :mod:`.hybrid`) and report its validation gain under ``hybrid``.
    """

    candidates: Sequence[str] | None = None
    calibrate_baseline: bool = True
    calibration_params: Sequence[str] | None = None
    alpha: float = 0.01
    min_rel_gain: float = 0.005
    trial_nfev: int = 25
    scan_nfev: int = 15
    scan_points: int = 13
    refine: int = 3
    max_lag: int = 20
    max_echo_s: float | None = None
    skip: int = 0
    split: float = 0.6
    generic_lags: int = 10
    keep_stages: bool = False
    retest_defaults: bool = True
    follow_ranges: bool = True
    starts: int = 1
    pairs: bool = False
    progress: Callable[[str], Any] | None = None
    hybrid: bool = True

    def __post_init__(self) -> None:
        for name in ("trial_nfev", "scan_nfev", "scan_points", "skip", "max_lag", "starts"):
            setattr(self, name, int(getattr(self, name)))

    def say(self, msg: str) -> None:
        """Report one step to ``progress`` (nothing when it is not callable)."""
        if callable(self.progress):
            self.progress(msg)
