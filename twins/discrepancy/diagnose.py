"""The discrepancy loop: calibrate, analyse the residual, name the cause, extend the twin, measure the gain.

``diagnose(twin, data, val)`` runs these steps, each a function below with typed inputs and outputs:

0. **Prepare** (:func:`_prepare`): split off a validation record that carries excitation, let the twin's ranges
   follow the records (:mod:`.realdata`), and find saturation rails (:func:`.features.saturation_rails`): where
   a record sits exactly at its extreme on a flat top while the configuration predicts beyond it, every
   prediction of it is compared clipped to the rails, as the instrument showed it.
1. **Calibrate** (:func:`_calibrate`) the core parameters to the estimation record, noise off, the effects that
   are on held at their configured sizes (a mis-sized default shows as the gain of its re-test, :mod:`.defaults`);
   adopted only when significantly better than the configuration as given (F-test on effective samples).
2. **Analyse** the residual ``e = y − ŷ`` of both records (:func:`.trials.make_stage`, :func:`.features.analyse`).
3. **Trial every catalog effect** the configuration lacks (:func:`.candidates.round_trials`): pre-scan its
   parameters (:mod:`.prescan`), fit them with the core by free-run output error (:mod:`.trials`), re-simulate the
   validation record. The validation gain is the evidence; the signature score (:mod:`.evidence`) explains it.
4. **Rank** (:mod:`.ranking`): F-test (Bonferroni over the candidates) and a relative validation NRMSE reduction
   of at least ``min_rel_gain``, the group the data cannot tell apart, the confidence.
5. **Extend** (:mod:`.rounds`): keep a significant leader and repeat (``max_rounds``); then revisit each added
   effect but the last, since a first-round leader can mimic the sum of two hidden effects.
6. **Verdict** (:func:`_conclude`): ``unexplained`` when the final residual stays far above the noise measured
   from the data and is more than coloured noise (:func:`.unexplained.structure`; its structure described by
   :func:`.unexplained.generic_residual_model`, and with ``hybrid`` a black-box remainder fitted,
   :mod:`.hybrid`), else ``discrepancy`` with causes or ``none``.

:func:`run_diagnosis` returns the typed :class:`.result.Diagnosis`; :func:`diagnose` its dict view.
"""

from __future__ import annotations

import dataclasses
import inspect
import time
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from twins.base import Twin, param_info

from . import defaults as dflt
from . import evidence as ev
from . import features as ft
from . import ranges as rg
from . import realdata
from . import unexplained as unx
from .band import mark_outside_band
from .candidates import adopt
from .confidence import attributed_verdict, calibrate_causes
from .fields import core_for, numeric_fields, quant_params
from .hybrid import hybrid_block
from .inside import follow_calibration, sparse_inside
from .options import DiagnoseOptions
from .prediction import (
    MIN_SCORED_SAMPLES,
    NOISE_EFFECTS,
    deterministic,
    significance,
    significantly_better,
    simulate,
    simulate_val,
    sse,
    unpredictable,
    validation_start,
    with_rails,
)
from .result import Diagnosis
from .rounds import Extension, extend
from .transfer import mark_untransferable
from .trials import Stage
from .unexplained import generic_residual_model

__all__ = ["diagnose", "run_diagnosis", "NOISE_EFFECTS", "significance"]


def diagnose(
    twin: Twin,
    data: Record,
    val: Record | None = None,
    max_rounds: int = 3,
    *,
    threads: int | None = None,
    **options: Any,
) -> dict[str, Any]:
    """Diagnose what ``twin`` gets wrong about ``data``; return the JSON-able result (:meth:`.Diagnosis.to_dict`).

    ``data`` and ``val`` are the estimation and validation records (without ``val`` the data is split at
    ``split`` of its length); at most ``max_rounds`` effects are added. The keyword ``options`` are the fields
    of :class:`.options.DiagnoseOptions`; ``threads`` as for :func:`run_diagnosis`.

    Returns a dict with ``verdict``, ``causes``, ``baseline``, ``extended``, ``gain`` and the details
    ``rounds`` (every trial with its numbers), ``unexplained`` and ``analysis`` (baseline and final residual
    numbers on both records).
    """
    opts = DiagnoseOptions(**options)
    return run_diagnosis(twin, data, val, max_rounds, opts, threads=threads).to_dict(keep_stages=opts.keep_stages)


