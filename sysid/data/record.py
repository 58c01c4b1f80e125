"""The Record: one input/output experiment (the contract between readers, identifiers and twins).

A :class:`Record` holds the input ``u`` and output ``y`` (float arrays of equal length, 1-D for SISO or
2-D ``(N, channels)`` for MIMO), the sampling rate ``fs`` in Hz, the units of both signals and a metadata
dict (twin, parameters, effects, seed, protocol, provenance, preprocessing steps ...).

A record built by a signal generator may have ``y is None`` (input only).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sysid.errors import DataError

__all__ = ["Record", "check_array", "Normaliser", "NormalisedModel", "FS_MIN", "FS_MAX"]

#: documented range of sampling rates [Hz] of data files and options (docs/data-files.md): up to 1 GHz (10x the
#: 100 MHz acoustic rig); down to 1e-9 Hz because frequency-domain records (the acoustic twin's vna-sweep files)
#: store fs = 1/(point spacing in Hz), e.g. 1e-4 for a 10 kHz grid. Outside it a rate is a unit mistake and is
#: refused by sysid.data.io.read_record and the CLI; a Record itself only needs fs > 0.
FS_MIN, FS_MAX = 1e-9, 1e9


def check_array(values: Any, name: str, source: str = "array", allow_nan: bool = False) -> np.ndarray:
    """Return ``values`` as a float64 array of 1 or 2 dimensions, or raise :class:`DataError`.

    ``name`` names the signal and ``source`` the file or object it came from, for the message.
    """
    try:
        arr = np.asarray(values)
        if not np.iscomplexobj(arr):
            arr = arr.astype(np.float64, copy=False)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{source}: {name} is not numeric ({exc})") from None
    if np.iscomplexobj(arr):  # never drop an imaginary part silently
        if np.any(arr.imag != 0):
            raise DataError(f"{source}: {name} has complex samples; expected real values")
        arr = arr.real.astype(np.float64)
    if arr.ndim == 0:
        raise DataError(f"{source}: {name} is a scalar, expected a signal")
    if arr.ndim == 2 and arr.shape[1] == 1:
        arr = arr[:, 0]
    if arr.ndim > 2:
        raise DataError(f"{source}: {name} has {arr.ndim} dimensions, expected 1 (SISO) or 2 (samples x channels)")
    if arr.shape[0] == 0:
        raise DataError(f"{source}: {name} is empty")
    if not allow_nan:
        bad = ~np.isfinite(arr)
        if bad.any():
            idx = np.flatnonzero(bad.reshape(arr.shape[0], -1).any(axis=1))
            kind = "NaN" if np.isnan(arr).any() else "inf"
            raise DataError(
                f"{source}: {name} has {idx.size} non-finite ({kind}) samples, first at index {idx[0]}"
                " (use --fill-missing / fill_missing=True to interpolate missing samples)"
            )
    return arr


@dataclass
class Record:
    """One experiment: input ``u``, output ``y``, sampling rate ``fs`` [Hz], units and metadata.

    Parameters
    ----------
    u, y : array_like
        Input and output, shape ``(N,)`` or ``(N, channels)``. ``y`` may be ``None`` for an input-only record.
    fs : float
        Sampling rate in Hz, > 0.
    units : dict
        Units of the signals, e.g. ``{"u": "V", "y": "um"}``.
    meta : dict
        JSON-serialisable metadata.
    source : str
        Where the record came from (file name), used in error messages.
    """

    u: np.ndarray
    y: np.ndarray | None
    fs: float
    units: dict[str, str] = field(default_factory=lambda: {"u": "", "y": ""})
    meta: dict[str, Any] = field(default_factory=dict)
    source: str = "record"

    def __post_init__(self) -> None:
        self.u = check_array(self.u, "u", self.source)
        if self.y is not None:
            self.y = check_array(self.y, "y", self.source)
            if self.y.shape[0] != self.u.shape[0]:
                raise DataError(
                    f"{self.source}: u and y have unequal lengths ({self.u.shape[0]} and {self.y.shape[0]} samples)"
                )
        try:
            fs = float(self.fs)
        except (TypeError, ValueError, OverflowError):
            raise DataError(f"{self.source}: fs is not a number ({self.fs!r})") from None
        if not np.isfinite(fs) or fs <= 0:
            raise DataError(f"{self.source}: sampling rate fs must be positive and finite, got {fs}")
        self.fs = fs
        self.units = {"u": "", "y": "", **dict(self.units or {})}
        self.meta = dict(self.meta or {})

    # ------------------------------------------------------------------ basic properties
    def __len__(self) -> int:
        return int(self.u.shape[0])

    @property
    def n(self) -> int:
        """Number of samples."""
        return len(self)

    @property
    def dt(self) -> float:
        """Sampling interval [s]."""
        return 1.0 / self.fs

    @property
    def t(self) -> np.ndarray:
        """Time axis [s], starting at 0 (or at ``meta['t0']`` when present)."""
        return float(self.meta.get("t0", 0.0)) + np.arange(len(self)) / self.fs

    @property
    def duration(self) -> float:
        """Length in seconds (N / fs)."""
        return len(self) / self.fs

    @property
    def n_inputs(self) -> int:
        return 1 if self.u.ndim == 1 else int(self.u.shape[1])

    @property
    def n_outputs(self) -> int:
        if self.y is None:
            return 0
        return 1 if self.y.ndim == 1 else int(self.y.shape[1])

    def require_output(self) -> Record:
        """Raise :class:`DataError` unless the record has an output ``y``; return self."""
        _ = self.output  # DataError on an input-only record
        return self

    @property
    def output(self) -> np.ndarray:
        """The output ``y`` of a record that must have one: :class:`DataError` naming the record when it has none
        (an input-only record). Code that needs ``y`` reads it here, so the type checker knows it is an array."""
        if self.y is None:
            raise DataError(f"{self.source}: record has no output y (input-only record)")
        return self.y

    # ------------------------------------------------------------------ derived records
    def replace(self, **changes: Any) -> Record:
        """A copy with some fields replaced (arrays are not copied unless replaced)."""
        kw: dict[str, Any] = dict(
            u=self.u, y=self.y, fs=self.fs, units=dict(self.units), meta=copy.deepcopy(self.meta), source=self.source
        )
        kw.update(changes)
        return Record(**kw)

    def __getitem__(self, index: slice) -> Record:
        """Sample slice, e.g. ``rec[1000:5000]``; the time origin moves with the slice (``meta['t0']``)."""
        if not isinstance(index, slice):
            raise TypeError("Record supports slicing by a slice of sample indices only")
        start, stop, step = index.indices(len(self))
        if step != 1:
            raise DataError(f"{self.source}: slicing with a step changes fs; use sysid.signals.preprocess.decimate")
        if stop <= start:
            raise DataError(f"{self.source}: slice [{start}:{stop}] is empty")
        meta = copy.deepcopy(self.meta)
        meta["t0"] = float(meta.get("t0", 0.0)) + start / self.fs
        return Record(
            u=self.u[start:stop],
            y=None if self.y is None else self.y[start:stop],
            fs=self.fs,
            units=dict(self.units),
            meta=meta,
            source=self.source,
        )

    def time_slice(self, t_start: float, t_stop: float | None = None) -> Record:
        """Slice by time in seconds relative to the record's start."""
        i0 = int(round(t_start * self.fs))
        i1 = len(self) if t_stop is None else int(round(t_stop * self.fs))
        return self[i0:i1]

    def split(self, fraction: float | None = None, index: int | None = None) -> tuple[Record, Record]:
        """Split into (estimation, validation) at a sample ``index`` or a ``fraction`` of the length."""
        if fraction is not None and index is None:
            if not 0.0 < float(fraction) < 1.0:
                raise DataError(f"split: fraction must lie in (0, 1), got {fraction}")
            index = int(round(len(self) * float(fraction)))
        elif index is None or fraction is not None:
            raise DataError("split: give exactly one of fraction or index")
        if not 0 < index < len(self):
            raise DataError(f"split: index {index} outside 1..{len(self) - 1}")
        return self[:index], self[index:]

    def blocked_folds(self, k: int) -> list[tuple[list[Record], Record]]:
        """Blocked k-fold cross-validation: the record cut into ``k`` contiguous blocks whose lengths differ by at
        most one sample; fold i holds block i out for validation and estimates on what lies before and after it
        (one or two records). The blocks keep their order: a dynamic record's samples are not exchangeable, so
        shuffled folds would validate on samples the estimation part surrounds (Bergmeir & Benítez 2012)."""
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 2:
            raise DataError(f"blocked folds: k must be an integer of at least 2, got {k!r}")
        n = len(self)
        if n < 2 * k:
            raise DataError(f"{self.source}: {n} samples are too few for {k} folds (at least {2 * k})")
        edges = np.linspace(0, n, k + 1).round().astype(int)
        out = []
        for a, b in zip(edges[:-1], edges[1:]):
            parts = ([self[:a]] if a > 0 else []) + ([self[b:]] if b < n else [])
            out.append((parts, self[a:b]))
        return out

    def segments(self) -> list[Record]:
        """Split at the boundaries listed in ``meta['segments']`` (list of dicts with start/stop indices)."""
        segs = self.meta.get("segments")
        if not segs:
            return [self]
        out = []
        for seg in segs:
            part = self[int(seg["start"]) : int(seg["stop"])]
            part.meta.pop("segments", None)
            part.meta["segment"] = {k: v for k, v in seg.items()}
            out.append(part)
        return out

    def __repr__(self) -> str:  # compact, arrays are long
        ny = "none" if self.y is None else str(self.y.shape)
        return f"Record(n={len(self)}, fs={self.fs:g} Hz, u{self.u.shape}, y={ny}, source={self.source!r})"


