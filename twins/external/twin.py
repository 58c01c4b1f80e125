"""A twin around a simulator the user brings (a Python model or an FMU), wrapped in the generic effects.

:func:`external_twin_class` builds a :class:`twins.base.Twin` subclass from

- a *core*: ``core(u, fs, params, effects) -> y`` (the model's output samples for the input samples ``u`` at
  ``fs`` [Hz]; ``params`` an instance of the model's own parameter dataclass, ``effects`` the model's own
  effects that are on),
- the model's parameter dataclass (fields made with :func:`twins.base.pfield`: unit, range, description),
- the model's own effects (catalog entries whose parameters are fields of that dataclass),

and adds the model-agnostic catalog :data:`twins.generic_effects.GENERIC_EFFECTS` around it: the input-side
effects act on ``u`` before the core, the output-side ones on its output. The twin's parameters are the
model's fields followed by the generic effects' fields (a generic field whose name the model
uses too is called ``generic_<name>``); before a diagnosis the
generic fields' ranges follow the records (:meth:`ExternalTwin.follow_records`). Everything the diagnosis, the
calibration and ``--set`` need is then the same as for the shipped twins.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping
from typing import Any, ClassVar

import numpy as np

from sysid.data.record import Record, check_array
from sysid.errors import ConfigError, DataError
from twins.base import EffectSpec, Twin
from twins.generic_effects import GENERIC_EFFECTS, GENERIC_FIELDS, apply_input, apply_output, data_ranges
from twins.paramfields import param_info, pfield, with_ranges

__all__ = ["ExternalTwin", "external_twin_class", "Core"]

#: core(u, fs, params, effects) -> y
Core = Callable[[np.ndarray, float, Any, frozenset], np.ndarray]


class ExternalTwin(Twin):
    """A user's simulator (``CORE``) with the generic effects around it; built by :func:`external_twin_class`."""

    name: ClassVar[str] = "model"
    CORE: ClassVar[Core]
    MODEL_PARAMS: ClassVar[type]  # the model's own parameter dataclass
    MODEL_EFFECTS: ClassVar[frozenset[str]] = frozenset()  # effects the core applies itself
    #: generic field → its name here (``generic_<name>`` where the model has a parameter of that name)
    GENERIC_NAMES: ClassVar[dict[str, str]] = {}
    #: the input before a record was its first value (the model starts at an operating point), not 0 (at rest)
    INPUT_HELD: ClassVar[bool] = False

    def model_params(self) -> Any:
        """The model's own parameter dataclass instance (its fields of :attr:`params`)."""
        return self.MODEL_PARAMS(
            **{f.name: getattr(self.params, f.name) for f in dataclasses.fields(self.MODEL_PARAMS) if f.init}
        )

    def simulate(self, u: np.ndarray, fs: float) -> np.ndarray:
        """Output for the input samples ``u`` at ``fs`` [Hz]: input effects → model → output effects."""
        u = check_array(u, "u", f"{self.name} input")
        if u.ndim != 1:
            raise DataError(f"{self.name} input: u must be 1-D (one input), got shape {u.shape}")
        fs = float(fs)
        if not np.isfinite(fs) or fs <= 0:
            raise DataError(f"{self.name}: sampling rate fs must be positive and finite, got {fs}")
        gp = _Renamed(self.params, self.GENERIC_NAMES)
        v = apply_input(u, fs, self.effects, gp, self.INPUT_HELD)
        try:
            y = np.asarray(type(self).CORE(v, fs, self.model_params(), self.effects & self.MODEL_EFFECTS), dtype=float)
        except (ConfigError, DataError):
            raise
        except Exception as exc:  # noqa: BLE001 — a user's model may raise anything: a failed simulation, one line
            raise DataError(f"{self.name}: the model's simulation failed ({type(exc).__name__}: {exc})") from None
        y = np.ravel(y)
        if y.shape != u.shape:
            raise DataError(f"{self.name}: the model returned {y.size} output samples for {u.size} input samples")
        return apply_output(y, u, fs, self.effects, gp)

    def generate(self, protocol: str, **options: Any) -> Record:
        raise ConfigError(f"twin {self.name} (a user's model) has no protocols; simulate a record's input instead")

    def follow_records(self, est: Record, val: Record) -> tuple[ExternalTwin, list[str]]:
        """The twin with the generic effects' ranges set from the records (:func:`twins.generic_effects.data_ranges`);
        values outside a new range are moved onto it (a note for each of an effect that is on)."""
        u = np.concatenate([np.ravel(est.u), np.ravel(val.u)])
        y = np.concatenate([np.ravel(est.output), np.ravel(val.output)])
        ranges = {self.GENERIC_NAMES.get(k, k): r for k, r in data_ranges(u, y, est.fs).items()}
        params = with_ranges(self.params, ranges, "generic ranges from the records")
        clipped = {k: float(np.clip(getattr(params, k), lo, hi)) for k, (lo, hi) in ranges.items()}
        active = {f for e in self.effects if e in GENERIC_EFFECTS for f in self.EFFECTS[e].params.values()}
        notes = [
            f"{k} moved {float(getattr(params, k)):g} -> {v:g} (into its range from the records "
            f"[{ranges[k][0]:g}, {ranges[k][1]:g}])"
            for k, v in clipped.items()
            if k in active and v != float(getattr(params, k))
        ]
        params = dataclasses.replace(params, **clipped)
        return type(self)(params, self.effects, self.seed), notes


