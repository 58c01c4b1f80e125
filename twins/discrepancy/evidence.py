"""Per-effect evidence from physical residual signatures.

An effect of a twin's catalog is matched to a *signature family* by the words of its id and its one-line
``signature`` (creep, echo, delay, compression, …). Each family reads the numbers of
:func:`twins.discrepancy.features.analyse` and returns a score in [0, 1] (how clearly the residual carries that
signature) and a sentence with the numbers behind it. The score only ranks and explains; the decisive
evidence is the trial fit in :mod:`twins.discrepancy.trials` (add the effect, fit, measure the gain).

Families whose members the data cannot tell apart from one signature alone are separated by the experiments of
:mod:`twins.discrepancy.separating`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from twins.base import EffectSpec, Twin

__all__ = ["family_of", "signature_evidence", "describe_generic", "sound_speed", "FAMILIES"]

#: family → keywords looked for in the effect id and signature (first match in this order wins)
FAMILIES: dict[str, tuple[str, ...]] = {
    "quantization": ("quantiz", "quantis", "adc"),
    "echo": ("echo", "reflect", "wall", "multipath", "reverber"),
    "crosstalk": ("crosstalk", "feedthrough", "cross-talk", "pickup"),
    "time_of_flight": ("distance", "temperature", "fluid", "sound_speed", "time_of_flight", "time-of-flight"),
    "delay": ("delay", "latency", "dead_time", "dead-time"),
    "creep": ("creep",),
    "drift": ("drift", "thermal"),
    "rate_hysteresis": ("rate_dependent", "rate-dependent"),
    "even_nl": ("even", "asymmetr"),
    "odd_nl": ("compress", "saturat", "clip", "odd", "rapp", "cubic"),
    "resonance": ("mode", "resonan"),
    "lowpass": ("lowpass", "low-pass", "bandwidth", "misalign", "diffraction", "filter"),
    "noise": ("noise",),
}


def family_of(spec: EffectSpec) -> str:
    """The signature family of a catalog effect (``generic`` when no keyword matches)."""
    text_id = spec.id.lower()
    for fam, words in FAMILIES.items():
        if any(w in text_id for w in words):
            return fam
    text = (spec.signature + " " + spec.description).lower()
    for fam, words in FAMILIES.items():
        if any(w in text for w in words):
            return fam
    return "generic"


def sound_speed(twin: Twin) -> float | None:
    """The twin's sound speed in its fluid [m/s], if it has one (acoustic twin), else None."""
    for name in ("sound_speed", "fluid_sound_speed", "sound_speed_m_s", "c_fluid"):
        obj = getattr(twin, name, None)
        try:
            val = obj() if callable(obj) else obj
            if val is not None and np.isfinite(float(val)) and float(val) > 0:
                return float(val)
        except Exception:  # noqa: BLE001 — a twin's helper may need arguments; then try the next
            continue
    for name in ("sound_speed_m_s", "c_m_s", "c_fluid_m_s"):
        val = getattr(twin.params, name, None)
        if isinstance(val, (int, float)) and val > 0:
            return float(val)
    sm = getattr(twin, "spectrum_metrics", None)  # the acoustic twin's sweep figures carry the sound speed
    if callable(sm):
        try:
            val = sm(points=16).get("sound_speed_m_s")
            if val:
                return float(val)
        except Exception:  # noqa: BLE001
            return None
    return None


def _clip01(x: float) -> float:
    return float(min(1.0, max(0.0, x))) if math.isfinite(x) else 0.0


def _us(t: float) -> str:
    return f"{t * 1e6:.1f} µs" if abs(t) < 1e-2 else f"{t * 1e3:.2f} ms"


# ---------------------------------------------------------------------------------------------- per family
def _echo(a: dict, twin: Twin) -> tuple[float, str]:
    ec = a["echo"]
    z = ec.get("z", 0.0)
    tau = ec.get("lag_s", float("nan"))
    score = _clip01((z - 4.0) / 12.0)
    c = sound_speed(twin)
    path = f" ≈ {tau * c * 1e3:.0f} mm extra path at c = {c:.0f} m/s" if c and math.isfinite(tau) else ""
    return score, (
        f"residual matches a delayed copy of the simulated output: echo at {_us(tau)}{path}, "
        f"amplitude {ec.get('coef', 0.0):+.3f} (peak {z:.1f} robust σ above the lag spread)"
    )


