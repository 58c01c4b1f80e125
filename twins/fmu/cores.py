"""Per-sample cores of an exported FMU: ``step(u) -> y`` for one input sample at the twin's rate.

``stepper``: the twin's own ``make_stepper(fs)`` (interfaces.md: the same discretisation as ``simulate``,
drawing the measurement noise in the same order), used where the twin provides it (cantilever).
``response``: for twins whose ``simulate`` is a block (FFT) computation (acoustic), a cheap causal
realisation of ``amplifier -> H(f) -> measure`` built by :mod:`twins.fmu.response`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["build_core", "choose_core"]


def choose_core(twin, fs: float) -> dict[str, Any]:
    """The core description baked into the FMU: ``{"kind": "stepper"}`` when the twin has a per-sample
    stepper, else ``{"kind": "response", ...}`` (fitted at export, see :mod:`twins.fmu.response`)."""
    make = getattr(twin, "make_stepper", None)
    if make is not None:
        try:
            make(fs)
            return {"kind": "stepper"}
        except NotImplementedError:
            pass
    if hasattr(twin, "frequency_response"):
        return {"kind": "response"}
    from sysid.errors import ConfigError

    raise ConfigError(f"twin {twin.name} has neither make_stepper(fs) nor frequency_response(f): cannot export")


def build_core(twin, fs: float, core: dict[str, Any], resources: str | Path | None = None):
    """An object with ``step(u: float) -> float`` for ``twin`` at ``fs``, starting from rest."""
    kind = core.get("kind")
    if kind == "stepper":
        stepper = twin.make_stepper(fs)
        stepper.reset()
        return stepper
    if kind == "response":
        from twins.fmu.response import ResponseCore

        return ResponseCore.for_twin(twin, fs, core, resources)
    raise ValueError(f"unknown FMU core kind {kind!r}")
