"""The settings of a diagnosis, as one typed object."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from typing import Any

from sysid.errors import ConfigError

__all__ = ["DiagnoseOptions", "VALIDATION_STARTS"]

#: how a separate validation record's start state is set (:func:`twins.discrepancy.prediction.validation_start`)
VALIDATION_STARTS = ("given", "fitted", "estimation")


@dataclasses.dataclass
class DiagnoseOptions:
    """Settings of :func:`twins.discrepancy.diagnose` (its keyword arguments).

      - ``candidates``: catalog effects to try (default every effect not in the configuration, noise excepted).
      - ``calibrate_baseline``: refit the configuration as given first; ``calibration_params``: the core parameters
        refitted with every trial (default ``twin.CALIBRATION_PARAMS``).
      - ``alpha``, ``min_rel_gain``: significance level (Bonferroni over the candidates) and least relative reduction
        of the validation NRMSE.
      - ``trial_nfev``, ``scan_nfev``, ``scan_points``, ``refine``: least-squares budgets of a full trial (effect and
        core) and of stage A (effect only), points of each parameter's pre-scan, leaders given the full refit.
      - ``max_lag``, ``max_echo_s``: lags of the correlation tests; longest echo delay searched [s].
      - ``skip``: leading samples not scored; ``split``: estimation share of ``data`` without a validation record.
      - ``generic_lags``: FIR length of the generic residual model (what no catalog effect explains).
      - ``keep_stages``: attach the predictions (``_stages``) for :func:`twins.discrepancy.report.write_report`.
      - ``retest_defaults``: re-test the deterministic effects that are on; ``follow_ranges``: fit the twin's
        amplitude limit, time constants and integration step to the records.
      - ``starts``: above 1, every candidate gets the full refit from ``starts`` points over its ranges, for effects
        that pay only once the core moves with them; about ``starts`` × candidates fits a round.
      - ``pairs``: try a leader that is not significant alone jointly with each other candidate (:mod:`.pairs`);
        None: for a model given by its equations, a leader that lowers the validation NRMSE by 5 % or more; True:
        every such leader, and a later one refitted with the causes named before it whatever its gain alone.
      - ``progress``: a callable taking one message per step, or None; ``on_round``: one line per finished round
    (trial count, leader, elapsed time), or None.
      - ``hybrid``: with an ``unexplained`` verdict, fit the hybrid twin (:mod:`.hybrid`) and report its gain.
      - ``validation_start``: the state a separate validation record starts in (the twin's
        ``INITIAL_CONDITION_PARAMS``): ``"given"`` (the configuration's), ``"fitted"`` (on the record) or
        ``"estimation"`` (the estimation record's fitted start).
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
    pairs: bool | None = None
    progress: Callable[[str], Any] | None = None
    hybrid: bool = True
    on_round: Callable[[str], Any] | None = None
    validation_start: str = "given"

    def __post_init__(self) -> None:
        for name in ("trial_nfev", "scan_nfev", "scan_points", "skip", "max_lag", "starts"):
            setattr(self, name, int(getattr(self, name)))
        if self.validation_start not in VALIDATION_STARTS:
            raise ConfigError(f"validation_start {self.validation_start!r}: give one of {', '.join(VALIDATION_STARTS)}")

    def say(self, msg: str) -> None:
        """Report one step to ``progress`` (nothing when it is not callable)."""
        if callable(self.progress):
            self.progress(msg)

    def round_done(self, msg: str) -> None:
        """Report a finished round to ``on_round`` (one line: trials, leader, elapsed time) and to ``progress``."""
        if callable(self.on_round):
            self.on_round(msg)
        elif callable(self.progress):
            self.progress(msg)