def _delay(a: dict, twin: Twin) -> tuple[float, str]:
    d = a["delay"]
    sh = d["shift_s"]
    frac = abs(d["shift_samples"])
    score = _clip01((frac - 0.05) / 0.5) * _clip01((d["corr"] - 0.3) / 0.4)
    c = sound_speed(twin)
    path = f" (≈ {sh * c * 1e3:.2f} mm of path at c = {c:.0f} m/s)" if c else ""
    return score, (
        f"measured output lags the simulation by {_us(sh)} = {d['shift_samples']:.2f} samples{path}; "
        f"input–output delay {_us(a['io_delay_s'])} measured vs {_us(a['io_delay_sim_s'])} simulated"
    )


def _crosstalk(a: dict, twin: Twin) -> tuple[float, str]:
    ei = a.get("early_input", {})
    if ei.get("valid"):
        # before the first (acoustic) arrival only an electrical path can correlate the residual with the input:
        # the early peak must stand out of the chance level (negative lags) and exceed the correlation after it
        score = _clip01((ei["ratio"] - 4.0) / 8.0) * _clip01((ei["early_over_late"] - 0.8) / 0.4)
        return score, (
            f"residual correlates with the input at {_us(ei['lag_s'])} lag, before the model's first "
            f"arrival at {_us(ei['first_arrival_s'])}: |r| = {ei['r_max']:.3f}, {ei['ratio']:.1f}× the "
            f"chance level and {ei['early_over_late']:.2f}× the largest correlation after it: a path "
            "without acoustic delay (electrical crosstalk)"
        )
    il = a["input_lag"]
    z = il.get("z", 0.0)
    near = il.get("lag_samples", 99) <= 3
    score = _clip01((z - 4.0) / 12.0) * (1.0 if near else 0.3)
    return score, (
        f"residual contains a scaled copy of the input at lag {il.get('lag_samples', 0)} samples, "
        f"coefficient {il.get('coef', 0.0):+.3g} ({z:.1f} robust σ): direct electrical coupling"
    )


def _nl_db(a: dict) -> tuple[float | None, str]:
    ln = a.get("lines", {})
    if ln.get("valid") and ln.get("odd_grid") and ln.get("n_even", 0) > 0 and ln.get("n_odd_detection", 0) > 0:
        return ln["odd_minus_even_db"], (
            f"odd detection lines {ln['e_odd_db']:.1f} dB, even lines {ln['e_even_db']:.1f} dB re excited lines"
        )
    h = a.get("harmonics", {})
    if h.get("sine_share", 0.0) > 0.8:
        f0 = h["f0_hz"]
        where = f"{f0:.4g} Hz" if not isinstance(f0, list) else f"{len(f0)} sine segments"
        return h["odd_over_even_db"], f"odd/even harmonics of {where} differ by {h['odd_over_even_db']:.1f} dB"
    return None, ""


def _odd(a: dict, twin: Twin) -> tuple[float, str]:
    nl = a["nonlinear"]
    band = nl["band"]
    c3 = max(nl["u3"], nl["y3"])
    c2 = max(nl["u2"], nl["y2"])
    score = _clip01((c3 / band - 1.5) / 6.0) * (1.0 if c3 >= c2 else 0.4)
    db, txt = _nl_db(a)
    if db is not None:
        score = max(score, _clip01((db - 3.0) / 15.0)) if db > 0 else score * 0.3
        txt = f"; {txt}: odd-order distortion dominates by {db:.1f} dB" if db > 0 else f"; {txt}"
    return score, (
        f"residual correlates with the cubic part of the input/output (|r| = {c3:.3f}, band {band:.3f}) "
        f"more than with the square (|r| = {c2:.3f}){txt}: odd-order compression"
    )


