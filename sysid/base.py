"""The interface every identifier follows (scikit-learn shape: constructor options, ``fit``, ``predict``).

- configuration in ``__init__`` (keyword arguments with defaults; :meth:`get_params` lists them);
- ``fit(record_or_list)`` returns ``self``; a list of Records is several separate experiments, and no
  regressor may span the boundary between two of them;
- learned values end in ``_``; ``max_lag_`` is the number of leading samples a prediction copies from the
  measurement as initial conditions (metrics skip them);
- ``predict(record, horizon=1 | k | None)``: one-step-ahead, k-step-ahead at every sample, or free-run
  simulation (``None``). Returns an array shaped like ``record.y``. A free run that diverges is stopped, the
  remaining samples are ``nan``, ``diverged_at_`` holds the index and a :class:`~sysid.errors.DivergenceWarning`
  is issued — never an exception;
- ``n_parameters_`` counts the estimated parameters; ``describe()`` returns a JSON-able summary (terms...);
- ``save(path)`` / :func:`load_model` round-trip a fitted model so it predicts identically (format:
  :mod:`sysid.data.modelfile`).

Arrays as well as records (done once here, for every identifier: :meth:`Identifier.__init_subclass__` wraps
each subclass's ``fit`` and ``predict``):

- ``fit(u, y, fs=...)`` builds a Record from arrays (``fs`` defaults to 1 Hz, i.e. time in samples);
  after any fit, ``estimation_`` describes the estimation data (fs, units, sizes, SHA-256) and ``fs_`` is its rate;
- ``predict(u, y=None, horizon=...)``: without ``y`` a free-run simulation from zero initial conditions
  (the first ``max_lag_`` outputs are those zeros), with ``y`` one-step by default; a Record without ``y``
  is predicted the same way. ``predict(record, horizon)`` keeps its meaning;
- ``score(u, y, horizon=None)`` is R² (eq. 2-31) of that prediction after the first ``max_lag_`` samples.
"""

from __future__ import annotations

import functools
import inspect
import warnings
from abc import ABC, abstractmethod
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError, DivergenceWarning

__all__ = [
    "Identifier",
    "as_record_list",
    "check_records",
    "load_model",
    "as_fit_data",
    "as_predict_record",
    "check_prediction",
    "stop_at_divergence",
]

_UNSET: Any = object()  # "argument not given" (None is a meaningful horizon: free run)


def as_record_list(data: Record | Sequence[Record]) -> list[Record]:
    """Accept one Record or a sequence of them; check each has an output."""
    recs = [data] if isinstance(data, Record) else list(data)
    if not recs:
        raise DataError("fit: no records given")
    for r in recs:
        if not isinstance(r, Record):
            raise DataError(f"fit: expected Record objects, got {type(r).__name__}")
        r.require_output()
    return recs


def check_records(records: Sequence[Record], max_lag: int, min_rows: int, what: str) -> None:
    """Refuse data that cannot be identified: NaN/inf, too few samples for the lags, constant input."""
    n_in, n_out = records[0].n_inputs, records[0].n_outputs
    rows = 0
    for rec in records:
        if rec.n_inputs != n_in or rec.n_outputs != n_out:
            raise DataError(
                f"{rec.source}: {rec.n_inputs} inputs / {rec.n_outputs} outputs, but the first record has "
                f"{n_in} / {n_out}"
            )
        for name, arr in (("u", rec.u), ("y", rec.output)):
            if not np.isfinite(arr).all():
                i = int(np.flatnonzero(~np.isfinite(arr.reshape(arr.shape[0], -1)).any(axis=1))[0])
                raise DataError(f"{rec.source}: {name} has non-finite (NaN/inf) samples, first at index {i}")
        if len(rec) <= max_lag:
            raise DataError(
                f"{rec.source}: {len(rec)} samples are too few for the lags of {what} "
                f"(max lag {max_lag}; need more than {max_lag} samples per record)"
            )
        rows += len(rec) - max_lag
    if rows < min_rows:
        raise DataError(
            f"{what}: {rows} usable samples (after the max lag {max_lag}) are too few for "
            f"{min_rows - 1} candidate parameters; give more data or smaller lags/degree"
        )
    u_all = np.concatenate([r.u.reshape(len(r), -1) for r in records])
    for ch in range(u_all.shape[1]):
        if np.ptp(u_all[:, ch]) == 0.0:
            name = "u" if u_all.shape[1] == 1 else f"u{ch + 1}"
            raise DataError(
                f"{records[0].source}: input {name} is constant ({u_all[0, ch]:g}); "
                "a constant input does not excite the system, nothing to identify"
            )
    y_all = np.concatenate([r.output.reshape(len(r), -1) for r in records])
    for ch in range(y_all.shape[1]):
        if np.ptp(y_all[:, ch]) == 0.0:
            name = "y" if y_all.shape[1] == 1 else f"y{ch + 1}"
            raise DataError(f"{records[0].source}: output {name} is constant ({y_all[0, ch]:g}); nothing to identify")


