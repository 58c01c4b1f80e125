"""Two cascaded tanks by Torricelli's law, given by their equations (``piezotwin diagnose --model``), with no
overflow written in.

Water pumped into the upper tank (input u [V] drives the pump, set once per 4 s sample) flows through a small
opening into the lower tank and out of it; the level of the lower tank is measured (y [V]). Schoukens, Mattson,
Wigren & Noël, "Cascaded tanks benchmark combining soft and hard nonlinearities" (2016), eqs. (1)–(2):

    ẋ₁ = −k₁√x₁ + k₄u,    ẋ₂ = k₂√x₁ − k₃√x₂,    y = x₂,

with the levels x₁, x₂ in the sensor's volts. This is the model as first written from the textbook: the tanks
are not bounded and nothing else is assumed; what the measurements show beyond it is the diagnosis's to find
(:mod:`benchmarks.examples.cascaded_tanks` is the same model with its overflow written by hand).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from twins.base import pfield

NAME = "torricelli-tanks"
UNITS = {"u": "V", "y": "V"}
STATES = {"x1": ("level", "V"), "x2": ("level", "V")}
INPUT = "hold"  # the pump's voltage is set once per sample


@dataclass
class Params:
    k1: float = pfield(0.05, "V^0.5/s", 1e-3, 0.5, "outflow coefficient of the upper tank")
    k2: float = pfield(0.05, "V^0.5/s", 1e-3, 0.5, "inflow coefficient of the lower tank (from the upper)")
    k3: float = pfield(0.05, "V^0.5/s", 1e-3, 0.5, "outflow coefficient of the lower tank")
    k4: float = pfield(0.03, "1/s", 1e-3, 0.5, "pump gain")
    x1_0: float = pfield(5.0, "V", 0.0, 12.0, "initial level of the upper tank")
    x2_0: float = pfield(5.0, "V", 0.0, 12.0, "initial level of the lower tank")


def rates(x, u, p):
    q1 = math.sqrt(max(x[0], 0.0))
    q2 = math.sqrt(max(x[1], 0.0))
    return (p.k4 * u - p.k1 * q1, p.k2 * q1 - p.k3 * q2)


def output(x, u, p):
    return x[1]


def initial_state(p, u0):
    return (p.x1_0, p.x2_0)
