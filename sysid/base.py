"""The interface every identifier follows (scikit-learn shape, DESIGN.md "Style").

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
- ``save(path)`` / :func:`load_model` round-trip a fitted model so it predicts identically.
"""

from __future__ import annotations

import functools
import inspect
import json
import warnings
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any, ClassVar, Sequence

import numpy as np

from sysid.errors import ConfigError, DataError
from sysid.io import json_default, output_file
from sysid.record import Record

__all__ = ["Identifier", "as_record_list", "check_records", "load_model"]


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
            raise DataError(f"{rec.source}: {rec.n_inputs} inputs / {rec.n_outputs} outputs, but the first record has "
                            f"{n_in} / {n_out}")
        for name, arr in (("u", rec.u), ("y", rec.y)):
            if not np.isfinite(arr).all():
                i = int(np.flatnonzero(~np.isfinite(arr.reshape(arr.shape[0], -1)).any(axis=1))[0])
                raise DataError(f"{rec.source}: {name} has non-finite (NaN/inf) samples, first at index {i}")
        if len(rec) <= max_lag:
            raise DataError(f"{rec.source}: {len(rec)} samples are too few for the lags of {what} "
                            f"(max lag {max_lag}; need more than {max_lag} samples per record)")
        rows += len(rec) - max_lag
    if rows < min_rows:
        raise DataError(f"{what}: {rows} usable samples (after the max lag {max_lag}) are too few for "
                        f"{min_rows - 1} candidate parameters; give more data or smaller lags/degree")
    u_all = np.concatenate([r.u.reshape(len(r), -1) for r in records])
    for ch in range(u_all.shape[1]):
        if np.ptp(u_all[:, ch]) == 0.0:
            name = "u" if u_all.shape[1] == 1 else f"u{ch + 1}"
            raise DataError(f"{records[0].source}: input {name} is constant ({u_all[0, ch]:g}); "
                            "a constant input does not excite the system, nothing to identify")
    y_all = np.concatenate([r.y.reshape(len(r), -1) for r in records])
    for ch in range(y_all.shape[1]):
        if np.ptp(y_all[:, ch]) == 0.0:
            name = "y" if y_all.shape[1] == 1 else f"y{ch + 1}"
            raise DataError(f"{records[0].source}: output {name} is constant ({y_all[0, ch]:g}); nothing to identify")


class Identifier(ABC):
    """Base class of all identifiers. Subclasses set ``name`` (the registry id) and implement fit/predict."""

    name: ClassVar[str] = "identifier"

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Every identifier's constructor accepts the deprecated option names of :data:`sysid.config.ALIASES`."""
        super().__init_subclass__(**kwargs)
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

    def set_params(self, **params: Any) -> "Identifier":
        from sysid.config import resolve_aliases

        valid = self._param_names()
        params = resolve_aliases(params, valid, self.name)
        for k, v in params.items():
            if k not in valid:
                raise ConfigError(f"{self.name}: unknown option {k!r}; valid: {', '.join(valid)}")
            setattr(self, k, v)
        return self

    @classmethod
    def from_assignments(cls, assignments: dict[str, str]) -> "Identifier":
        """Build from raw ``--set`` strings, coercing each to the type of the constructor default."""
        from sysid.config import apply_assignments

        sig = inspect.signature(cls.__init__)
        defaults = {
            p.name: p.default
            for p in sig.parameters.values()
            if p.name != "self" and p.kind is p.POSITIONAL_OR_KEYWORD
        }
        from sysid.config import resolve_aliases

        assignments = resolve_aliases(assignments, defaults, f"{cls.name} --set")
        values = apply_assignments(defaults, assignments, what=f"{cls.name} option")
        return cls(**values)

    # ------------------------------------------------------------------ learning / prediction
    @abstractmethod
    def fit(self, data: Record | Sequence[Record]) -> "Identifier":
        ...

    @abstractmethod
    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        ...

    def describe(self) -> dict[str, Any]:
        """JSON-able summary of the fitted model (subclasses add terms, structure...)."""
        return {"identifier": self.name, "params": self.get_params(), "n_parameters": getattr(self, "n_parameters_", None)}

    # ------------------------------------------------------------------ persistence
    @abstractmethod
    def _state(self) -> dict[str, Any]:
        """Learned state as JSON-able dict (arrays as lists) — enough to predict identically."""

    @abstractmethod
    def _load_state(self, state: dict[str, Any]) -> None:
        ...

    def save(self, path: str | Path) -> Path:
        """Save config and learned state as JSON (neural models may override to use torch files)."""
        payload = {"format": "piezotwin-model/1", "identifier": self.name, "params": self.get_params(), "state": self._state()}
        with output_file(path) as tmp:  # atomic: a temporary file renamed over path (sysid.safeio)
            tmp.write_text(json.dumps(payload, default=json_default))
        return Path(path)


def load_model(path: str | Path) -> Identifier:
    """Load a model written by :meth:`Identifier.save` (any registered identifier)."""
    from sysid.registry import get_identifier

    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: model file not found")
    if path.is_dir():
        raise DataError(f"{path}: is a directory, expected a model file")
    loader = None
    try:
        payload = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError):
        payload = None
    if payload is None:
        # Binary formats (torch) register a loader by suffix in the registry.
        from sysid.registry import binary_loader

        loader = binary_loader(path)
        if loader is None:
            raise DataError(f"{path}: not a piezotwin model file")
        return loader(path)
    if not isinstance(payload, dict) or payload.get("format") != "piezotwin-model/1":
        found = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise DataError(f"{path}: not a piezotwin model file (format {found!r})")
    missing = [k for k in ("identifier", "params", "state") if k not in payload]
    if missing:
        raise DataError(f"{path}: model file lacks {', '.join(missing)}")
    cls = get_identifier(payload["identifier"])
    if isinstance(payload["params"], dict):  # files written before an option was renamed (sysid.config.ALIASES)
        from sysid.config import resolve_aliases

        payload["params"] = resolve_aliases(payload["params"], cls._param_names(), f"{path}")
    unknown = sorted(set(payload["params"]) - set(cls._param_names())) if isinstance(payload["params"], dict) else ["(not a dict)"]
    if unknown:
        raise DataError(f"{path}: model file has options {', '.join(unknown)} that {cls.name} does not take")
    model = cls(**payload["params"])
    model._load_state(payload["state"])
    return model
