"""Registry of identifiers: id → class, imported lazily so that e.g. torch loads only when used."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path

from sysid.errors import ConfigError

__all__ = ["IDENTIFIERS", "LINEAR_IDENTIFIERS", "get_identifier", "available_identifiers", "binary_loader"]

# id -> "module:Class". Each module owns its identifier; add a line here to register a new one.
IDENTIFIERS: dict[str, str] = {
    "fir": "sysid.linear.fir:FIR",
    "arx": "sysid.linear.arx:ARX",
    "armax": "sysid.linear.arx:ARMAX",
    "bla": "sysid.linear.bla_model:BLAModel",
    "oe": "sysid.linear.pem:OE",
    "bj": "sysid.linear.pem:BJ",
    "n4sid": "sysid.linear.subspace:N4SID",
    "narx-poly": "sysid.polynomial.narmax:NARXPoly",
    "narmax-poly": "sysid.polynomial.narmax:NARMAXPoly",
    "narx-mlp": "sysid.neural.narx_mlp:NARXMLP",
    "narx-mlp-sim": "sysid.neural.narx_mlp:NARXMLPSim",
    "rnn": "sysid.neural.rnn:RNNStateSpace",
    "ss-encoder": "sysid.neural.ss_encoder:SSEncoder",
    "wh-net": "sysid.neural.wh_net:WHNet",
    "narx-poly-sim": "sysid.polynomial.polysim:NARXPolySim",
    "oe-echo": "sysid.linear.echo_oe:EchoOE",
    "pnlss": "sysid.nonlinear.pnlss:PNLSS",
    "wh-bla": "sysid.nonlinear.wiener_hammerstein:WienerHammerstein",
}

# Identifiers whose models are linear in the input: the baselines a nonlinear model must beat (the scoring rule of
# benchmarks.scoring.floors, the linear reference of sysid.identify).
LINEAR_IDENTIFIERS: tuple[str, ...] = ("fir", "arx", "armax", "bla", "oe", "bj", "n4sid", "oe-echo")

# Binary (non-JSON) model files: suffix -> "module:function(path) -> Identifier".
BINARY_LOADERS: dict[str, str] = {
    ".pt": "sysid.neural.persist:load",
}


def _import(spec: str):
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr)


def available_identifiers() -> list[str]:
    """Ids whose module imports (an id whose module is not present yet is left out)."""
    out = []
    for key, spec in IDENTIFIERS.items():
        try:
            _import(spec)
        except (ImportError, AttributeError):
            continue
        out.append(key)
    return out


def get_identifier(name: str):
    """The identifier class registered as ``name``; unknown names are refused with the valid list."""
    if name not in IDENTIFIERS:
        raise ConfigError(f"unknown identifier {name!r}; valid: {', '.join(IDENTIFIERS)}")
    try:
        return _import(IDENTIFIERS[name])
    except (ImportError, AttributeError) as exc:
        raise ConfigError(f"identifier {name!r} is not available in this build ({exc})") from None


def binary_loader(path: Path) -> Callable | None:
    spec = BINARY_LOADERS.get(Path(path).suffix.lower())
    return None if spec is None else _import(spec)
