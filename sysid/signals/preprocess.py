"""Signal preprocessing (dissertation §2.3 and §3.2), in the manner of :mod:`scipy.signal`.

Array functions (time along axis 0; 1-D or 2-D ``(N, channels)``; ``fs`` explicit where it matters):

- :func:`remove_offset`, :func:`detrend` — offset and polynomial trend removal;
- :func:`hampel` — outlier detection and replacement by the local median, with a report of every change;
- :func:`fill_missing` — interpolation of missing (NaN) samples, with the filled indices;
- :func:`moving_average` — the dissertation's moving-average filter with a span (§3.2: 100 points);
- :func:`decimate`, :func:`resample` — anti-aliased integer decimation and rational resampling
  (§3.2: 100 MHz -> 6.75 MHz) with a Kaiser-window FIR designed for a stated pass-band flatness and
  stop-band attenuation, applied as a zero-phase polyphase filter (:func:`scipy.signal.resample_poly`);
- :func:`bandpass` — zero-phase Butterworth band-pass (§3.2: fifth order), :func:`scipy.signal.sosfiltfilt`;
- :func:`segment` / :func:`segment_bounds` — fixed-length (overlapping) segments;
- :func:`suggest_rate` — the covariance-based choice of the sampling rate (§3.2, ref. [83], Aguirre).

The array functions live by concern in :mod:`sysid.signals.cleaning` (offset, trend, outliers, missing samples),
:mod:`sysid.signals.filters` (moving average, decimation, resampling, band-pass) and
:mod:`sysid.signals.sampling` (segments,
rate suggestion); this module gathers them under one name and adds the record level.

Record level: :func:`apply_steps` applies a list of steps in order to ``u`` and ``y`` and appends one entry
``{"step", "params", "changes"}`` per step to ``record.meta["preprocessing"]`` (the same list in which
:func:`sysid.data.io.read_record` records ``fill_missing`` when it interpolates at read time).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from sysid.config import positive
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.signals.checks import _int_param
from sysid.signals.cleaning import detrend, fill_missing, hampel, remove_offset
from sysid.signals.filters import (
    ATTEN_DB_DEFAULT,
    PASSBAND_DEFAULT,
    antialias_filter,
    bandpass,
    bandpass_design,
    decimate,
    moving_average,
    resample,
)
from sysid.signals.sampling import autocovariance, segment, segment_bounds, suggest_rate

__all__ = [
    "remove_offset",
    "detrend",
    "hampel",
    "fill_missing",
    "moving_average",
    "decimate",
    "resample",
    "antialias_filter",
    "bandpass",
    "bandpass_design",
    "segment",
    "segment_bounds",
    "autocovariance",
    "suggest_rate",
    "apply_steps",
    "STEPS",
]


# ---------------------------------------------------------------------------------------------- record level
STEPS = (
    "remove_offset",
    "detrend",
    "hampel",
    "fill_missing",
    "moving_average",
    "decimate",
    "resample",
    "bandpass",
    "segment",
    "suggest_rate",
)
_ALIASES = {
    "outliers": "hampel",
    "offset": "remove_offset",
    "fill-missing": "fill_missing",
    "moving-average": "moving_average",
    "suggest-rate": "suggest_rate",
}
_PARAMS = {
    "remove_offset": set(),
    "detrend": {"order"},
    "hampel": {"window", "n_sigma"},
    "fill_missing": {"method"},
    "moving_average": {"span", "mode"},
    "decimate": {"q", "passband", "atten_db"},
    "resample": {"fs_new", "passband", "atten_db"},
    "bandpass": {"fmin", "fmax", "order"},
    "segment": {"length", "overlap"},
    "suggest_rate": {"max_lag"},
}
_PER_SIGNAL = {"remove_offset", "detrend", "hampel", "moving_average", "bandpass"}  # may be limited to u or y


def _normalise_step(step: Any) -> tuple[str, dict[str, Any]]:
    if isinstance(step, str):
        name, params = step, {}
    elif isinstance(step, dict):
        params = dict(step)
        name = params.pop("step", None)
        if name is None:
            raise ConfigError(f"preprocessing step {step!r} has no 'step' name")
    else:
        try:
            name, params = step
            params = dict(params or {})
        except (TypeError, ValueError):
            raise ConfigError(f"preprocessing step must be a name, (name, params) or a dict, got {step!r}") from None
    name = _ALIASES.get(str(name), str(name))
    if name not in _PARAMS:
        raise ConfigError(f"unknown preprocessing step {name!r}; valid: {', '.join(STEPS)}")
    allowed = _PARAMS[name] | ({"signals"} if name in _PER_SIGNAL else set())
    unknown = set(params) - allowed
    if unknown:
        raise ConfigError(
            f"preprocessing step {name}: unknown parameter(s) {', '.join(sorted(unknown))};"
            f" valid: {', '.join(sorted(allowed)) or 'none'}"
        )
    return name, params


def apply_steps(record: Record, steps: Iterable[Any]) -> Record:
    """Apply preprocessing ``steps`` to ``record`` in the order given and return a new Record.

    A step is a name (``"detrend"``), a pair ``(name, params)`` or a dict ``{"step": name, **params}``;
    names are those of :data:`STEPS` (``outliers`` is an alias of ``hampel``). Steps act on ``u`` and ``y``;
    ``remove_offset``, ``detrend``, ``hampel``, ``moving_average`` and ``bandpass`` accept
    ``signals="u"|"y"|"both"``. ``decimate`` and ``resample`` always act on both and change ``fs``;
    ``segment`` writes ``meta["segments"]`` (``Record.segments()`` splits by it); ``suggest_rate`` changes
    nothing and reports the Aguirre suggestion computed on ``y`` (its first channel; on ``u`` for an
    input-only record). A Record cannot hold missing samples (they are refused, or filled by
    ``read_record(..., fill_missing=True)`` when the file is read), so ``fill_missing`` here only records that
    nothing was missing.

    Each step appends ``{"step": name, "params": {...}, "changes": {...}}`` to ``meta["preprocessing"]``:
    the offsets / trend coefficients removed, every outlier replaced (index, channel, value, replacement),
    the filled indices, the rates and lengths before and after, the filter length, the segments.
    """
    rec = record.replace()
    log = rec.meta.setdefault("preprocessing", [])
    for raw in steps:
        name, params = _normalise_step(raw)
        signals = params.pop("signals", "both") if name in _PER_SIGNAL else "both"
        if signals not in ("u", "y", "both"):
            raise ConfigError(f"preprocessing step {name}: signals must be u, y or both, got {signals!r}")
        targets = ["u", "y"] if signals == "both" else [signals]
        targets = [t for t in targets if getattr(rec, t) is not None]
        if signals == "y" and rec.y is None:
            raise DataError(f"{rec.source}: step {name} asks for y but the record has no output")
        changes: dict[str, Any] = {}
        new: dict[str, Any] = {}
        fs = rec.fs
        if name in ("decimate", "resample") and rec.meta.get("segments"):
            raise ConfigError(f"step {name} after segment would invalidate the segment indices; segment last")
        if name == "remove_offset":
            for t in targets:
                x = getattr(rec, t)
                changes.setdefault("offset", {})[t] = x.mean(axis=0).tolist()
                new[t] = remove_offset(x)
        elif name == "detrend":
            order = params.get("order", 1)
            for t in targets:
                new[t], coef = detrend(getattr(rec, t), order=order, return_coefficients=True)
                changes.setdefault("trend_coefficients", {})[t] = coef.T.tolist()
        elif name == "hampel":
            for t in targets:
                new[t], ch = hampel(
                    getattr(rec, t), window=params.get("window", 10), n_sigma=params.get("n_sigma", 3.0)
                )
                changes.setdefault("replaced", {})[t] = ch
            changes["n_replaced"] = {t: len(changes["replaced"][t]) for t in targets}
        elif name == "fill_missing":
            for t in targets:
                new[t], filled = fill_missing(getattr(rec, t), method=params.get("method", "linear"))
                changes.setdefault("filled_indices", {})[t] = filled
        elif name == "moving_average":
            if "span" not in params:
                raise ConfigError("preprocessing step moving_average needs span")
            for t in targets:
                new[t] = moving_average(getattr(rec, t), params["span"], params.get("mode", "centred"))
        elif name in ("decimate", "resample"):
            if name == "decimate":
                if "q" not in params:
                    raise ConfigError("preprocessing step decimate needs q")
                q = _int_param("decimation factor q", params["q"], 1)
                fs_new = fs / q
                # fn is called below, in this same step: binding late to q and params is harmless
                fn = lambda x: decimate(  # noqa: E731
                    x,
                    q,  # noqa: B023
                    params.get("passband", PASSBAND_DEFAULT),  # noqa: B023
                    params.get("atten_db", ATTEN_DB_DEFAULT),  # noqa: B023
                    return_filter=True,
                )
            else:
                if "fs_new" not in params:
                    raise ConfigError("preprocessing step resample needs fs_new")
                fs_new = positive("new sampling rate", params["fs_new"])
                fn = lambda x: resample(  # noqa: E731
                    x,
                    fs,  # noqa: B023
                    fs_new,  # noqa: B023
                    params.get("passband", PASSBAND_DEFAULT),  # noqa: B023
                    params.get("atten_db", ATTEN_DB_DEFAULT),  # noqa: B023
                    return_filter=True,
                )
            for t in targets:
                new[t], h = fn(getattr(rec, t))
            changes.update(
                {
                    "fs_before": fs,
                    "fs_after": fs_new,
                    "n_before": len(rec),
                    "n_after": int(new["u"].shape[0]),
                    "filter_taps": int(h.size),
                }
            )
            new["fs"] = fs_new
        elif name == "bandpass":
            if "fmin" not in params or "fmax" not in params:
                raise ConfigError("preprocessing step bandpass needs fmin and fmax")
            for t in targets:
                new[t] = bandpass(getattr(rec, t), fs, params["fmin"], params["fmax"], params.get("order", 5))
        elif name == "segment":
            if "length" not in params:
                raise ConfigError("preprocessing step segment needs length")
            b = segment_bounds(len(rec), params["length"], params.get("overlap", 0))
            rec.meta["segments"] = [{"start": s, "stop": e} for s, e in b]
            changes = {"n_segments": len(b), "dropped_tail": len(rec) - b[-1][1]}
        elif name == "suggest_rate":
            target = rec.y if rec.y is not None else rec.u
            if target.ndim == 2:
                target = target[:, 0]
            changes = {
                "signal": "y" if rec.y is not None else "u",
                "channel": 0,
                **suggest_rate(target, fs=fs, max_lag=params.get("max_lag")),
            }
        if new:
            kw = {k: v for k, v in new.items() if k in ("u", "y", "fs")}
            meta = rec.meta
            rec = rec.replace(**kw)
            rec.meta = meta
        log.append(
            {
                "step": name,
                "params": {**params, **({"signals": signals} if name in _PER_SIGNAL else {})},
                "changes": changes,
            }
        )
        rec.meta["preprocessing"] = log
    return rec
