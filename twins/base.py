"""What every twin shares: parameter dataclasses with units and ranges, the effect catalog, configuration.

A twin's *configuration* is its parameters (a dataclass whose fields carry unit, range and description in
their metadata, see :func:`pfield`) and its set of switched-on effects (:class:`EffectSpec`). The helpers
here turn the CLI's ``--params / --set / --effect / --without / --effects / --seed`` into a configured twin,
and write and read parameter files.
"""

from __future__ import annotations

import dataclasses
import json
import math
from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from sysid.config import coerce, make_rng, parse_assignments
from sysid.data.io import output_file
from sysid.data.jsonio import json_default as _json_default
from sysid.data.jsonio import read_json_file
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from twins.calibration import CalibrationResult, calibrate
from twins.paramfields import ParamInfo, param_info, pfield

__all__ = ["pfield", "ParamInfo", "param_info", "EffectSpec", "Twin", "PARAMS_FORMAT"]

PARAMS_FORMAT = "piezotwin-params/1"


@dataclass(frozen=True)
class EffectSpec:
    """One effect of a twin's catalog.

    ``params`` maps the short keys accepted by ``--effect NAME:key=value`` to field names of the twin's
    parameter dataclass (the effect's own parameters). ``signature`` is the one-line residual signature
    that reveals the effect when a twin without it is compared with data that has it.
    """

    id: str
    twin: str
    description: str
    signature: str
    params: Mapping[str, str] = field(default_factory=dict)
    default_on: bool = False
    group: str = ""  # effects the data cannot tell apart share a group name
    generic: str = ""  # the model-agnostic effect this one specialises (twins.generic_effects), if any
    # its law changes with the time since the record's start (a drift of the reading or of the gain): between
    # separate records the diagnosis judges it only over the time both records cover (twins.discrepancy.ranking)
    time_varying: bool = False
    # effects of the same catalog that are special cases of this one (Stribeck friction contains Coulomb friction):
    # the diagnosis prefers them unless this one fits significantly better (twins.discrepancy.nesting)
    nests: tuple[str, ...] = ()
    # weights (field, w) of a contrast Σ w·θ that is 0 where this effect is the one it nests (the two levels of an
    # asymmetric friction equal, a Stribeck excess 0): a fit within its uncertainty of 0 yields to the simpler one
    nest_contrast: tuple[tuple[str, float], ...] = ()

    def to_dict(self, params_cls: type | None = None) -> dict[str, Any]:
        d: dict[str, Any] = {
            "id": self.id,
            "twin": self.twin,
            "description": self.description,
            "signature": self.signature,
            "default_on": self.default_on,
            "group": self.group,
            "time_varying": self.time_varying,
        }
        if self.nests:
            d["nests"] = list(self.nests)
        info = param_info(params_cls) if params_cls is not None else {}
        d["params"] = {
            k: (
                {
                    "field": f,
                    "unit": info[f].unit,
                    "range": list(info[f].range),
                    "default": info[f].default,
                    "doc": info[f].doc,
                }
                if f in info
                else {"field": f}
            )
            for k, f in self.params.items()
        }
        return d


