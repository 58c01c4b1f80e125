"""Parameter dataclass fields with unit, documented range, description and source (:func:`pfield`), and
reading them back (:func:`param_info`).

Kept apart from :mod:`twins.base` so that the generic calibration can read a twin's parameter ranges
without importing the twin base class that calls it.
"""

from __future__ import annotations

import dataclasses
import functools
import weakref
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from sysid.errors import ConfigError

__all__ = ["pfield", "ParamInfo", "param_info", "with_ranges"]


def pfield(
    default: Any,
    unit: str,
    lo: float | None = None,
    hi: float | None = None,
    doc: str = "",
    choices: Iterable[Any] | None = None,
    source: str = "",
) -> Any:
    """A dataclass field for a physical parameter: default, unit, documented range [lo, hi], description.

    ``source`` says where the value comes from (physics notes section, paper). ``choices`` restricts
    string-valued parameters (e.g. a fluid name).
    """
    meta = {
        "unit": unit,
        "range": (lo, hi),
        "doc": doc,
        "source": source,
        "choices": tuple(choices) if choices is not None else None,
    }
    if isinstance(default, (list, dict)):
        return field(default_factory=functools.partial(type(default), default), metadata=meta)  # a fresh copy each
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class ParamInfo:
    name: str
    default: Any
    unit: str
    range: tuple[float | None, float | None]
    doc: str
    source: str
    choices: tuple[Any, ...] | None

    def bounds(self) -> tuple[float, float]:
        """The documented range [lo, hi] as floats; :class:`ConfigError` for a parameter without one."""
        lo, hi = self.range
        if lo is None or hi is None:
            raise ConfigError(f"parameter {self.name} has no documented range [lo, hi]")
        return float(lo), float(hi)


#: param_info per class, read once: the fields' metadata do not change (a class with other ranges is a new class,
#: :func:`with_ranges`); weak keys, so that the classes a diagnosis makes do not stay alive through the cache
_INFO: weakref.WeakKeyDictionary[type, tuple[dict[str, ParamInfo], dict[str, Any]]] = weakref.WeakKeyDictionary()


def param_info(params_cls: type) -> dict[str, ParamInfo]:
    """Field name → :class:`ParamInfo` for a parameter dataclass (a new dict each call; a list or dict default is a
    fresh copy each call, as the dataclass makes it). Read once per class: a twin validates its parameters on every
    simulation, and a diagnosis simulates thousands of times."""
    cached = _INFO.get(params_cls)
    if cached is None:
        cached = _read_info(params_cls)
        _INFO[params_cls] = cached
    infos, factories = cached
    out = dict(infos)
    for name, make in factories.items():
        out[name] = dataclasses.replace(infos[name], default=make())
    return out


def _read_info(params_cls: type) -> tuple[dict[str, ParamInfo], dict[str, Any]]:
    out, factories = {}, {}
    for f in dataclasses.fields(params_cls):
        if f.default is dataclasses.MISSING and f.default_factory is not dataclasses.MISSING:
            factories[f.name] = f.default_factory
        md: Mapping[str, Any] = f.metadata or {}
        default = (
            f.default
            if f.default is not dataclasses.MISSING
            else (f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        )
        out[f.name] = ParamInfo(
            f.name,
            default,
            md.get("unit", ""),
            tuple(md.get("range", (None, None))),
            md.get("doc", ""),
            md.get("source", ""),
            md.get("choices"),
        )
    return out, factories


def with_ranges(params: Any, ranges: dict[str, tuple[float, float]], note: str = "ranges changed") -> Any:
    """A copy of the parameter dataclass instance ``params`` whose class has the documented ranges of some
    fields replaced (``ranges``: field → (lo, hi)); a subclass of the original, so every twin that checks
    ``isinstance(params, Params)`` takes it, and ``validate_params`` checks against the new ranges."""
    if not ranges:
        return params
    cls = type(params)
    fields = []
    for f in dataclasses.fields(cls):
        if f.name in ranges:
            md = dict(f.metadata)
            md["range"] = tuple(ranges[f.name])
            kw: dict[str, Any] = {"metadata": md}
            if f.default is not dataclasses.MISSING:
                kw["default"] = f.default
            elif f.default_factory is not dataclasses.MISSING:
                kw["default_factory"] = f.default_factory
            fields.append((f.name, f.type, field(**kw)))
    new_cls = dataclasses.make_dataclass(cls.__name__, fields, bases=(cls,), frozen=cls.__dataclass_params__.frozen)
    new_cls.__doc__ = f"{cls.__doc__} ({note}: {', '.join(ranges)})"
    return new_cls(**{f.name: getattr(params, f.name) for f in dataclasses.fields(cls)})