def check_prediction(model: Identifier, record: Record, horizon: Any) -> None:
    """What ``predict`` refuses for every simulation model: a record without output, other channel counts than the
    model was fitted on, a horizon that is not a positive integer or ``None`` (free run)."""
    record.require_output()
    if record.n_inputs != model.n_inputs_ or record.n_outputs != model.n_outputs_:
        raise DataError(
            f"{record.source}: {record.n_inputs} inputs / {record.n_outputs} outputs, model was fitted "
            f"on {model.n_inputs_} / {model.n_outputs_}"
        )
    if horizon is not None and (isinstance(horizon, bool) or int(horizon) != horizon or horizon < 1):
        raise ConfigError(f"horizon must be a positive integer or None (free run), got {horizon!r}")


def stop_at_divergence(model: Identifier, yhat: np.ndarray, what: str = "prediction") -> np.ndarray:
    """The divergence rule of the module docstring on ``yhat`` (one row per sample), in place: from the first
    sample with any output outside ``±model.y_bound_`` on, ``nan``; ``model.diverged_at_`` holds that index (None
    when there is none) and a :class:`~sysid.errors.DivergenceWarning` names it."""
    outside = ~(np.abs(yhat) <= model.y_bound_)
    bad = np.flatnonzero(outside if outside.ndim == 1 else outside.any(axis=1))
    model.diverged_at_ = None
    if bad.size:
        model.diverged_at_ = int(bad[0])
        yhat[bad[0] :] = np.nan
        warnings.warn(
            f"{model.name}: {what} left ±{model.y_bound_:.3g} at sample {bad[0]}; the rest is nan",
            DivergenceWarning,
            stacklevel=3,
        )
    return yhat


def as_fit_data(
    data: Any, y: Any = None, fs: float | None = None, units: dict[str, str] | None = None
) -> Record | list[Record]:
    """What ``fit`` accepts: a Record, a list of Records, or arrays ``u, y`` (with ``fs`` [Hz], default 1)."""
    if isinstance(data, Record) or (
        isinstance(data, (list, tuple)) and data and all(isinstance(r, Record) for r in data)
    ):
        if y is not None:
            raise ConfigError("fit: give either records or arrays u, y, not a record and y")
        return data if isinstance(data, Record) else list(data)
    if y is None:
        raise DataError("fit: arrays need both u and y (fit(u, y, fs=...))")
    return Record(u=data, y=y, fs=1.0 if fs is None else fs, units=units or {"u": "", "y": ""}, source="array")


def as_predict_record(model: Identifier, data: Any, y: Any = None, fs: float | None = None) -> Record:
    """A Record from ``predict``'s arguments (arrays get the model's estimation rate, or 1 Hz)."""
    if isinstance(data, Record):
        if y is not None:
            raise ConfigError("predict: give either a record or arrays u (, y), not a record and y")
        return data
    rate = fs if fs is not None else getattr(model, "fs_", None) or 1.0
    return Record(u=data, y=y, fs=rate, source="array")