class Twin(ABC):
    """Base class of the digital twins.

    Subclasses define ``name``, ``Params`` (a dataclass built with :func:`pfield`), ``EFFECTS`` (catalog),
    ``PROTOCOLS`` (id → one-line description), and implement :meth:`simulate` and :meth:`generate`.
    """

    name: ClassVar[str] = "twin"
    Params: ClassVar[type]
    EFFECTS: ClassVar[dict[str, EffectSpec]] = {}
    PROTOCOLS: ClassVar[dict[str, str]] = {}
    units: ClassVar[dict[str, str]] = {"u": "V", "y": ""}
    #: parameters that ``piezotwin calibrate`` fits by default (fields of ``Params``)
    CALIBRATION_PARAMS: ClassVar[tuple[str, ...]] = ()
    #: parameters that set the state a record starts from, not the system (a remanent state, initial levels): a
    #: calibration fits them to its record; the diagnosis starts a separate validation record from the state its
    #: ``validation_start`` option says (:func:`twins.discrepancy.prediction.validation_start`)
    INITIAL_CONDITION_PARAMS: ClassVar[tuple[str, ...]] = ()

    def __init__(self, params: Any = None, effects: Iterable[str] | None = None, seed: int | None = 0):
        self.params = params if params is not None else self.Params()
        if not isinstance(self.params, self.Params):
            raise ConfigError(f"{self.name}: params must be a {self.Params.__name__}")
        self.effects = frozenset(self.default_effects() if effects is None else effects)
        unknown = sorted(self.effects - set(self.EFFECTS))
        if unknown:
            raise ConfigError(f"unknown effect {unknown[0]!r} for twin {self.name}; valid: {', '.join(self.EFFECTS)}")
        if seed is not None:
            make_rng(seed, f"{self.name}: seed")  # refuse a seed numpy cannot take now, not deep in a simulation
        self.seed = seed
        self.validate_params()

    # ------------------------------------------------------------------ catalog
    @classmethod
    def default_effects(cls) -> frozenset[str]:
        return frozenset(k for k, e in cls.EFFECTS.items() if e.default_on)

    def has(self, effect: str) -> bool:
        return effect in self.effects

    # ------------------------------------------------------------------ parameters
    def validate_params(self) -> None:
        """Refuse out-of-range values with a message that names the parameter and its range."""
        # the instance's own class: a copy with widened ranges (twins.discrepancy.ranges) validates against those
        for name, info in param_info(type(self.params)).items():
            value = getattr(self.params, name)
            lo, hi = info.range
            if isinstance(value, (int, float)) and not isinstance(value, bool):
                if math.isnan(value):
                    raise ConfigError(f"{self.name} parameter {name} is NaN; give a number in [{lo}, {hi}] {info.unit}")
                if (lo is not None and value < lo) or (hi is not None and value > hi):
                    raise ConfigError(f"{self.name} parameter {name}={value} out of range [{lo}, {hi}] {info.unit}")
            if info.choices is not None and value not in info.choices:
                raise ConfigError(
                    f"{self.name} parameter {name}={value!r} not one of: {', '.join(map(str, info.choices))}"
                )

    def with_params(self, **changes: Any) -> Self:
        """A new twin of the same class, effects and seed, with some parameters changed."""
        return type(self)(dataclasses.replace(self.params, **changes), self.effects, self.seed)

    def with_effects(self, effects: Iterable[str]) -> Self:
        return type(self)(self.params, effects, self.seed)

    def config(self) -> dict[str, Any]:
        """JSON-able configuration: twin, parameters, effects, seed."""
        return {
            "twin": self.name,
            "params": dataclasses.asdict(self.params),
            "effects": sorted(self.effects),
            "seed": self.seed,
        }

    # ------------------------------------------------------------------ simulation
    @abstractmethod
    def simulate(self, u: np.ndarray, fs: float) -> np.ndarray:
        """Output ``y`` for the input samples ``u`` at rate ``fs`` [Hz] (deterministic for ``self.seed``)."""

    def simulate_record(self, record: Record) -> Record:
        """Simulate the input of ``record``; returns a new Record with the twin's configuration in its metadata."""
        y = self.simulate(record.u, record.fs)
        meta = dict(record.meta)
        meta.update(self.config())
        return Record(u=record.u, y=y, fs=record.fs, units=dict(self.units), meta=meta, source=record.source)

    @abstractmethod
    def generate(self, protocol: str, **options: Any) -> Record:
        """Run a named protocol (``PROTOCOLS``) and return its Record."""

    def check_protocol(self, protocol: str) -> None:
        if protocol not in self.PROTOCOLS:
            raise ConfigError(f"unknown protocol {protocol!r} for twin {self.name}; valid: {', '.join(self.PROTOCOLS)}")

    def calibrate(
        self, data: Record, val: Record | None = None, names: Iterable[str] | None = None, **options: Any
    ) -> CalibrationResult[Self]:
        """Fit ``names`` (default ``CALIBRATION_PARAMS``) to ``data`` by free-run output error.

        Twins override this to add a good start (e.g. a linear pre-fit) or a staged fit.
        """
        fit = list(names) if names is not None else list(self.CALIBRATION_PARAMS)
        if not fit:
            raise ConfigError(f"twin {self.name} names no parameters to calibrate")
        return calibrate(self, data, fit, val=val, **options)

    # ------------------------------------------------------------------ parameter files
    def save_params(self, path: str | Path, extra: Mapping[str, Any] | None = None) -> Path:
        """Write the configuration (and e.g. calibration statistics in ``extra``) as a JSON parameter file."""
        payload = {"format": PARAMS_FORMAT, **self.config(), **(dict(extra) if extra else {})}
        with output_file(path) as tmp:  # atomic: a temporary file renamed over path (sysid.data.safeio)
            tmp.write_text(json.dumps(payload, indent=2, default=_json_default))
        return Path(path)

    # ------------------------------------------------------------------ configuration from the CLI
    @classmethod
    def from_options(
        cls,
        params_file: str | Path | None = None,
        set_: Iterable[str] | None = None,
        effect: Iterable[str] | None = None,
        without: Iterable[str] | None = None,
        effects: str | None = None,
        seed: int | None = 0,
    ) -> Twin:
        """Build a configured twin from the options every twin command takes (``--params``, ``--set``,
        ``--effect``, ``--without``, ``--effects``, ``--seed``).

        Order: defaults → ``params_file`` → ``effects`` (exact set, ``none`` = bare core) → ``effect``
        (add, with ``NAME:key=value,...``) → ``without`` (remove) → ``set_`` (parameters by name).
        """
        values = {f.name: getattr(cls.Params(), f.name) for f in dataclasses.fields(cls.Params)}
        active = set(cls.default_effects())
        if params_file is not None:
            data = load_params_file(params_file, cls.name)
            params = data.get("params", {})
            if not isinstance(params, dict):
                raise DataError(
                    f"{params_file}: 'params' must be an object of name: value, got {type(params).__name__}"
                )
            values.update(_coerce_all(cls, params, str(params_file)))
            if "effects" in data:
                eff = data["effects"]
                if not isinstance(eff, list) or not all(isinstance(e, str) for e in eff):
                    raise DataError(f"{params_file}: 'effects' must be a list of effect names, got {eff!r}"[:200])
                active = set(eff)
        if effects is not None:
            text = effects.strip()
            active = set() if text.lower() in ("none", "") else {e.strip() for e in text.split(",") if e.strip()}
        for item in effect or []:
            name, _, kv = str(item).partition(":")
            name = name.strip()
            spec = cls._effect_spec(name)
            active.add(name)
            for key, text in parse_assignments([kv], f"--effect {name}").items():
                fname = spec.params.get(key, key if key in spec.params.values() else None)
                if fname is None:
                    raise ConfigError(
                        f"effect {name} has no parameter {key!r}; valid: {', '.join(spec.params) or 'none'}"
                    )
                values.update(_coerce_all(cls, {fname: text}, f"--effect {name}"))
        for name in without or []:
            for n in str(name).split(","):
                n = n.strip()
                if n:
                    cls._effect_spec(n)
                    active.discard(n)
        for key, text in parse_assignments(set_).items():
            values.update(_coerce_all(cls, {key: text}, "--set"))
        unknown = sorted(active - set(cls.EFFECTS))
        if unknown:
            raise ConfigError(f"unknown effect {unknown[0]!r} for twin {cls.name}; valid: {', '.join(cls.EFFECTS)}")
        return cls(cls.Params(**values), active, seed)

    @classmethod
    def _effect_spec(cls, name: str) -> EffectSpec:
        if name not in cls.EFFECTS:
            raise ConfigError(f"unknown effect {name!r} for twin {cls.name}; valid: {', '.join(cls.EFFECTS)}")
        return cls.EFFECTS[name]