class _Renamed:
    """Read-only view of a parameter instance under the generic field names."""

    def __init__(self, params: Any, names: Mapping[str, str]):
        self._p, self._n = params, names

    def __getattr__(self, name: str) -> Any:
        return getattr(self._p, self._n.get(name, name))


def _generic_field(name: str, field_name: str, units: Mapping[str, str]) -> tuple[str, type, Any]:
    g = GENERIC_FIELDS[name]
    unit = g.unit.replace("{u}", units.get("u", "") or "1").replace("{y}", units.get("y", "") or "1")
    return field_name, float, pfield(g.default, unit, g.lo, g.hi, g.doc, source="twins.generic_effects")


def start_declarations(obj: Any) -> dict[str, Any]:
    """The keywords of :func:`external_twin_class` that a model file (or object) declares about the state its records
    start in: ``INITIAL_CONDITION_PARAMS`` and ``INPUT_BEFORE`` (defaults: none, ``"zero"``)."""
    return {
        "initial_condition_params": tuple(getattr(obj, "INITIAL_CONDITION_PARAMS", ()) or ()),
        "input_before": str(getattr(obj, "INPUT_BEFORE", "zero")),
    }


def external_twin_class(
    name: str,
    core: Core,
    params_cls: type,
    model_effects: Mapping[str, EffectSpec] | None = None,
    calibration_params: Iterable[str] | None = None,
    units: Mapping[str, str] | None = None,
    doc: str = "",
    base: type[ExternalTwin] | None = None,
    initial_condition_params: Iterable[str] = (),
    input_before: str = "zero",
) -> type[ExternalTwin]:
    """A :class:`ExternalTwin` subclass for a model: ``core`` simulates, ``params_cls`` is its parameter dataclass
    (fields with unit and range from :func:`twins.base.pfield`), ``model_effects`` its own effects,
    ``calibration_params`` what ``calibrate`` and the diagnosis fit by default (default: every numeric field
    with a range that belongs to no effect); ``base`` the class to derive from (a subclass of ExternalTwin);
    ``initial_condition_params`` the fields that are the state a record starts in, not properties of the system
    (:attr:`twins.base.Twin.INITIAL_CONDITION_PARAMS`: fitted on one record, they do not carry to another);
    ``input_before`` what drove the model before a record: ``"zero"`` (at rest) or ``"held"`` (the record's first
    input value: a model that starts at an operating point, such as tanks at a level; what an input delay shifts in).

    Refused with a ConfigError: a parameter class that is not a dataclass, a field or effect name that clashes
    with the generic catalog, an effect naming a field the class lacks.
    """
    if not (isinstance(params_cls, type) and dataclasses.is_dataclass(params_cls)):
        raise ConfigError(f"model {name}: its parameters must be a dataclass (fields made with twins.base.pfield)")
    model_effects = dict(model_effects or {})
    units = {"u": "", "y": "", **dict(units or {})}
    own = {f.name for f in dataclasses.fields(params_cls)}
    gnames = {k: (f"generic_{k}" if k in own else k) for k in GENERIC_FIELDS}
    clash = sorted(own & {v for k, v in gnames.items() if v != k})
    if clash:
        raise ConfigError(
            f"model {name}: parameters {clash[0][8:]!r} and {clash[0]!r} clash with a generic effect's "
            "parameter; rename one"
        )
    clash = sorted(set(model_effects) & set(GENERIC_EFFECTS))
    if clash:
        raise ConfigError(f"model {name}: effect {clash[0]!r} clashes with a generic effect; rename it")
    for eid, spec in model_effects.items():
        missing = [f for f in spec.params.values() if f not in own]
        if missing:
            raise ConfigError(
                f"model {name}: effect {eid!r} names parameter {missing[0]!r}, not a field of {params_cls.__name__}"
            )
    try:
        params_cls()
    except TypeError as exc:
        raise ConfigError(f"model {name}: every parameter needs a default value ({exc})") from None
    fields = [(f.name, f.type, f) for f in dataclasses.fields(params_cls)]
    fields += [_generic_field(k, gnames[k], units) for k in GENERIC_FIELDS]
    all_params = dataclasses.make_dataclass(
        f"{params_cls.__name__}WithEffects", [(n, t, _copy_field(f)) for n, t, f in fields]
    )
    all_params.__doc__ = f"Parameters of {params_cls.__name__} and of the generic effects."
    effects = {
        **{
            k: dataclasses.replace(v, twin=name, params={pk: gnames[f] for pk, f in v.params.items()}, generic=k)
            for k, v in GENERIC_EFFECTS.items()
        },
        **{k: dataclasses.replace(v, twin=name) for k, v in model_effects.items()},
    }
    if calibration_params is None:
        owned = {f for s in model_effects.values() for f in s.params.values()}
        info = param_info(params_cls)
        calibration_params = [
            k
            for k, i in info.items()
            if k not in owned
            and i.range[0] is not None
            and i.range[1] is not None
            and isinstance(i.default, (int, float))
            and not isinstance(i.default, (bool, int))
        ]
    calib = tuple(calibration_params)
    unknown = [c for c in calib if c not in own]
    if unknown:
        raise ConfigError(f"model {name}: calibration parameter {unknown[0]!r} is not a field of {params_cls.__name__}")
    initial = tuple(initial_condition_params)
    unknown = [c for c in initial if c not in own]
    if unknown:
        raise ConfigError(
            f"model {name}: initial-condition parameter {unknown[0]!r} is not a field of {params_cls.__name__}"
        )
    if input_before not in ("zero", "held"):
        raise ConfigError(f"model {name}: INPUT_BEFORE must be 'zero' or 'held', got {input_before!r}")
    attrs = {
        "name": name,
        "Params": all_params,
        "EFFECTS": effects,
        "PROTOCOLS": {},
        "units": units,
        "CALIBRATION_PARAMS": calib,
        "INITIAL_CONDITION_PARAMS": initial,
        "INPUT_HELD": input_before == "held",
        "CORE": staticmethod(core),
        "MODEL_PARAMS": params_cls,
        "MODEL_EFFECTS": frozenset(model_effects),
        "GENERIC_NAMES": gnames,
        "__doc__": doc or ExternalTwin.__doc__,
    }
    return type(f"{params_cls.__name__}Twin", (base or ExternalTwin,), attrs)


def _copy_field(f: Any) -> Any:
    """A fresh ``dataclasses.field`` with the default and metadata of ``f`` (a field object cannot be reused)."""
    if not isinstance(f, dataclasses.Field):
        return f
    kw: dict[str, Any] = {"metadata": dict(f.metadata or {})}
    if f.default is not dataclasses.MISSING:
        kw["default"] = f.default
    elif f.default_factory is not dataclasses.MISSING:
        kw["default_factory"] = f.default_factory
    return dataclasses.field(**kw)