def _zero_output(model: Identifier, rec: Record) -> Record:
    """``rec`` with y = 0: the zero initial conditions of a free run from the input alone."""
    n_out = int(getattr(model, "n_outputs_", 1) or 1)
    shape = (len(rec),) if n_out == 1 else (len(rec), n_out)
    out = rec.replace(y=np.zeros(shape))
    out.meta["initial_conditions"] = "zero"
    return out


def _wrap_fit(fn):
    @functools.wraps(fn)
    def fit(self, data, y=None, *, fs=None, units=None, **kwargs):
        from sysid.data.modelfile import estimation_info

        fit_data = as_fit_data(data, y, fs, units)
        out = fn(self, fit_data, **kwargs)
        recs = [fit_data] if isinstance(fit_data, Record) else fit_data
        self.estimation_ = estimation_info(recs)
        self.fs_ = float(recs[0].fs)
        return out

    fit._piezotwin_wrapped = True  # type: ignore[attr-defined]
    return fit


def _wrap_predict(fn):
    @functools.wraps(fn)
    def predict(self, data, *args, horizon=_UNSET, fs=None, y=None):
        if isinstance(data, Record):  # predict(record, horizon) as before
            if len(args) > 1 or (args and horizon is not _UNSET):
                raise TypeError("predict(record, horizon): too many arguments")
            rec = as_predict_record(self, data, y, fs)
            h = args[0] if args else ((1 if rec.y is not None else None) if horizon is _UNSET else horizon)
        else:  # predict(u, y=None, horizon=...)
            if len(args) > 2 or (args and y is not None) or (len(args) == 2 and horizon is not _UNSET):
                raise TypeError("predict(u, y=None, horizon=...): too many arguments")
            y = args[0] if args else y
            if len(args) == 2:
                horizon = args[1]
            rec = as_predict_record(self, data, y, fs)
            h = (1 if rec.y is not None else None) if horizon is _UNSET else horizon
        if rec.y is None:
            if h is not None:
                raise ConfigError(
                    f"{self.name}: {h}-step prediction needs the measured output y; a free run "
                    "(horizon=None, --horizon inf) needs only the input u"
                )
            return fn(self, _zero_output(self, rec), None)
        return fn(self, rec, h)

    predict._piezotwin_wrapped = True  # type: ignore[attr-defined]
    return predict


