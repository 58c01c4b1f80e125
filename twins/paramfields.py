"""Parameter dataclass fields with unit, documented range, description and source (:func:`pfield`), and
reading them back (:func:`param_info`).

Kept apart from :mod:`twins.base` so that the generic calibration can read a twin's parameter ranges
without importing the twin base class that calls it.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from sysid.errors import ConfigError

__all__ = ["pfield", "ParamInfo", "param_info"]


def pfield(default: Any, unit: str, lo: float | None = None, hi: float | None = None, doc: str = "",
           choices: Iterable[Any] | None = None, source: str = "") -> Any:
    """A dataclass field for a physical parameter: default, unit, documented range [lo, hi], description.

    ``source`` says where the value comes from (physics notes section, paper). ``choices`` restricts
    string-valued parameters (e.g. a fluid name).
    """
    meta = {"unit": unit, "range": (lo, hi), "doc": doc, "source": source,
            "choices": tuple(choices) if choices is not None else None}
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


def param_info(params_cls: type) -> dict[str, ParamInfo]:
    """Field name → :class:`ParamInfo` for a parameter dataclass."""
    out = {}
    for f in dataclasses.fields(params_cls):
        md: Mapping[str, Any] = f.metadata or {}
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        out[f.name] = ParamInfo(f.name, default, md.get("unit", ""), tuple(md.get("range", (None, None))),
                                md.get("doc", ""), md.get("source", ""), md.get("choices"))
    return out
