"""What an exported FMU declares: one FMU variable per physical parameter, effect switch, seed and rate.

:func:`fmu_config` turns a configured twin into the JSON-able description that the generated slave reads at
instantiation (``resources/piezotwin_fmu.json``). Mapping of a ``Params`` field (built with
:func:`twins.base.pfield`) to an FMI 2.0 scalar variable:

========================  ==========  ==================================================================
field value               FMI type    notes
========================  ==========  ==================================================================
float                     Real        ``unit`` from pfield (declared in UnitDefinitions), ``min``/``max``
                                      from the documented range, start = configured value
int                       Integer     ``min``/``max`` from the range
bool                      Boolean
str                       String      allowed choices listed in the description
list / tuple of numbers   String      written with dashes as on the command line (``75-75``, ``-1;-2``)
========================  ==========  ==================================================================

Effect switches are Boolean parameters ``effect_<id>``; ``seed`` (Integer) seeds the measurement noise as
in ``simulate``; ``fs`` [Hz] is the sampling rate, whose period is the FMU's communication step.
All of them have causality ``parameter``. Variability ``tunable`` (a change between communication
steps acts from the next step on, the dynamic state carried over) is declared only for the fields a twin
lists in ``TUNABLE_PARAMS`` and only with the ``stepper`` core, whose ``retune(twin)`` keeps the state
(cantilever: :meth:`twins.cantilever.twin.CantileverStepper.retune`). Everything else is ``fixed``, set
before initialisation (fmpy ``start_values``, a tool's parameter dialog): integer counts, model choices,
effect switches, ``seed`` and ``fs`` change the state's layout or meaning, and the ``response`` core
(acoustic) would need a new impulse response that keeps the input history, which it does not build.
"""

from __future__ import annotations

import dataclasses
import math
import re
from typing import Any

from sysid.errors import ConfigError
from twins.base import Twin, param_info

__all__ = [
    "CONFIG_NAME",
    "FORMAT",
    "RESERVED",
    "fmu_variables",
    "fmu_config",
    "encode_value",
    "decode_value",
    "twin_class_path",
]

CONFIG_NAME = "piezotwin_fmu.json"
FORMAT = "piezotwin-fmu/1"
#: names the slave itself uses; a twin parameter with one of these names cannot be exported
RESERVED = ("u", "y", "fs", "seed", "time")


def twin_class_path(twin: Twin) -> str:
    cls = type(twin)
    return f"{cls.__module__}:{cls.__qualname__}"


def _is_number_list(value: Any) -> bool:
    return isinstance(value, (list, tuple)) and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) for v in value
    )


def encode_value(value: Any, fmi_type: str) -> Any:
    """A parameter value as the FMU carries it (lists become the CLI's dash notation)."""
    if fmi_type == "String" and isinstance(value, (list, tuple)):
        parts = [repr(float(v)) if isinstance(v, float) else str(v) for v in value]
        sep = ";" if any(str(p).startswith("-") for p in parts) else "-"
        return sep.join(parts)
    if fmi_type == "Real":
        return float(value)
    if fmi_type == "Integer":
        return int(value)
    if fmi_type == "Boolean":
        return bool(value)
    return str(value)


def decode_value(value: Any, like: Any, name: str) -> Any:
    """Back from the FMU's representation to the field's Python type (``like`` = default value)."""
    from sysid.config import coerce

    if isinstance(like, (list, tuple)):
        return coerce(str(value), like, name)
    if isinstance(like, bool):
        return bool(value)
    if isinstance(like, int):
        return int(value)
    if isinstance(like, float):
        return float(value)
    return value


def _fmi_type(name: str, value: Any) -> str:
    if isinstance(value, bool):
        return "Boolean"
    if isinstance(value, int):
        return "Integer"
    if isinstance(value, float):
        return "Real"
    if isinstance(value, str) or _is_number_list(value):
        return "String"
    raise ConfigError(f"parameter {name} of type {type(value).__name__} cannot be an FMU variable")


def _finite(x: Any) -> float | None:
    return float(x) if isinstance(x, (int, float)) and math.isfinite(x) else None


