"""The Silverbox as a user would first write it: a linear mass–spring–damper (``piezotwin diagnose --model``).

The Silverbox is an electronic circuit built to behave as a forced oscillator (Wigren & Schoukens, "Three free
data sets for development and benchmarking in nonlinear system identification", ECC 2013): the input u [V]
is the force, the output y [V] the displacement. The textbook model is Newton's law for a mass on a linear
spring with viscous damping,

    m·ẍ + d·ẋ + k·x = g·u   →   ẋ = v,   v̇ = ω₀²·(g·u − x) − 2ζω₀·v,   y = x,

with ω₀ = 2π·f0 the resonance, ζ the damping ratio and g the static gain. Nothing of the circuit's nonlinearity
is written here: the diagnosis is asked what the model lacks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from twins.base import pfield

NAME = "silverbox-linear"
UNITS = {"u": "V", "y": "V"}
STATES = {"x": ("position", "V"), "v": ("velocity", "V/s")}
INPUT = "cubic"  # the input is a sampled band-limited signal: a cubic spline between samples


@dataclass
class Params:
    f0_hz: float = pfield(60.0, "Hz", 5.0, 300.0, "resonance frequency")
    zeta: float = pfield(0.05, "1", 1e-3, 1.0, "damping ratio")
    gain: float = pfield(1.0, "V/V", 0.01, 100.0, "static gain")


def rates(x, u, p):
    w = 2.0 * math.pi * p.f0_hz
    return (x[1], w * w * (p.gain * u - x[0]) - 2.0 * p.zeta * w * x[1])


def output(x, u, p):
    return x[0]