def _coerce_all(cls: type[Twin], raw: Mapping[str, Any], where: str) -> dict[str, Any]:
    info = param_info(cls.Params)
    out = {}
    for key, value in raw.items():
        if key not in info:
            raise ConfigError(f"{where}: unknown parameter {key!r} for twin {cls.name}; valid: {', '.join(info)}")
        out[key] = (
            coerce(value, info[key].default, key)
            if isinstance(value, str)
            else _json_value(value, info[key].default, key, where)
        )
    return out


def _json_value(value: Any, default: Any, key: str, where: str) -> Any:
    """A parameter value from a JSON file: its JSON type must fit the parameter's (numbers for numbers, a
    list for a list ...); refused with one line otherwise, never silently converted."""

    def kind(v: Any) -> str:
        if isinstance(v, bool):
            return "bool"
        if isinstance(v, (int, float)):
            return "number"
        if isinstance(v, (list, tuple)):
            return "list"
        return type(v).__name__

    if default is None:
        if isinstance(value, (dict, list, tuple)):
            raise ConfigError(f"{where}: parameter {key!r} must be a number, a string or null, got {kind(value)}")
        return value
    want, got = kind(default), kind(value)
    if want != got:
        raise ConfigError(f"{where}: parameter {key!r} must be a {want}, got {got} ({str(value)[:40]})")
    if got == "list" and isinstance(default, tuple):
        return tuple(value)
    return value


def load_params_file(path: str | Path, twin: str | None = None) -> dict[str, Any]:
    """Read a parameter file written by :meth:`Twin.save_params`; check it belongs to ``twin``."""
    p = Path(path)
    data = read_json_file(p, PARAMS_FORMAT, "parameter file")
    if twin is not None and data.get("twin") != twin:
        raise DataError(f"{p}: parameter file is for twin {data.get('twin')!r}, not {twin!r}")
    return data