def _even(a: dict, twin: Twin) -> tuple[float, str]:
    nl = a["nonlinear"]
    band = nl["band"]
    c3 = max(nl["u3"], nl["y3"])
    c2 = max(nl["u2"], nl["y2"])
    score = _clip01((c2 / band - 1.5) / 6.0) * (1.0 if c2 >= c3 else 0.4)
    db, txt = _nl_db(a)
    if db is not None:
        score = max(score, _clip01((-db - 3.0) / 15.0)) if db < 0 else score * 0.3
        txt = f"; {txt}: even-order distortion dominates by {-db:.1f} dB" if db < 0 else f"; {txt}"
    pb = a.get("products", {})
    if db is None and pb.get("valid"):
        # band-pass input under an octave: even-order products land outside the band and its third-order skirts
        x = pb["even_db"] - max(pb["in_db"], pb["skirt_db"])
        score = max(score, _clip01((x - 3.0) / 10.0))
        txt += (
            "; residual density in the even-order product bands "
            f"(difference 0–{(pb['band_hz'][1] - pb['band_hz'][0]) / 1e3:.0f} kHz "
            f"{pb['diff_db']:.1f} dB, sum {2 * pb['band_hz'][0] / 1e3:.0f}–{2 * pb['band_hz'][1] / 1e3:.0f} kHz "
            f"{pb['sum_db']:.1f} dB) vs the excited band {pb['in_db']:.1f} dB and the odd skirts "
            f"{pb['skirt_db']:.1f} dB above the quietest band"
        )
    return score, (
        f"residual correlates with the square of the input/output (|r| = {c2:.3f}, band {band:.3f}) "
        f"more than with the cube (|r| = {c3:.3f}){txt}: even-order (asymmetric) distortion"
    )


def _creep(a: dict, twin: Twin) -> tuple[float, str]:
    sd = a["step_drift"]
    tr = a["trend"]
    if sd["n_steps"] > 0:
        score = _clip01((sd["share"] - 0.05) / 0.4)
        return score, (
            f"after {sd['n_steps']} input steps the residual drifts logarithmically: "
            f"{sd['gain_per_decade']:+.3g} per input unit per decade, {100 * sd['share']:.0f} % of the "
            "in-hold residual variance: creep"
        )
    score = _clip01((tr["drift_share"] - 0.1) / 0.5) * 0.7
    return score, (
        f"slow residual component ({100 * tr['drift_share']:.0f} % of its variance is a trend); no input "
        "steps to confirm a logarithmic creep law"
    )


def _drift(a: dict, twin: Twin) -> tuple[float, str]:
    tr = a["trend"]
    score = _clip01((tr["drift_share"] - 0.1) / 0.5)
    return score, (
        f"residual drifts by {tr['drift_total']:+.3g} over the record ({tr['slope_per_s']:+.3g}/s, "
        f"{100 * tr['drift_share']:.0f} % of the residual variance): slow thermal drift"
    )


def _resonance(a: dict, twin: Twin) -> tuple[float, str]:
    pk = a["resonances"]
    if not pk:
        return 0.0, "no narrow peak in the residual spectrum"
    p = pk[0]
    score = _clip01((p["prominence_db"] - 6.0) / 14.0)
    return score, (
        f"narrow residual peak at {p['freq_hz']:.4g} Hz, {p['prominence_db']:.1f} dB above the "
        f"residual floor ({p['residual_over_output_db']:.1f} dB re output): unmodelled resonance"
    )


def _lowpass(a: dict, twin: Twin) -> tuple[float, str]:
    b = a["bands"]
    d = a["delay"]
    # a missing low-pass makes the residual grow with frequency and look like a small lag of the output
    score = _clip01((abs(d["shift_samples"]) - 0.02) / 0.5) * 0.6 + _clip01(-b["in_band_db"] / 40.0) * 0.2
    return score, (
        f"residual is {b['in_band_db']:.1f} dB below the output in the excited band "
        f"{b['band_hz'][0]:.4g}–{b['band_hz'][1]:.4g} Hz and behaves like a {d['shift_samples']:.2f}-sample "
        "group delay: missing band limitation"
    )


def _quant(a: dict, twin: Twin) -> tuple[float, str]:
    q = a["quantization"]
    coh = q.get("coherence", 0.0)
    score = _clip01((coh - 0.2) / 0.6) if q.get("p_value", 1.0) < 1e-6 else 0.0
    return score, (
        f"measured values lie on a lattice of step {q['step']:.4g} (coherence {coh:.2f}, "
        f"{q.get('distinct_levels', 0)} levels): quantisation"
    )


def _rate(a: dict, twin: Twin) -> tuple[float, str]:
    h = [s for s in a["hysteresis"] if math.isfinite(s["width_measured"]) and math.isfinite(s["width_simulated"])]
    if len(h) < 2:
        return 0.1, "no sine segments to compare loop widths against frequency"
    f = np.array([s["freq_hz"] for s in h])
    dw = np.array([s["width_measured"] - s["width_simulated"] for s in h])
    dl = np.array([s["lag_deg_measured"] - s["lag_deg_simulated"] for s in h])
    slope = float(np.polyfit(np.log10(f), dw, 1)[0]) if np.ptp(np.log10(f)) > 0 else 0.0
    score = _clip01((abs(slope) - 0.005) / 0.03)
    return score, (
        f"loop width measured − simulated changes by {100 * slope:+.1f} % of span per decade of frequency "
        f"({f.min():.3g}–{f.max():.3g} Hz; phase lag difference {dl.min():+.1f}…{dl.max():+.1f}°): "
        "rate-dependent hysteresis"
    )