def run_diagnosis(
    twin: Twin,
    data: Record,
    val: Record | None = None,
    max_rounds: int = 3,
    options: DiagnoseOptions | None = None,
    *,
    threads: int | None = None,
) -> Diagnosis:
    """The diagnosis as a typed :class:`.result.Diagnosis` (steps in the module docstring).

    ``threads``: threads of the twin's compiled (numba) kernels during the diagnosis. Default: 1 for records
    under 2²⁰ samples in all — the diagnosis simulates short records thousands of times, and a parallel
    kernel's fork-join costs more than its work there (docs/diagnosis.md, "Measurements behind the code's
    choices"); None keeps numba's setting for longer records.
    """
    opts = options if options is not None else DiagnoseOptions()
    n_total = sum(len(r) for r in (data, val) if isinstance(r, Record))
    nt = threads if threads is not None else (1 if n_total < _PARALLEL_FROM else None)
    with _numba_threads(nt):
        inp = _prepare(twin, data, val, opts)
        cal = _calibrate(inp, opts)
        follow_calibration(inp, cal, opts)  # a twin whose ranges follow its calibrated state (twins.equations)
        base = adopt(inp, cal.twin, opts)
        ext = _extend(inp, cal, base, max_rounds, opts)
        return _conclude(inp, cal, base, ext, opts)


_PARALLEL_FROM = 1 << 20  # samples (estimation + validation) from which numba's own thread count is kept


class _numba_threads:
    """Context manager: numba's thread count for the current thread (thread-local in numba), restored after."""

    def __init__(self, n: int | None):
        self.n = n
        self.prev: int | None = None

    def __enter__(self):
        if self.n is not None:
            try:
                import numba

                self.prev = numba.get_num_threads()
                # NUMBA_NUM_THREADS is set on numba.config at import from the environment, unseen by the checker
                cap = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
                numba.set_num_threads(max(1, min(int(self.n), cap)))
            except ImportError:  # pragma: no cover - numba is a dependency; without it nothing to set
                self.prev = None
        return self

    def __exit__(self, *exc):
        if self.prev is not None:
            import numba

            numba.set_num_threads(self.prev)
        return False


# ---------------------------------------------------------------------------------------------- 0. prepare
@dataclasses.dataclass
class _Inputs:
    """The records and configuration the loop works on."""

    twin: Twin  # ranges adjusted to the records
    given: Twin  # its deterministic prediction as configured
    est: Record  # with the saturation rails attached
    val: Record
    core: list[str]  # core calibration parameters (numeric, with a range)
    split: dict[str, Any]
    ranges: list[str]
    saturation: dict[str, Any]
    t_start: float
    substep_auto: bool = False  # the integration sub-step follows the configuration (:func:`.ranges.substep_for`)
    # the noise level of both records (:func:`.unexplained.records_noise`)
    noise: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def railed(self) -> bool:
        """The estimation record has rails: the calibration must compare the clipped prediction."""
        return self.saturation["estimation"]["lo"] is not None or self.saturation["estimation"]["hi"] is not None


def _prepare(twin: Twin, data: Record, val: Record | None, opts: DiagnoseOptions) -> _Inputs:
    """Check the input, split, follow the ranges, and detect the saturation rails of both records."""
    if not isinstance(twin, Twin):
        raise ConfigError("diagnose: twin must be a Twin instance")
    substep_auto = bool(opts.follow_ranges and rg.substep_followed(twin))
    twin, data, val, split_info, range_notes = realdata.prepare(twin, data, val, opts.split, opts.follow_ranges)
    if data.n_inputs != 1 or data.n_outputs != 1:
        raise DataError(f"{data.source}: diagnose handles single-input single-output records")
    if abs(data.fs - val.fs) > 1e-9 * data.fs:
        raise DataError(f"estimation and validation records have different fs ({data.fs} and {val.fs} Hz)")
    short = min((len(data), "estimation"), (len(val), "validation"))
    if short[0] - opts.skip < MIN_SCORED_SAMPLES:
        raise DataError(
            f"skip={opts.skip} leaves {max(short[0] - opts.skip, 0)} of the {short[0]} {short[1]} samples "
            f"to score; the diagnosis needs at least {MIN_SCORED_SAMPLES} (skip <= "
            f"{max(short[0] - MIN_SCORED_SAMPLES, 0)})"
        )
    unknown = [e for e in (opts.candidates or []) if e not in twin.EFFECTS]
    if unknown:
        raise ConfigError(f"unknown effect {unknown[0]!r} for twin {twin.name}; valid: {', '.join(twin.EFFECTS)}")
    t_start = time.perf_counter()
    core = list(opts.calibration_params if opts.calibration_params is not None else twin.CALIBRATION_PARAMS)
    fit = numeric_fields(twin, core)
    if opts.calibration_params is not None and len(fit) < len(set(core)):
        bad = next(c for c in core if c not in fit)
        raise ConfigError(
            f"cannot calibrate {bad!r} of twin {twin.name}: not a numeric parameter with a range; "
            f"valid: {', '.join(numeric_fields(twin, param_info(type(twin.params))))}"
        )
    core = fit
    opts.say(f"diagnose {twin.name}: {len(data)} + {len(val)} samples" + "".join(f"; {n}" for n in range_notes))
    given = deterministic(twin)
    saturation = {
        "estimation": ft.saturation_rails(data.output, simulate(given, data)),
        "validation": ft.saturation_rails(val.output, simulate_val(given, data, val)),
    }
    data, val = with_rails(data, saturation["estimation"]), with_rails(val, saturation["validation"])
    noise = unx.records_noise(data, val)
    return _Inputs(twin, given, data, val, core, split_info, range_notes, saturation, t_start, substep_auto, noise)


