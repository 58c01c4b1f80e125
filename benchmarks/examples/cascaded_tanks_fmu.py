"""The two-tank Torricelli model of :mod:`benchmarks.examples.cascaded_tanks` written as a user's FMU would be:
a pythonfmu co-simulation slave, standalone (it imports nothing of this project), built with
:func:`build_tanks_fmu` and diagnosed with ``piezotwin diagnose --fmu``.

The slave declares what the diagnosis reads from any FMU: its input ``u`` [V] (pump) and output ``y`` [V]
(lower tank level); Real parameters with ``min``/``max`` (the calibration parameters k1…k4, x1_0, x2_0); and the
mechanism it models itself behind a Boolean switch, ``effect_overflow``, with its ranged parameters ``x1_max``
and ``overflow_share`` — tried by ``--fmu-effect overflow=x1_max,overflow_share``. pythonfmu's ``Real`` writes no
``min``/``max``; the slave's ``_Ranged`` adds them to the XML element, as a user would.

Each communication step holds ``u`` over the step (zero-order hold, as the pump is driven) and integrates the
levels by ``substeps`` classical Runge–Kutta steps (the same law and integrator as the Python model, so both give
the same samples; ``tests/test_cascaded_tanks_fmu.py`` checks it).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["SLAVE_SOURCE", "build_tanks_fmu"]

#: the pythonfmu slave script, as a user would write it (built by :func:`build_tanks_fmu`)
SLAVE_SOURCE = '''
import math
from xml.etree.ElementTree import Element

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real

PARAMS = [  # name, start, min, max, description
    ("k1", 0.05, 1e-3, 0.5, "outflow coefficient of the upper tank [V^0.5/s]"),
    ("k2", 0.05, 1e-3, 0.5, "inflow coefficient of the lower tank [V^0.5/s]"),
    ("k3", 0.05, 1e-3, 0.5, "outflow coefficient of the lower tank [V^0.5/s]"),
    ("k4", 0.03, 1e-3, 0.5, "pump gain [1/s]"),
    ("x1_0", 5.0, 0.0, 12.0, "initial level of the upper tank [V]"),
    ("x2_0", 5.0, 0.0, 12.0, "initial level of the lower tank [V]"),
    ("x1_max", 10.0, 3.0, 15.0, "overflow level of the upper tank [V]"),
    ("overflow_share", 0.5, 0.0, 1.0, "share of the overflow that reaches the lower tank [1]"),
]


class _Ranged(Real):
    """A Real variable that declares its range (pythonfmu writes only start)."""

    def __init__(self, name, lo, hi, **kw):
        super().__init__(name, **kw)
        self.lo, self.hi = lo, hi

    def to_xml(self) -> Element:
        node = super().to_xml()
        node[0].set("min", repr(float(self.lo)))
        node[0].set("max", repr(float(self.hi)))
        return node


class CascadedTanks(Fmi2Slave):
    author = "PiezoTwin example"
    description = "Two cascaded tanks by Torricelli's law, with an optional overflow of the upper tank"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u, self.y = 0.0, 5.0
        self.substeps = 4
        self.effect_overflow = False
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))
        for name, start, lo, hi, doc in PARAMS:
            setattr(self, name, start)
            self.register_variable(_Ranged(name, lo, hi, causality=Fmi2Causality.parameter,
                                           variability=Fmi2Variability.fixed, description=doc))
        self.register_variable(Integer("substeps", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed, description="Runge-Kutta steps per step"))
        self.register_variable(Boolean("effect_overflow", causality=Fmi2Causality.parameter,
                                       variability=Fmi2Variability.fixed,
                                       description="the upper tank overflows above x1_max; a share of the excess "
                                       "falls into the lower tank"))
        self.x1 = self.x2 = 0.0

    def exit_initialization_mode(self):
        self.x1, self.x2 = float(self.x1_0), float(self.x2_0)
        self.y = self.x2

    def _rates(self, x1, x2, u):
        q1 = self.k1 * math.sqrt(max(x1, 0.0))
        d1 = -q1 + self.k4 * u
        d2 = self.k2 * math.sqrt(max(x1, 0.0)) - self.k3 * math.sqrt(max(x2, 0.0))
        if self.effect_overflow and x1 >= self.x1_max and d1 > 0.0:
            d2 += self.overflow_share * d1 * self.k2 / self.k1
            d1 = 0.0
        return d1, d2

    def do_step(self, current_time, step_size):
        n = max(int(self.substeps), 1)
        h = step_size / n
        x1, x2, u = self.x1, self.x2, float(self.u)
        for _ in range(n):
            a1, a2 = self._rates(x1, x2, u)
            b1, b2 = self._rates(x1 + 0.5 * h * a1, x2 + 0.5 * h * a2, u)
            c1, c2 = self._rates(x1 + 0.5 * h * b1, x2 + 0.5 * h * b2, u)
            d1, d2 = self._rates(x1 + h * c1, x2 + h * c2, u)
            x1 = max(x1 + h * (a1 + 2 * b1 + 2 * c1 + d1) / 6.0, 0.0)
            x2 = max(x2 + h * (a2 + 2 * b2 + 2 * c2 + d2) / 6.0, 0.0)
            if self.effect_overflow:
                x1 = min(x1, self.x1_max)
        self.x1, self.x2 = x1, x2
        self.y = x2
        return True
'''


def build_tanks_fmu(path: str | Path) -> Path:
    """Build the FMU of :data:`SLAVE_SOURCE` at ``path`` (pythonfmu; written atomically)."""
    import tempfile

    from twins.fmu.export import build_from_source

    path = Path(path)
    with tempfile.TemporaryDirectory() as tmp:
        return build_from_source(Path(tmp), "CascadedTanks", SLAVE_SOURCE, [], path)