class Identifier(ABC):
    """Base class of all identifiers. Subclasses set ``name`` (the registry id) and implement fit/predict."""

    name: ClassVar[str] = "identifier"
    #: first sample at which the last prediction left its bound (None: it did not), set by predict
    diverged_at_: int | None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Give every identifier the array API (see the module docstring) by wrapping its own fit/predict, and
        let its constructor accept the deprecated option names of :data:`sysid.config.ALIASES`."""
        super().__init_subclass__(**kwargs)
        for attr, wrap in (("fit", _wrap_fit), ("predict", _wrap_predict)):
            fn = cls.__dict__.get(attr)
            if (
                fn is not None
                and not getattr(fn, "__isabstractmethod__", False)
                and not getattr(fn, "_piezotwin_wrapped", False)
            ):
                setattr(cls, attr, wrap(fn))
        if "__init__" not in cls.__dict__:
            return
        init = cls.__dict__["__init__"]

        @functools.wraps(init)
        def __init__(self, *args: Any, **kw: Any) -> None:
            from sysid.config import resolve_aliases

            if kw:
                kw = resolve_aliases(kw, inspect.signature(init).parameters, f"{cls.name}")
            init(self, *args, **kw)

        cls.__init__ = __init__  # type: ignore[method-assign]

    def __getattr__(self, name: str) -> Any:
        """Deprecated option names (:data:`sysid.config.ALIASES`) still read, e.g. ``model.n_y``."""
        from sysid.config import ALIASES

        new = ALIASES.get(name)
        if new is not None and not name.startswith("__") and new in type(self)._param_names():
            warnings.warn(f"{self.name}: {name} is deprecated, use {new}", DeprecationWarning, stacklevel=2)
            return getattr(self, new)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    # ------------------------------------------------------------------ configuration
    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values() if p.name != "self" and p.kind is p.POSITIONAL_OR_KEYWORD]

    def get_params(self) -> dict[str, Any]:
        """The constructor arguments of this instance."""
        return {k: getattr(self, k) for k in self._param_names()}

    def set_params(self, **params: Any) -> Identifier:
        from sysid.config import resolve_aliases

        valid = self._param_names()
        params = resolve_aliases(params, valid, self.name)
        for k, v in params.items():
            if k not in valid:
                raise ConfigError(f"{self.name}: unknown option {k!r}; valid: {', '.join(valid)}")
            setattr(self, k, v)
        return self

    @classmethod
    def from_assignments(cls, assignments: dict[str, str]) -> Identifier:
        """Build from raw ``--set`` strings, coercing each to the type of the constructor default."""
        from sysid.config import apply_assignments

        sig = inspect.signature(cls.__init__)
        defaults = {
            p.name: p.default for p in sig.parameters.values() if p.name != "self" and p.kind is p.POSITIONAL_OR_KEYWORD
        }
        from sysid.config import resolve_aliases

        assignments = resolve_aliases(assignments, defaults, f"{cls.name} --set")
        values = apply_assignments(defaults, assignments, what=f"{cls.name} option")
        return cls(**values)

    # ------------------------------------------------------------------ learning / prediction
    @abstractmethod
    def fit(self, data: Record | Sequence[Record]) -> Identifier: ...

    @abstractmethod
    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray: ...

    def describe(self) -> dict[str, Any]:
        """JSON-able summary of the fitted model (subclasses add terms, structure...)."""
        return {
            "identifier": self.name,
            "params": self.get_params(),
            "n_parameters": getattr(self, "n_parameters_", None),
        }

    # ------------------------------------------------------------------ persistence
    @abstractmethod
    def _state(self) -> dict[str, Any]:
        """Learned state as JSON-able dict (arrays as lists) — enough to predict identically."""

    @abstractmethod
    def _load_state(self, state: dict[str, Any]) -> None: ...

    def score(self, data: Any, y: Any = None, horizon: int | None = None, fs: float | None = None) -> float:
        """R² (eq. 2-31) of ``predict`` against the measured output, after the first ``max_lag_`` samples.

        ``score(u, y)`` or ``score(record)``; ``horizon`` as in :meth:`predict` (default ``None``: free run,
        what MATLAB's ``compare`` shows by default). A diverged prediction scores nan.
        """
        from sysid.evaluation import metrics

        rec = as_predict_record(self, data, y, fs)
        rec.require_output()
        yh = self.predict(rec, horizon)
        y_meas = rec.output
        skip = int(getattr(self, "max_lag_", 0) or 0)
        return metrics.score(y_meas, np.asarray(yh).reshape(y_meas.shape), skip=skip)["r2"]

    def save(self, path: str | Path) -> Path:
        """Write the fitted model to ``path`` (atomically): the npz container, or JSON for ``.json``
        (:mod:`sysid.data.modelfile`; neural identifiers also write torch ``.pt``)."""
        from sysid.data.modelfile import write_model

        return write_model(self, path)

    @classmethod
    def load(cls, path: str | Path) -> Identifier:
        """Load a model file; on a subclass, refuse a file that holds another identifier."""
        model = load_model(path)
        if cls is not Identifier and not isinstance(model, cls):
            raise DataError(f"{path}: holds a {model.name} model, not {cls.name}")
        return model


def load_model(path: str | Path) -> Identifier:
    """Load a model written by :meth:`Identifier.save` (any registered identifier, any format version)."""
    from sysid.data.modelfile import read_model

    return read_model(path)