# ---------------------------------------------------------------------------------------------- 1. calibrate
@dataclasses.dataclass
class _Calibrated:
    """The baseline configuration and what the calibration did."""

    twin: Twin
    prior: Twin  # the configuration as given (deterministic)
    info: dict[str, Any]
    retest: list[str]  # effects that are on, re-tested in every round
    held: set[str]  # their parameters, held at the configured values in the baseline fit


def _calibrate(inp: _Inputs, opts: DiagnoseOptions) -> _Calibrated:
    """Fit the core parameters (not those of the effects that are on) to the estimation record."""
    current = inp.given
    retest = dflt.retestable(current, unpredictable(inp.twin), NOISE_EFFECTS) if opts.retest_defaults else []
    held = dflt.owned_fields(current, retest)
    core0 = [c for c in core_for(current, inp.core) if c not in held]
    info: dict[str, Any] = {}
    if opts.calibrate_baseline and core0:
        current, info = _fit_baseline(current, core0, inp, opts)
        inp.val, start = validation_start(current, inp.given, inp.est, inp.val, core0, opts.validation_start, opts.skip)
        if start is not None:  # the state a separate validation record starts in
            info["validation_start"] = {"how": opts.validation_start, **start}
            opts.say(f"validation record's start ({opts.validation_start}): {start}")
    return _Calibrated(current, inp.given, info, retest, held)


def _fit_baseline(current: Twin, core0: list[str], inp: _Inputs, opts: DiagnoseOptions) -> tuple[Twin, dict[str, Any]]:
    est, skip = inp.est, opts.skip
    opts.say("calibrating the configuration as given")
    # the twin's own calibration does not know the rails: output error on the clipped prediction
    own = not inp.railed and _own_calibration(current)
    res = realdata.calibrate_core(current, est, inp.val, core0, own, simulate)
    fitted = deterministic(res.twin)
    info: dict[str, Any] = {"fitted": res.fitted, "stderr": res.stderr}

    def cost(tw: Twin) -> float:
        return sse(est.output, simulate(tw, est), skip)

    # parameters that end at a bound: the bound widened once and the fit retried
    fitted, wide_info = realdata.refit_at_bounds(fitted, core0, est, cost, simulate, opts.say)
    info = wide_info or info
    # keep the calibration only if it improves on the configuration as given (an unconverged fit would
    # otherwise hand every trial that restarts from the prior a spurious gain), and by more than fitting the
    # noise would: the F-test on the estimation residual's effective samples (coloured noise has few), with
    # every fitted parameter counted. A fit to the noise carries it into the validation record as a
    # deterministic error no effect explains (docs/discrepancy-notes.md, "a calibration must beat the noise").
    y_fit = simulate(fitted, est)
    c_given, c_fit = cost(current), sse(est.output, y_fit, skip)
    if c_fit > c_given:
        info["kept"] = False
        info["note"] = "calibration did not improve on the given configuration; the given one is used"
        return current, info
    n_eff = ft.effective_samples(est.output[skip:] - y_fit[skip:])
    k = max(len(info.get("fitted", {})), 1)
    if significantly_better(c_given, c_fit, n_eff, k, opts.alpha, 0.0):
        return fitted, info
    info["kept"] = False
    info["note"] = (
        f"calibration not significantly better than the given configuration on the estimation record (SSE "
        f"{c_fit:.4g} against {c_given:.4g}, {k} parameters, {n_eff:.0f} effective samples); the given one is used"
    )
    return current, info


def _own_calibration(twin: Twin) -> bool:
    """The twin's own ``calibrate`` takes the validation record and the parameter names (as
    :meth:`twins.base.Twin.calibrate` does); else the generic output-error fit is used."""
    params = inspect.signature(twin.calibrate).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return True
    return "val" in params and "names" in params


# ---------------------------------------------------------------------------------------------- 3.–5. extend
def _extend(inp: _Inputs, cal: _Calibrated, base: Stage, max_rounds: int, opts: DiagnoseOptions) -> Extension:
    """Greedy rounds of trials, then the revisit of each named effect (:mod:`.rounds`)."""
    return extend(inp, cal, base, max_rounds, opts)