class Normaliser:
    """Affine scaling to zero mean and unit standard deviation that remembers its scale and inverts exactly.

    ``fit`` stores per-channel ``u_mean_, u_scale_, y_mean_, y_scale_``; ``transform`` / ``inverse_transform``
    act on records, ``transform_y`` / ``inverse_y`` on output arrays. A constant channel keeps scale 1, so
    nothing divides by zero. The inverse reproduces the original to floating-point round-off.
    """

    y_mean_: np.ndarray | np.float64  # a scalar 0 / 1 when the records have no output
    y_scale_: np.ndarray | np.float64

    def fit(self, data: Record | Sequence[Record]) -> Normaliser:
        """Scale from ``data``: one record, or several taken together (one mean and deviation per channel)."""
        recs = [data] if isinstance(data, Record) else list(data)
        u = recs[0].u if len(recs) == 1 else np.concatenate([r.u for r in recs])
        self.u_mean_, self.u_scale_ = self._stats(u)
        ys = [r.y for r in recs if r.y is not None]
        if len(ys) == len(recs):
            self.y_mean_, self.y_scale_ = self._stats(ys[0] if len(ys) == 1 else np.concatenate(ys))
        else:
            self.y_mean_, self.y_scale_ = np.float64(0.0), np.float64(1.0)
        return self

    @staticmethod
    def _stats(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        mean = x.mean(axis=0)
        scale = x.std(axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        return mean, scale

    def transform_u(self, u: np.ndarray) -> np.ndarray:
        return (np.asarray(u, dtype=float) - self.u_mean_) / self.u_scale_

    def transform_y(self, y: np.ndarray) -> np.ndarray:
        return (np.asarray(y, dtype=float) - self.y_mean_) / self.y_scale_

    def inverse_u(self, un: np.ndarray) -> np.ndarray:
        return np.asarray(un, dtype=float) * self.u_scale_ + self.u_mean_

    def inverse_y(self, yn: np.ndarray) -> np.ndarray:
        return np.asarray(yn, dtype=float) * self.y_scale_ + self.y_mean_

    def transform(self, record: Record) -> Record:
        y = None if record.y is None else self.transform_y(record.y)
        return record.replace(u=self.transform_u(record.u), y=y)

    def inverse_transform(self, record: Record) -> Record:
        y = None if record.y is None else self.inverse_y(record.y)
        return record.replace(u=self.inverse_u(record.u), y=y)

    def to_dict(self) -> dict[str, Any]:
        return {k: np.asarray(getattr(self, k)).tolist() for k in ("u_mean_", "u_scale_", "y_mean_", "y_scale_")}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Normaliser:
        obj = cls()
        for k, v in d.items():
            setattr(obj, k, np.asarray(v, dtype=float))
        return obj


class NormalisedModel:
    """Any identifier fitted on data scaled to zero mean / unit deviation (a :class:`Normaliser` fitted on the
    estimation data, all records together); predictions are mapped back to the data's units, so metrics computed
    on them are in the original units. Other attributes are the wrapped model's."""

    def __init__(self, model):
        self.model = model

    def fit(self, data: Record | Sequence[Record]) -> NormalisedModel:
        recs = [data] if isinstance(data, Record) else list(data)
        self.norm_ = Normaliser().fit(recs)
        self.model.fit([self.norm_.transform(r) for r in recs] if len(recs) > 1 else self.norm_.transform(recs[0]))
        return self

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        return self.norm_.inverse_y(self.model.predict(self.norm_.transform(record), horizon=horizon))

    def __getattr__(self, name: str):
        if name == "model":
            raise AttributeError(name)
        return getattr(self.model, name)
