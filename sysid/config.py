"""Parsing of ``KEY=VALUE`` assignments (``--set``) and coercion to typed values.

One place for these rules, so every command reads options alike: ``--set`` may repeat; one ``--set`` may carry
several pairs separated by commas; a list value is written with dashes (``hidden=75-75``); names are checked against
the valid ones and refused with the list of valid names.
"""

from __future__ import annotations

import typing
import warnings
from collections.abc import Iterable, Mapping
from typing import Any

from sysid.errors import ConfigError

__all__ = [
    "parse_assignments",
    "coerce",
    "apply_assignments",
    "positive",
    "int_option",
    "make_rng",
    "ALIASES",
    "resolve_aliases",
]

# One vocabulary for identifier options, the same in the Python API, ``--set`` and model files: lags ``ny``, ``nu``,
# delay ``nk`` in every identifier that has them, the linear bypass ``linear``. Older spellings stay accepted for
# one release, with a DeprecationWarning: deprecated name -> current name. Applied to constructor keywords,
# ``set_params`` and ``--set`` alike (sysid.base.Identifier), so a saved model with the old names still loads.
ALIASES: dict[str, str] = {
    "n_y": "ny",
    "n_u": "nu",
    "linear_order": "linear",  # rnn: order of the ARX bypass (narx-mlp: linear=true)
}


def resolve_aliases(params: Mapping[str, Any], valid: Iterable[str], owner: str = "option") -> dict[str, Any]:
    """``params`` with deprecated names (:data:`ALIASES`) renamed to the current ones that ``valid`` holds.

    A deprecated name is renamed only where the current name is a valid option and the old one is not; it
    issues a :class:`DeprecationWarning`. Giving both spellings of one option is refused (ConfigError).
    """
    valid = set(valid)
    out: dict[str, Any] = {}
    renamed = []
    for key, value in params.items():
        new = ALIASES.get(key)
        if new is not None and new in valid and key not in valid:
            if new in params:
                raise ConfigError(f"{owner}: {key!r} and {new!r} are the same option; give only {new!r}")
            renamed.append((key, new))
            key = new
        out[key] = value
    if renamed:
        names = ", ".join(f"{old} -> {new}" for old, new in renamed)
        warnings.warn(
            f"{owner}: deprecated option name(s) {names}; the old names will be removed in a later release",
            DeprecationWarning,
            stacklevel=3,
        )
    return out


def parse_assignments(items: Iterable[str] | None, what: str = "--set") -> dict[str, str]:
    """``["a=1,b=2", "c=x"]`` → ``{"a": "1", "b": "2", "c": "x"}`` (raw strings, later pairs win)."""
    out: dict[str, str] = {}
    for item in items or []:
        for pair in str(item).split(","):
            pair = pair.strip()
            if not pair:
                continue
            if "=" not in pair:
                raise ConfigError(f"{what}: expected KEY=VALUE, got {pair!r}")
            key, value = pair.split("=", 1)
            key, value = key.strip(), value.strip()
            if not key:
                raise ConfigError(f"{what}: empty name in {pair!r}")
            out[key] = value
    return out


def make_rng(seed: Any, what: str = "seed"):
    """``numpy.random.default_rng(seed)``, refusing a seed numpy cannot take (negative, non-integer) with a
    one-line :class:`ConfigError` instead of numpy's ValueError."""
    import numpy as np

    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a non-negative integer, got {seed!r}") from None


def _parse_bool(text: str, key: str) -> bool:
    t = text.strip().lower()
    if t in ("1", "true", "yes", "on"):
        return True
    if t in ("0", "false", "no", "off"):
        return False
    raise ConfigError(f"{key}: expected a boolean (true/false), got {text!r}")


