"""Caches of the acoustic chain's parameter-independent parts.

A diagnosis simulates the same configuration thousands of times with only a few parameters moving: the
pre-scan of an amplifier effect moves only the amplifier's nonlinearity, that of a wall echo or of crosstalk
only the term added to the chain, and the core (stack, fluid, geometry) stays at its calibration. The costly
parts — the Mason/Kino two-ports and layer matrices (:func:`twins.acoustic.channel.channel_parts`, ≈ 4 ms on
the 12 800-point grid of a 5 ms impulse response) and the reverberation series (≈ 8 ms) — depend only on the
core, so they are kept here, keyed by the exact values they depend on:

* **chain** (:func:`chain_key`): every parameter field except those listed in :data:`NOT_IN_CHAIN` (the
  amplifier's nonlinearity, gain and bandwidth, the terms added on top of the reverberation series — wall
  echo, crosstalk, output gain — and the acquisition), and every effect except :data:`EFFECTS_OUTSIDE_CHAIN`.
  A field not listed is part of the key, so a parameter added later can only cost a cache miss, never a
  stale result.
* **linear** (:func:`linear_key`): every field except the amplifier's nonlinearity and gain and the
  acquisition (:data:`NOT_IN_LINEAR`); the impulse response h of the whole linear chain and its spectra.

Entries are exact: a hit returns the arrays the same computation would give, bit for bit (the test compares
cached and uncached simulations). Each cache holds a few entries (least recently used dropped first); arrays
handed out are read-only so that no caller can change an entry.
"""

from __future__ import annotations

import dataclasses
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any

import numpy as np

__all__ = [
    "NOT_IN_CHAIN",
    "NOT_IN_LINEAR",
    "EFFECTS_OUTSIDE_CHAIN",
    "EFFECTS_OUTSIDE_LINEAR",
    "LRU",
    "chain_key",
    "linear_key",
    "grid_key",
    "CHAIN",
    "LINEAR",
    "STACK",
    "FLUID",
    "AMP_BANDWIDTH",
    "enabled",
    "disabled",
]

#: fields that act after the linear chain or before it (amplifier nonlinearity and gain, acquisition)
NOT_IN_LINEAR: frozenset[str] = frozenset(
    {
        "amp_gain_db",
        "amp_compression",
        "amp_sat_v",
        "amp_smoothness",
        "amp_even_ratio",
        "noise_v",
        "adc_bits",
        "adc_range_v",
    }
)
#: fields that enter H only through the terms added to (or multiplying) the reverberation series
NOT_IN_CHAIN: frozenset[str] = NOT_IN_LINEAR | {
    "amp_f_low_hz",
    "amp_f_high_hz",
    "model_max_hz",
    "output_gain",
    "wall_distance_m",
    "wall_reflection",
    "wall_coupling",
    "wall_echo_path",
    "wall_echo_cutoff_hz",
    "crosstalk_capacitance_f",
    "crosstalk_resistive",
    "crosstalk_derivative_s",
}
#: effects outside the linear chain (amplifier, acquisition)
EFFECTS_OUTSIDE_LINEAR: frozenset[str] = frozenset(
    {"amplifier_compression", "amplifier_even_distortion", "measurement_noise", "adc_quantization"}
)
#: effects whose terms are added to the chain's reverberation series (not part of the series itself)
EFFECTS_OUTSIDE_CHAIN: frozenset[str] = EFFECTS_OUTSIDE_LINEAR | {"wall_echo", "crosstalk"}


def _fields_key(p: Any, skip: frozenset[str]) -> tuple[Hashable, ...]:
    return tuple((f.name, getattr(p, f.name)) for f in dataclasses.fields(p) if f.name not in skip)


def chain_key(p: Any, effects: frozenset[str] | set[str]) -> tuple[Hashable, ...]:
    """What the reverberation chain (two-ports, series) depends on: parameter values and effects."""
    return (_fields_key(p, NOT_IN_CHAIN), frozenset(set(effects) - EFFECTS_OUTSIDE_CHAIN))


def linear_key(p: Any, effects: frozenset[str] | set[str]) -> tuple[Hashable, ...]:
    """What the whole linear chain H (and its impulse response) depends on."""
    return (_fields_key(p, NOT_IN_LINEAR), frozenset(set(effects) - EFFECTS_OUTSIDE_LINEAR))


def grid_key(f: np.ndarray) -> tuple[Hashable, ...]:
    """An exact key of a frequency grid (its length, ends and the hash of its bytes)."""
    f = np.ascontiguousarray(f, dtype=float)
    return (f.size, float(f[0]) if f.size else 0.0, float(f[-1]) if f.size else 0.0, hash(f.tobytes()))


class LRU:
    """A small least-recently-used map; ``get_or(key, make)`` computes and keeps an entry on a miss."""

    def __init__(self, size: int):
        self.size = int(size)
        self._d: OrderedDict[Hashable, Any] = OrderedDict()
        self.hits = 0
        self.misses = 0

    def get_or(self, key: Hashable, make: Callable[[], Any]) -> Any:
        if not _ENABLED[0]:
            return make()
        try:
            val = self._d[key]
        except KeyError:
            self.misses += 1
            val = _freeze(make())
            self._d[key] = val
            while len(self._d) > self.size:
                self._d.popitem(last=False)
            return val
        self.hits += 1
        self._d.move_to_end(key)
        return val

    def clear(self) -> None:
        self._d.clear()
        self.hits = self.misses = 0


def _freeze(val: Any) -> Any:
    """Mark the arrays of an entry read-only (a dict's values or the array itself)."""
    for a in val.values() if isinstance(val, dict) else (val,):
        if isinstance(a, np.ndarray):
            a.flags.writeable = False
    return val


_ENABLED = [True]

#: reverberation chain parts per (grid, chain key, direct_only)
CHAIN = LRU(6)
#: impulse responses (and their spectra) per (fs, grid length, linear key)
LINEAR = LRU(6)
#: the transducer stacks' fluid-independent parts per (grid, the layer, plate and load values they use)
STACK = LRU(4)
#: the factors of H that depend on the stacks and the fluid, not on the gap, per (grid, stack values, fluid state)
FLUID = LRU(4)
#: the amplifier's bandwidth response per (grid, corner frequencies)
AMP_BANDWIDTH = LRU(4)


def enabled() -> bool:
    return _ENABLED[0]


class disabled:
    """Context manager: every cache bypassed (the uncached computation, for tests and comparisons)."""

    def __enter__(self) -> disabled:
        self._was = _ENABLED[0]
        _ENABLED[0] = False
        return self

    def __exit__(self, *exc: object) -> None:
        _ENABLED[0] = self._was
