"""Features of the measured values and of hysteresis loops: a quantisation lattice, saturation rails (censored
samples) and the loop width and phase lag per sine segment.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["quantization_step", "saturation_rails", "clip_to_rails", "hysteresis_by_segment"]


def quantization_step(y: np.ndarray, max_levels: int = 200000) -> dict[str, float]:
    """Detect a lattice in the measured values: the step q such that y/q is (nearly) an integer.

    The candidate step is the smallest clearly non-zero |Δy|; the lattice is confirmed when the values'
    remainders modulo q cluster (Rayleigh test of the phase 2πy/q: ``coherence`` near 1, p-value tiny).
    A continuous (un-quantised or finely quantised) signal gives coherence ≈ 0.
    """
    y = np.asarray(y, dtype=float)
    d = np.abs(np.diff(y))
    d = d[d > 1e-12 * max(np.max(np.abs(y)), 1e-300)]
    if d.size < 10:
        return {"step": 0.0, "coherence": 0.0, "p_value": 1.0, "distinct_levels": int(np.unique(y).size)}
    q = float(np.min(d))
    # ensure the smallest step is typical (a lattice makes many diffs equal to multiples of q)
    ratio = d / q
    on = np.mean(np.abs(ratio - np.round(ratio)) < 0.02)
    ph = 2 * np.pi * (y - y[0]) / q
    coh = float(np.hypot(np.mean(np.cos(ph)), np.mean(np.sin(ph))))
    n = y.size
    p = float(np.exp(-n * coh**2))
    levels = int(np.unique(np.round((y - y.min()) / q)).size) if np.ptp(y) / q < max_levels else -1
    return {
        "step": q,
        "coherence": coh * float(on),
        "p_value": p if on > 0.9 else 1.0,
        "on_lattice": float(on),
        "distinct_levels": levels,
    }


def saturation_rails(
    y: np.ndarray, ysim: np.ndarray, min_count: int = 5, min_share: float = 0.002, k_rms: float = 2.0
) -> dict[str, Any]:
    """Saturation rails of a measured record: the levels where the measuring chain clipped it.

    A side (top or bottom) is a rail when (a) the measured extreme value is taken *exactly* by at least
    ``max(min_count, min_share·N)`` samples (a flat top: an analogue signal, or a quantised one that does not
    clip, reaches its extreme at a few isolated samples) and (b) on those samples the prediction lies beyond
    the extreme by a median of more than ``k_rms`` times the residual RMS of the other samples (the model says
    the signal went further than the instrument could show). Such samples are censored: the measurement only
    says "at least this far"; a prediction clipped to the rails is what the instrument would have shown.

    Returns ``{"lo", "hi"}`` (None where that side has no rail), the sample counts and the median excess.
    """
    y = np.asarray(y, dtype=float)
    s = np.asarray(ysim, dtype=float)
    n = y.size
    out: dict[str, Any] = {"lo": None, "hi": None, "n_lo": 0, "n_hi": 0}
    if n < 8 or not np.all(np.isfinite(s)):
        return out
    need = max(int(min_count), int(np.ceil(min_share * n)))
    sides = {}
    for side, level, sign in (("hi", float(np.max(y)), 1.0), ("lo", float(np.min(y)), -1.0)):
        at = y == level
        if int(at.sum()) >= need:
            sides[side] = (level, sign, at)
    if not sides:
        return out
    at_any = np.zeros(n, dtype=bool)
    for _, _, at in sides.values():
        at_any |= at
    rest = ~at_any
    rms = float(np.sqrt(np.mean((y[rest] - s[rest]) ** 2))) if rest.any() else 0.0
    for side, (level, sign, at) in sides.items():
        excess = float(np.median(sign * (s[at] - level)))
        if excess > k_rms * rms:
            out[side] = level
            out[f"n_{side}"] = int(at.sum())
            out[f"excess_{side}"] = excess
    return out


def clip_to_rails(ysim: np.ndarray, rails: dict[str, Any] | None) -> np.ndarray:
    """The prediction as the saturating instrument would show it (:func:`saturation_rails`)."""
    if not rails or (rails.get("lo") is None and rails.get("hi") is None):
        return ysim
    lo = -np.inf if rails.get("lo") is None else float(rails["lo"])
    hi = np.inf if rails.get("hi") is None else float(rails["hi"])
    return np.clip(ysim, lo, hi)


def _segments(meta: dict[str, Any], n: int) -> list[dict[str, Any]]:
    segs = meta.get("segments") or []
    out = []
    for s in segs:
        try:
            a, b = int(s["start"]), int(s["stop"])
        except (KeyError, TypeError, ValueError):
            continue
        f = s.get("freq_hz", s.get("frequency_hz", s.get("freq", s.get("f_hz"))))
        if f is None or not (0 <= a < b <= n):
            continue
        out.append({"start": a, "stop": b, "freq_hz": float(f)})
    return out


def _loop_metrics(u: np.ndarray, y: np.ndarray, f: float, fs: float) -> tuple[float, float]:
    """Loop width (max vertical gap between rising and falling branches ÷ output span) and the phase lag
    [deg] of the output's fundamental behind the input's, over the whole periods of a sine segment."""
    n = u.size
    per = fs / f
    nper = int(n // per)
    if nper < 1:
        return float("nan"), float("nan")
    # use the last whole periods (after the start-up transient when there are several)
    use = int(round(max(1, nper - 1 if nper > 2 else nper) * per))
    u = u[-use:]
    y = y[-use:]
    t = np.arange(use) / fs
    c, s = np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)
    A = np.column_stack([np.ones(use), c, s])
    cu, *_ = np.linalg.lstsq(A, u, rcond=None)
    cy, *_ = np.linalg.lstsq(A, y, rcond=None)
    pu = np.arctan2(-cu[2], cu[1])
    py = np.arctan2(-cy[2], cy[1])
    lag = float(np.degrees((pu - py + np.pi) % (2 * np.pi) - np.pi))
    du = np.gradient(u)
    grid = np.linspace(np.percentile(u, 5), np.percentile(u, 95), 41)
    span = float(np.ptp(y)) or 1e-300
    up, dn = du > 0, du < 0
    if up.sum() < 3 or dn.sum() < 3:
        return float("nan"), lag
    ou = np.argsort(u[up])
    od = np.argsort(u[dn])
    yu = np.interp(grid, u[up][ou], y[up][ou])
    yd = np.interp(grid, u[dn][od], y[dn][od])
    gaps = np.abs(yu - yd)
    return float(np.max(gaps) / span), lag


def hysteresis_by_segment(
    u: np.ndarray, y: np.ndarray, ysim: np.ndarray, fs: float, meta: dict[str, Any]
) -> list[dict[str, float]]:
    """Loop width (share of span) and phase lag [deg], measured and simulated, for each sine segment listed in
    ``meta['segments']`` (dicts with ``start``, ``stop`` and the frequency ``freq_hz``)."""
    out = []
    for s in _segments(meta, len(u)):
        a, b, f = s["start"], s["stop"], s["freq_hz"]
        if f <= 0:
            continue
        wm, lm = _loop_metrics(u[a:b], y[a:b], f, fs)
        ws, ls = _loop_metrics(u[a:b], ysim[a:b], f, fs)
        out.append(
            {"freq_hz": f, "width_measured": wm, "width_simulated": ws, "lag_deg_measured": lm, "lag_deg_simulated": ls}
        )
    return out