def _bound(x: Any, ftype: str, upper: bool) -> float | int | None:
    """A documented range end as the FMU type writes it (Integer bounds rounded inwards)."""
    v = _finite(x)
    if v is None or ftype not in ("Real", "Integer"):
        return None
    if ftype == "Real":
        return v
    return math.floor(v) if upper else math.ceil(v)


def fmu_variables(twin: Twin, fs: float, tunable: bool = False) -> list[dict[str, Any]]:
    """The FMU parameters of ``twin`` (in declaration order), each a dict with keys
    ``name, kind (param|effect|seed|fs), field, type, start, unit, min, max, description, tunable``
    (``tunable``: only if ``tunable`` is true, for the Real fields in the twin's ``TUNABLE_PARAMS``)."""
    out: list[dict[str, Any]] = []
    live = set(getattr(type(twin), "TUNABLE_PARAMS", ())) if tunable else set()
    info = param_info(type(twin).Params)
    for f in dataclasses.fields(type(twin).Params):
        if f.name in RESERVED or f.name.startswith("effect_"):
            raise ConfigError(f"twin {twin.name}: parameter name {f.name!r} clashes with an FMU variable name")
        pi = info[f.name]
        value = getattr(twin.params, f.name)
        ftype = _fmi_type(f.name, value if value is not None else pi.default)
        doc = pi.doc or f.name
        lo, hi = pi.range
        if ftype == "String" and pi.choices:
            doc += f" (one of: {', '.join(map(str, pi.choices))})"
        if ftype == "String" and isinstance(value, (list, tuple)):
            doc += " (list written with dashes, e.g. 75-75; with ';' when a value is negative)"
        if pi.unit and ftype != "Real":
            doc += f" [{pi.unit}]"
        if pi.source:
            doc += f"; source: {pi.source}"
        out.append(
            {
                "name": f.name,
                "kind": "param",
                "field": f.name,
                "type": ftype,
                "start": encode_value(value, ftype),
                "unit": (pi.unit or None) if ftype == "Real" else None,
                "min": _bound(lo, ftype, upper=False),
                "max": _bound(hi, ftype, upper=True),
                "description": doc,
                "tunable": ftype == "Real" and f.name in live,
            }
        )
    for eid, spec in type(twin).EFFECTS.items():
        out.append(
            {
                # FMI's structured names take letters, digits and "_" here ("cubic_spring@x" -> effect_cubic_spring_x)
                "name": "effect_" + re.sub(r"\W", "_", eid),
                "kind": "effect",
                "field": eid,
                "type": "Boolean",
                "start": eid in twin.effects,
                "unit": None,
                "min": None,
                "max": None,
                "description": f"effect switch: {spec.description}",
                "tunable": False,
            }
        )
    out.append(
        {
            "name": "seed",
            "kind": "seed",
            "field": "seed",
            "type": "Integer",
            "start": int(twin.seed if twin.seed is not None else 0),
            "unit": None,
            "min": 0,
            "max": None,
            "description": "seed of the measurement noise (the same draws as piezotwin simulate --seed)",
            "tunable": False,
        }
    )
    out.append(
        {
            "name": "fs",
            "kind": "fs",
            "field": "fs",
            "type": "Real",
            "start": float(fs),
            "unit": "Hz",
            "min": None,
            "max": None,
            "description": "sampling rate; the communication step must be a whole number of periods 1/fs",
            "tunable": False,
        }
    )
    return out


def fmu_config(
    twin: Twin, fs: float, core: dict[str, Any], model_name: str, units: dict[str, str] | None = None
) -> dict[str, Any]:
    """JSON-able description baked into the FMU (``resources/piezotwin_fmu.json``)."""
    if not (isinstance(fs, (int, float)) and math.isfinite(fs) and fs > 0):
        raise ConfigError(f"fs must be a positive number of Hz, got {fs!r}")
    u = dict(type(twin).units)
    if units:
        u.update(units)
    return {
        "format": FORMAT,
        "model_name": model_name,
        "twin": twin.name,
        "twin_class": twin_class_path(twin),
        "description": (type(twin).__doc__ or twin.name).strip().splitlines()[0],
        "config": twin.config(),
        "fs": float(fs),
        "units": {"u": u.get("u", ""), "y": u.get("y", "")},
        "variables": fmu_variables(twin, fs, tunable=core.get("kind") == "stepper"),
        "core": core,
    }
