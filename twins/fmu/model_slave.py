"""Run-time side of an identified-model FMU (``piezotwin export-fmu --model``): the FMI 2.0 co-simulation slave.

The FMU's ``resources/`` hold ``piezotwin_model_fmu.json`` (written by :mod:`twins.fmu.model_export`), the
model file ``model.npz`` (:mod:`sysid.data.modelfile`) and the ``sysid``/``twins`` packages. At instantiation the
slave loads the model and builds its per-sample stepper (:func:`sysid.stepper.make_stepper`).

Timing as for the twins (:mod:`twins.fmu.slave`): a communication step ``[t_k, t_k + 1/fs)`` feeds ``u(t_k)``
to the stepper; the output ``y`` at ``t_k + 1/fs`` is the model's output sample ``k``. The FMU output at
``t_{k+1}`` therefore equals sample ``k`` of the model's free-run prediction from the input alone
(``model.predict(u)``, zero initial conditions). The step must be exactly ``1/fs`` (the model is a
discrete-time model at its identification rate); ``y`` at ``t_0`` is 0.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pythonfmu import Fmi2Causality, Fmi2Variability, String
from pythonfmu.enums import Fmi2Status

from twins.fmu.slave import PiezoSlave, read_config, release_wrapper_state

__all__ = ["ModelSlave", "MODEL_CONFIG_NAME", "MODEL_FORMAT"]

MODEL_CONFIG_NAME = "piezotwin_model_fmu.json"
MODEL_FORMAT = "piezotwin-model-fmu/1"


def load_model_config(resources: str | Path) -> dict[str, Any]:
    return read_config(resources, MODEL_CONFIG_NAME, MODEL_FORMAT)


class ModelSlave(PiezoSlave):
    """An identified PiezoTwin model as an FMI 2.0 co-simulation slave (input ``u``, output ``y``)."""

    whole_steps = False  # a discrete-time model at its identification rate: the step is exactly 1/fs

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        cfg = load_model_config(self.resources)
        self._header(
            cfg,
            f"PiezoTwin identified {cfg['identifier']} model (free run at {cfg['fs']:g} Hz)",
            "input",
            "model output sample for the last input sample",
        )
        self.identifier = str(cfg["identifier"])
        self.register_variable(
            String(
                "identifier",
                causality=Fmi2Causality.parameter,
                variability=Fmi2Variability.fixed,
                description="identifier of the model",
            )
        )
        self._stepper = None
        release_wrapper_state(self.resources)  # pythonfmu 0.7: double release of its PyState at exit

    def _start(self) -> None:
        from sysid.base import load_model
        from sysid.stepper import make_stepper

        try:
            model = load_model(Path(self.resources) / self._cfg["model_file"])
            self._stepper = make_stepper(model)
        except Exception as exc:  # the message reaches the importing tool's log
            self.log(f"{type(exc).__name__}: {exc}", Fmi2Status.error)
            raise

    def _stepping(self):
        return self._stepper

    def _step(self, u: float, n: int, current_time: float) -> float:
        stepper = self._stepper
        if stepper is None:  # do_step checks _stepping() first
            raise RuntimeError("doStep before the model was loaded")
        return stepper.step(u)
