"""Registry of twins: id → class, imported lazily."""

from __future__ import annotations

import importlib

from sysid.errors import ConfigError

TWINS: dict[str, str] = {
    "cantilever": "twins.cantilever:CantileverTwin",
    "acoustic": "twins.acoustic:AcousticTwin",
}


def get_twin(name: str):
    """The twin class registered as ``name``; unknown names are refused with the valid list."""
    if name not in TWINS:
        raise ConfigError(f"unknown twin {name!r}; valid: {', '.join(TWINS)}")
    module, _, attr = TWINS[name].partition(":")
    try:
        return getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as exc:
        raise ConfigError(f"twin {name!r} is not available in this build ({exc})") from None


def available_twins() -> list[str]:
    out = []
    for name in TWINS:
        try:
            get_twin(name)
        except ConfigError:
            continue
        out.append(name)
    return out