def coerce(text: Any, like: Any, key: str = "value", annotation: Any = None) -> Any:
    """Convert ``text`` to the type of the example value ``like`` (or of ``annotation`` when given).

    Lists/tuples are written with dashes (``75-75``) and negative numbers keep their sign (``-3``), so a
    list of negative numbers is written with ``;`` (``-1;-2``). ``None`` for ``like`` accepts numbers or
    strings; ``none`` gives ``None``.
    """
    if not isinstance(text, str):
        return text
    if text.lower() == "none" and (like is None or _optional(annotation)):
        return None
    target = _target_type(like, annotation)
    try:
        if target is bool:
            return _parse_bool(text, key)
        if target is int:
            v = _finite(text, key)
            if abs(v) > _INT_MAX:
                raise ConfigError(f"{key}: integer {text!r} out of range (|value| <= 2**53)")
            if v != int(v):
                raise ValueError
            return int(v)
        if target is float:
            return float(text)  # nan/inf are left to the owner's range checks (they name the parameter)
        if target in (list, tuple):
            elem_like = None
            if isinstance(like, (list, tuple)) and like:
                elem_like = like[0]
            parts = (text.split(";") if ";" in text else text.split("-")) if text else []
            if "" in parts:  # '-4' would silently become [4], '25--25' [25, 25]
                raise ConfigError(
                    f"{key}: list {text!r} has an empty item; list items are separated by '-' "
                    "(e.g. 25-25), negative numbers by ';' (e.g. -1;-2)"
                )
            vals = [coerce(p, elem_like if elem_like is not None else 0.0, key) if _numeric(p) else p for p in parts]
            if elem_like is not None and isinstance(elem_like, int) and not isinstance(elem_like, bool):
                vals = [int(v) for v in vals]
            return target(vals)
        if target is str:
            return text
    except ConfigError:
        raise
    except ValueError:
        name = getattr(target, "__name__", str(target))
        raise ConfigError(f"{key}: expected {name}, got {text!r}") from None
    # unknown type: try number, else keep string
    return float(text) if _numeric(text) else text


_INT_MAX = 2**53  # integers beyond this are not exact in a float and no option needs them


def _finite(text: str, key: str) -> float:
    """``float(text)`` that refuses nan and ±inf (one line)."""
    import math

    v = float(text)
    if not math.isfinite(v):
        raise ConfigError(f"{key}: expected a finite number, got {text!r}")
    return v


def _numeric(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _optional(annotation: Any) -> bool:
    return annotation is not None and type(None) in typing.get_args(annotation)


def _target_type(like: Any, annotation: Any) -> Any:
    if annotation is not None:
        origin = typing.get_origin(annotation)
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if origin in (list, tuple):
            return origin
        if origin is typing.Union and args:
            return _target_type(like, args[0])
        if annotation in (bool, int, float, str, list, tuple):
            return annotation
        if isinstance(annotation, str):  # postponed annotations: fall back on the example
            pass
    if isinstance(like, bool):
        return bool
    if isinstance(like, int):
        return int
    if isinstance(like, float):
        return float
    if isinstance(like, (list, tuple)):
        return type(like)
    if isinstance(like, str):
        return str
    return None


def apply_assignments(
    defaults: Mapping[str, Any],
    assignments: Mapping[str, str],
    what: str = "parameter",
    ranges: Mapping[str, tuple[float, float]] | None = None,
    choices: Mapping[str, Iterable[Any]] | None = None,
) -> dict[str, Any]:
    """Return ``defaults`` updated by the raw ``assignments`` with types coerced and names/ranges checked."""
    out = dict(defaults)
    for key, text in assignments.items():
        if key not in defaults:
            valid = ", ".join(sorted(defaults))
            raise ConfigError(f"unknown {what} {key!r}; valid: {valid}")
        value = coerce(text, defaults[key], key)
        if ranges and key in ranges and isinstance(value, (int, float)) and not isinstance(value, bool):
            lo, hi = ranges[key]
            if not (lo <= value <= hi):
                raise ConfigError(f"{what} {key}={value} out of range [{lo}, {hi}]")
        if choices and key in choices:
            opts = list(choices[key])
            if value not in opts:
                raise ConfigError(f"{what} {key}={value!r} not one of: {', '.join(map(str, opts))}")
        out[key] = value
    return out


def positive(name: str, value: Any, integer: bool = False) -> float:
    """``value`` as a positive finite float (an integral one if ``integer``), else a one-line ConfigError."""
    import math

    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise ConfigError(f"{name} must be positive and finite, got {value!r}")
    if integer and v != int(v):
        raise ConfigError(f"{name} must be an integer, got {value!r}")
    return v


def int_option(owner: str, name: str, value: Any, low: int) -> int:
    """An identifier's integer option ``name`` (not a bool) of at least ``low``, else a one-line ConfigError naming
    ``owner`` (the identifier)."""
    import numpy as np

    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise ConfigError(f"{owner}: {name}={value!r} must be an integer >= {low}")
    return int(value)