def _generic(a: dict, twin: Twin) -> tuple[float, str]:
    return 0.0, describe_generic(a)


_SCORERS: dict[str, Callable[[dict, Twin], tuple[float, str]]] = {
    "echo": _echo,
    "crosstalk": _crosstalk,
    "time_of_flight": _delay,
    "delay": _delay,
    "creep": _creep,
    "drift": _drift,
    "rate_hysteresis": _rate,
    "even_nl": _even,
    "odd_nl": _odd,
    "resonance": _resonance,
    "lowpass": _lowpass,
    "quantization": _quant,
    "noise": _generic,
    "generic": _generic,
}


def signature_evidence(
    spec: EffectSpec, analysis: dict[str, Any], twin: Twin, also: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Signature score in [0, 1] and sentence for one catalog effect, from the validation residual analysis
    (and, when ``also`` is given, the estimation one: the clearer of the two is kept; the estimation record
    may show a signature the validation input cannot, e.g. intermodulation of a multisine versus a chirp)."""
    fam = family_of(spec)
    score, text = _SCORERS.get(fam, _generic)(analysis, twin)
    if also is not None:
        s2, t2 = _SCORERS.get(fam, _generic)(also, twin)
        if s2 > score:
            score, text = s2, t2 + " (estimation record)"
    return {"family": fam, "score": float(score), "text": text}


def describe_generic(a: dict[str, Any]) -> str:
    """Plain-words description of the residual's structure, for what no catalog entry explains."""
    parts = [f"residual NRMSE {a['nrmse']:.4f}"]
    tr = a["trend"]
    if tr["drift_share"] > 0.2:
        parts.append(
            f"{100 * tr['drift_share']:.0f} % of it is a slow trend ({tr['drift_total']:+.3g} over the record)"
        )
    ec = a["echo"]
    if ec.get("z", 0) > 8:
        parts.append(f"a delayed copy of the output at {_us(ec['lag_s'])} (amplitude {ec['coef']:+.3f})")
    if abs(a["delay"]["shift_samples"]) > 0.2:
        parts.append(f"a timing shift of {a['delay']['shift_samples']:+.2f} samples")
    ei = a.get("early_input", {})
    if ei.get("valid") and ei["ratio"] > 8 and ei["early_over_late"] > 1:
        parts.append(
            f"a path without acoustic delay: the residual correlates with the input at {_us(ei['lag_s'])} "
            f"(|r| = {ei['r_max']:.3f}, {ei['ratio']:.0f}× chance), before the first arrival at "
            f"{_us(ei['first_arrival_s'])}"
        )
    nl = a["nonlinear"]
    if max(nl["u2"], nl["y2"]) > 3 * nl["band"]:
        parts.append(f"even-order correlation |r| = {max(nl['u2'], nl['y2']):.3f}")
    if max(nl["u3"], nl["y3"]) > 3 * nl["band"]:
        parts.append(f"odd-order correlation |r| = {max(nl['u3'], nl['y3']):.3f}")
    for p in a["resonances"][:2]:
        parts.append(f"a spectral peak at {p['freq_hz']:.4g} Hz ({p['prominence_db']:.0f} dB)")
    b = a["bands"]
    parts.append(
        f"{100 * b['in_share']:.0f} % of its power inside the excited band "
        f"{b['band_hz'][0]:.4g}–{b['band_hz'][1]:.4g} Hz"
    )
    hy = [s for s in a["hysteresis"] if math.isfinite(s["width_measured"])]
    if hy:
        worst = max(hy, key=lambda s: abs(s["width_measured"] - s["width_simulated"]))
        parts.append(
            f"loop width {100 * worst['width_measured']:.1f} % measured vs {100 * worst['width_simulated']:.1f} % "
            f"simulated at {worst['freq_hz']:.3g} Hz"
        )
    failing = [f"{t['name']} ({t['n_failing']} lags)" for t in a["tests"]["tests"] if not t["passed"]]
    if failing:
        parts.append("correlation tests failing: " + ", ".join(failing))
    return "; ".join(parts)
