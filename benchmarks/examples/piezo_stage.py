"""A piezo positioning stage as its first-order user would write it: one damped mode, gain and delay-free.

Input u [V] to the stage's amplifier, output y [µm] from its capacitive sensor. The stage is the textbook
second-order resonator G(s) = g·ω₀²/(s² + 2ζω₀s + ω₀²) (a mass on the flexure's spring, viscous damping),
discretised by the bilinear map and started at rest. A user model of the diagnosis benchmark
(:mod:`benchmarks.diagnosis_bench`): the generic effects wrap it, and nothing of a real stage's hysteresis,
creep or sensor is in it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from twins.base import pfield

NAME = "piezo-stage"
UNITS = {"u": "V", "y": "um"}
CALIBRATION_PARAMS = ("gain", "f0_hz", "zeta")


@dataclass
class Params:
    gain: float = pfield(0.15, "um/V", 1e-3, 10.0, "static gain of the stage")
    f0_hz: float = pfield(350.0, "Hz", 10.0, 1e4, "first resonance")
    zeta: float = pfield(0.05, "1", 1e-3, 1.0, "damping ratio of the resonance")


def simulate(u, fs, p: Params):
    """Displacement y [µm] for the drive u [V] sampled at fs [Hz], from rest."""
    w0 = 2 * math.pi * min(p.f0_hz, 0.45 * fs)
    b, a = signal.bilinear([p.gain * w0 * w0], [1.0, 2 * p.zeta * w0, w0 * w0], fs)
    return signal.lfilter(b, a, np.asarray(u, dtype=float))
