"""A one-degree-of-freedom oscillator as a user would first write it for the Bouc–Wen benchmark's data
(``piezotwin diagnose --model``).

The benchmark's records (Noël & Schoukens, "Hysteretic benchmark with a dynamic nonlinearity", Workshop on
nonlinear system identification benchmarks, 2016) are the displacement y [m] of a mass driven by a force u [N].
The textbook model is a mass on a linear spring with viscous damping,

    m·ÿ + c·ẏ + k·y = u   →   ẏ = v,   v̇ = (u − c·v − k·y)/m,

with m the mass, c the damping and k the stiffness. Nothing of the hysteresis in the structure is written here:
the diagnosis is asked what the model lacks.
"""

from __future__ import annotations

from dataclasses import dataclass

from twins.base import pfield

NAME = "oscillator"
UNITS = {"u": "N", "y": "m"}
STATES = {"y": ("position", "m"), "v": ("velocity", "m/s")}
INPUT = "cubic"  # a sampled smooth force (a multisine): a cubic spline between samples


@dataclass
class Params:
    m: float = pfield(2.0, "kg", 0.1, 20.0, "moving mass")
    c: float = pfield(20.0, "N s/m", 0.1, 1000.0, "viscous damping")
    k: float = pfield(7e4, "N/m", 1e3, 1e6, "stiffness")


def rates(x, u, p):
    return (x[1], (u - p.c * x[1] - p.k * x[0]) / p.m)


def output(x, u, p):
    return x[0]