# ---------------------------------------------------------------------------------------------- 6. verdict
def _conclude(inp: _Inputs, cal: _Calibrated, base: Stage, ext: Extension, opts: DiagnoseOptions) -> Diagnosis:
    """Quantisation and unexplained structure beside the causes found, the verdict, the typed result."""
    stage = ext.stage
    causes = ext.causes + _quantization_causes(inp, opts)
    unexplained = _generic_structure(inp, stage, opts)
    if unexplained["significant"]:
        causes.append(
            {
                "effect": "unexplained",
                "confidence": float(1 - unexplained["p_value"]) * 0.5,
                "evidence": (
                    "structure no catalog effect explains: a generic residual model (FIR of u, u², u³ "
                    f"and a trend) removes {100 * (1 - unexplained['nrmse_ratio'] ** 2):.0f} % of the "
                    f"validation residual variance; {unexplained['description']}"
                ),
                "params": {},
            }
        )
    verdict, beyond, at_bound = realdata.final_verdict(
        inp.val, stage.yhat_val, causes, stage.twin, cal.info, opts.skip, inp.noise
    )
    mark_outside_band(causes, stage.twin, max(inp.est.fs, inp.val.fs), max(inp.est.duration, inp.val.duration))
    mark_untransferable(causes, stage.twin, inp.est, inp.val, stage.yhat_val, opts.skip, say=opts.say)
    calibrate_causes(causes, beyond.get("excess_ratio"), outside=verdict == "unexplained")
    causes.sort(key=lambda c: -float(c["confidence"]))  # strongest first (stable: round order among equals)
    residual_verdict, verdict = verdict, attributed_verdict(verdict, causes)
    opts.say(f"verdict {verdict}")
    defaults = dflt.contributions(stage.twin, cal.retest, inp.est, inp.val, opts.skip)
    hybrid, hybrid_twin = None, None
    if residual_verdict == "unexplained" and opts.hybrid:  # a remainder to model: above the noise only
        opts.say("fitting the hybrid twin (black-box remainder)")
        hybrid, hybrid_twin = hybrid_block(inp, stage, opts.skip)
    sparse, sparse_term = sparse_inside(inp, stage, base, residual_verdict, causes, opts)
    return Diagnosis(
        verdict=verdict,
        causes=causes,
        baseline=base,
        extended=stage,
        twin=inp.twin,
        calibration=cal.info,
        saturation=inp.saturation,
        rounds=ext.rounds,
        unexplained=unexplained,
        residual_vs_noise=beyond,
        split=inp.split,
        ranges=inp.ranges,
        defaults=defaults,
        at_bound=at_bound,
        est=inp.est,
        val=inp.val,
        seconds=time.perf_counter() - inp.t_start,
        hybrid=hybrid,
        hybrid_twin=hybrid_twin,
        sparse_term=sparse,
        sparse_model=sparse_term,
    )


def _quantization_causes(inp: _Inputs, opts: DiagnoseOptions) -> list[dict[str, Any]]:
    """Quantisation: no prediction can follow it, the evidence is the lattice of the measured values."""
    twin, out = inp.twin, []
    for e in [
        c
        for c in (opts.candidates if opts.candidates is not None else twin.EFFECTS)
        if c in twin.EFFECTS and c not in twin.effects and ev.family_of(twin.EFFECTS[c]) == "quantization"
    ]:
        q = ft.quantization_step(np.concatenate([inp.est.y, inp.val.y]))
        s = ev.signature_evidence(twin.EFFECTS[e], {"quantization": q}, twin)
        if q.get("p_value", 1.0) < opts.alpha * 1e-3 and s["score"] > 0.3:
            out.append(
                {
                    "effect": e,
                    "confidence": float(s["score"]),
                    "params": quant_params(twin, e, q["step"]),
                    "evidence": (
                        s["text"] + "; quantisation error depends on the noise, so adding it cannot "
                        "lower the residual (no validation gain expected)"
                    ),
                    "family": "quantization",
                    "round": 0,
                }
            )
    return out


def _generic_structure(inp: _Inputs, stage: Stage, opts: DiagnoseOptions) -> dict[str, Any]:
    """What no catalog entry explains: the generic residual model, significant by the F-test and a relative
    gain of at least ``max(5·min_rel_gain, 2 %)``, and the residual described in words."""
    e_est = inp.est.y - stage.yhat_est
    e_val = inp.val.y - stage.yhat_val
    gen = generic_residual_model(inp.est, inp.val, e_est, e_val, opts.generic_lags, opts.skip)
    sig = bool(gen["p_value"] < opts.alpha and (1.0 - gen["nrmse_ratio"]) >= max(5 * opts.min_rel_gain, 0.02))
    return {"significant": sig, **gen, "description": ev.describe_generic(stage.analysis_val)}
