"""Run-time side of a hybrid-twin FMU (``piezotwin export-fmu --hybrid``): the FMI 2.0 co-simulation slave.

The FMU's ``resources/`` hold ``piezotwin_hybrid_fmu.json`` (written by :mod:`twins.fmu.hybrid_export`), the
hybrid twin file ``hybrid.json`` (:meth:`twins.hybrid.HybridTwin.save`: the physics twin's configuration and the
remainder model) and the ``sysid``/``twins`` packages. At instantiation the slave loads the hybrid twin and builds
its per-sample stepper (:meth:`twins.hybrid.HybridTwin.make_stepper`: the physics core baked in at export and the
remainder model's stepper).

Timing as for the twins and identified models (:mod:`twins.fmu.slave`): the step must be exactly ``1/fs`` (the
remainder is a discrete-time model at its estimation rate); the output ``y`` at ``t_{k+1}`` equals sample ``k`` of
the hybrid twin's ``simulate`` on the same input samples; ``y`` at ``t_0`` is 0.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pythonfmu import Fmi2Causality, Fmi2Variability, String
from pythonfmu.enums import Fmi2Status

from twins.fmu.slave import PiezoSlave, read_config, release_wrapper_state

__all__ = ["HybridSlave", "HYBRID_CONFIG_NAME", "HYBRID_FMU_FORMAT"]

HYBRID_CONFIG_NAME = "piezotwin_hybrid_fmu.json"
HYBRID_FMU_FORMAT = "piezotwin-hybrid-fmu/1"


def load_hybrid_config(resources: str | Path) -> dict[str, Any]:
    return read_config(resources, HYBRID_CONFIG_NAME, HYBRID_FMU_FORMAT)


class HybridSlave(PiezoSlave):
    """A hybrid twin (physics twin + black-box remainder) as an FMI 2.0 co-simulation slave (input ``u``,
    output ``y``)."""

    whole_steps = False  # the remainder is discrete-time at its estimation rate: the step is exactly 1/fs

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        cfg = load_hybrid_config(self.resources)
        self._header(
            cfg,
            f"PiezoTwin hybrid twin: the {cfg['twin']} twin plus a {cfg['identifier']} remainder on "
            f"the drive and the twin's output (free run at {cfg['fs']:g} Hz)",
            "input (drive)",
            "hybrid twin's output sample for the last input sample",
        )
        self.twin, self.identifier = str(cfg["twin"]), str(cfg["identifier"])
        for name, text in (("twin", "physics twin of the hybrid"), ("identifier", "identifier of the remainder")):
            self.register_variable(
                String(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed, description=text)
            )
        self._stepper: Any = None
        release_wrapper_state(self.resources)  # pythonfmu 0.7: double release of its PyState at exit

    def _start(self) -> None:
        from twins.hybrid import HybridTwin

        try:
            hy = HybridTwin.load(Path(self.resources) / self._cfg["hybrid_file"])
            self._stepper = hy.make_stepper(self._fs, core=self._cfg["core"])
        except Exception as exc:  # the message reaches the importing tool's log
            self.log(f"{type(exc).__name__}: {exc}", Fmi2Status.error)
            raise

    def _stepping(self):
        return self._stepper

    def _step(self, u: float, n: int, current_time: float) -> float:
        return self._stepper.step(u)
