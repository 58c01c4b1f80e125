"""Run-time side of an identified-model FMU (``piezotwin export-fmu --model``): the FMI 2.0 co-simulation slave.

The FMU's ``resources/`` hold ``piezotwin_model_fmu.json`` (written by :mod:`twins.fmu.model_export`), the
model file ``model.npz`` (:mod:`sysid.modelfile`) and the ``sysid``/``twins`` packages. At instantiation the
slave loads the model and builds its per-sample stepper (:func:`sysid.stepper.make_stepper`).

Timing as for the twins (:mod:`twins.fmu.slave`): a communication step ``[t_k, t_k + 1/fs)`` feeds ``u(t_k)``
to the stepper; the output ``y`` at ``t_k + 1/fs`` is the model's output sample ``k``. The FMU output at
``t_{k+1}`` therefore equals sample ``k`` of the model's free-run prediction from the input alone
(``model.predict(u)``, zero initial conditions). The step must be exactly ``1/fs`` (the model is a
discrete-time model at its identification rate); ``y`` at ``t_0`` is 0.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real, String
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from twins.fmu.slave import STEP_TOLERANCE, FastIO, _with_attrs, release_wrapper_state

__all__ = ["ModelSlave", "MODEL_CONFIG_NAME", "MODEL_FORMAT"]

MODEL_CONFIG_NAME = "piezotwin_model_fmu.json"
MODEL_FORMAT = "piezotwin-model-fmu/1"


def load_model_config(resources: str | Path) -> dict[str, Any]:
    path = Path(resources) / MODEL_CONFIG_NAME
    cfg = json.loads(path.read_text())
    if cfg.get("format") != MODEL_FORMAT:
        raise RuntimeError(f"{path}: not a {MODEL_FORMAT} FMU configuration")
    return cfg


class ModelSlave(FastIO, Fmi2Slave):
    """An identified PiezoTwin model as an FMI 2.0 co-simulation slave (input ``u``, output ``y``)."""

    author = "PiezoTwin"
    license = "MIT"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        cfg = load_model_config(self.resources)
        self._cfg = cfg
        self.modelName = self.__class__.__name__
        self.description = f"PiezoTwin identified {cfg['identifier']} model (free run at {cfg['fs']:g} Hz)"
        self.version = str(cfg.get("project_version", ""))
        self._fs = float(cfg["fs"])
        self.default_experiment = DefaultExperiment(start_time=0.0, step_size=1.0 / self._fs)
        self.u = 0.0
        self.y = 0.0
        self.identifier = str(cfg["identifier"])
        units = cfg.get("units", {})
        self._units = {x for x in (units.get("u"), units.get("y")) if x}
        self.register_variable(_with_attrs(
            Real("u", causality=Fmi2Causality.input, variability=Fmi2Variability.continuous, description="input"),
            unit=units.get("u") or None))
        self.register_variable(_with_attrs(
            Real("y", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
                 initial=Fmi2Initial.exact, description="model output sample for the last input sample"),
            unit=units.get("y") or None))
        self.register_variable(String("identifier", causality=Fmi2Causality.parameter,
                                      variability=Fmi2Variability.fixed, description="identifier of the model"))
        self._check_io_refs()
        self._step_checked = None  # the communication step, once checked
        self._stepper = None
        release_wrapper_state(self.resources)  # pythonfmu 0.7: double release of its PyState at exit

    def to_xml(self, model_options=dict()):  # noqa: B006 (signature of the base class)
        from xml.etree.ElementTree import Element, SubElement

        root = super().to_xml(model_options)
        if self._units:
            defs = Element("UnitDefinitions")
            for unit in sorted(self._units):
                SubElement(defs, "Unit", {"name": unit})
            index = [i for i, child in enumerate(root) if child.tag == "CoSimulation"][0] + 1
            root.insert(index, defs)
        return root

    def _start(self) -> None:
        from sysid.base import load_model
        from sysid.stepper import make_stepper

        try:
            model = load_model(Path(self.resources) / self._cfg["model_file"])
            self._stepper = make_stepper(model)
        except Exception as exc:  # the message reaches the importing tool's log
            self.log(f"{type(exc).__name__}: {exc}", Fmi2Status.error)
            raise

    def exit_initialization_mode(self):
        self._start()

    def do_step(self, current_time: float, step_size: float) -> bool:
        if self._stepper is None:
            self._start()
        if step_size != self._step_checked:  # a host keeps its step: checked once
            if abs(step_size * self._fs - 1.0) > STEP_TOLERANCE:
                msg = (f"communication step {step_size!r} s must be 1/fs = {1.0 / self._fs!r} s "
                       "(a discrete-time model)")
                self.log(msg, Fmi2Status.error)
                raise RuntimeError(msg)
            self._step_checked = step_size
        u = float(self.u)
        if not math.isfinite(u):
            msg = f"input u={u!r} at t={current_time!r} s is not finite"
            self.log(msg, Fmi2Status.error)
            raise RuntimeError(msg)
        self.y = self._stepper.step(u)
        return True
