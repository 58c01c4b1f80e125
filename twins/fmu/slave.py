"""Run-time side of an exported twin FMU: the FMI 2.0 co-simulation slave (pythonfmu).

The generated slave module in the FMU's ``resources/`` only subclasses :class:`TwinSlave`; everything
else comes from ``resources/piezotwin_fmu.json`` (written by :mod:`twins.fmu.export`): the twin class, its
configuration, the FMU variables (see :mod:`twins.fmu.spec`) and the per-sample core.

Timing: a communication step ``[t_k, t_k + h)`` with ``h = n/fs`` feeds the input ``u(t_k)`` (held) to the
twin's per-sample core ``n`` times; the output ``y`` at ``t_k + h`` is the twin's output sample for the
last of those input samples. For ``h = 1/fs`` the FMU output at ``t_{k+1}`` therefore equals sample ``k``
of ``piezotwin simulate`` on the same input samples (``y_fmu[1:] == y_sim[:-1]``): the unit delay of any
sampled-data block whose output is read at the end of its step. ``y`` at ``t_0`` is its start value 0.
"""

from __future__ import annotations

import importlib
import json
import math
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from twins.fmu.spec import CONFIG_NAME, FORMAT, decode_value

__all__ = ["TwinSlave", "load_fmu_config"]

#: relative tolerance on ``step_size * fs`` being a whole number of samples
STEP_TOLERANCE = 1e-6


def load_fmu_config(resources: str | Path) -> dict[str, Any]:
    path = Path(resources) / CONFIG_NAME
    cfg = json.loads(path.read_text())
    if cfg.get("format") != FORMAT:
        raise RuntimeError(f"{path}: not a {FORMAT} FMU configuration")
    return cfg


class _Attrs:
    """Extra XML attributes (unit, min, max) for the element a pythonfmu variable writes."""

    def __init__(self, var, extra: dict[str, Any]):
        self.var, self.extra = var, {k: v for k, v in extra.items() if v is not None}

    def to_xml(self) -> Element:
        node = type(self.var).to_xml(self.var)
        child = node[0]
        for key, value in self.extra.items():
            child.set(key, f"{value:.16g}" if isinstance(value, float) else str(value))
        return node


def _with_attrs(var, **extra):
    wrapper = _Attrs(var, extra)
    var.to_xml = wrapper.to_xml  # instance attribute shadows the class method
    return var


_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}


class TwinSlave(Fmi2Slave):
    """A configured PiezoTwin twin as an FMI 2.0 co-simulation slave (input ``u``, output ``y``)."""

    author = "PiezoTwin"
    license = "MIT"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        cfg = load_fmu_config(self.resources)
        self._cfg = cfg
        self.modelName = self.__class__.__name__
        self.description = f"PiezoTwin {cfg['twin']} twin: {cfg['description']}"
        self.version = str(cfg.get("project_version", ""))
        self._values: dict[str, Any] = {}
        self._core = None
        self._fs = float(cfg["fs"])
        self.default_experiment = DefaultExperiment(start_time=0.0, step_size=1.0 / self._fs)
        self.u = 0.0
        self.y = 0.0
        units = cfg.get("units", {})
        self._units = set()
        self.register_variable(_with_attrs(
            Real("u", causality=Fmi2Causality.input, variability=Fmi2Variability.continuous,
                 description="input (drive voltage)"), unit=units.get("u") or None))
        # initial=exact: the output is defined from the start, so InitialUnknowns is consistent (notes C.4)
        self.register_variable(_with_attrs(
            Real("y", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
                 initial=Fmi2Initial.exact, description="output sample of the twin for the last input sample"),
            unit=units.get("y") or None))
        for unit in (units.get("u"), units.get("y")):
            if unit:
                self._units.add(unit)
        for v in cfg["variables"]:
            name = v["name"]
            self._values[name] = v["start"]
            var = _TYPES[v["type"]](
                name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                description=v["description"],
                getter=(lambda n=name: self._values[n]), setter=(lambda x, n=name: self._set(n, x)))
            extra = {}
            if v["type"] == "Real":
                extra = {"unit": v.get("unit"), "min": v.get("min"), "max": v.get("max")}
                if v.get("unit"):
                    self._units.add(v["unit"])
            elif v["type"] == "Integer":
                extra = {"min": v.get("min"), "max": v.get("max")}
            self.register_variable(_with_attrs(var, **extra))

    # ------------------------------------------------------------------ FMI
    def _set(self, name: str, value: Any) -> None:
        if self._core is not None:
            self.log(f"parameter {name} is fixed after initialisation; change ignored", Fmi2Status.warning)
            return
        self._values[name] = value

    def to_xml(self, model_options=dict()) -> Element:  # noqa: B006 (signature of the base class)
        root = super().to_xml(model_options)
        if self._units:
            defs = Element("UnitDefinitions")
            for unit in sorted(self._units):
                SubElement(defs, "Unit", {"name": unit})
            index = [i for i, child in enumerate(root) if child.tag == "CoSimulation"][0] + 1
            root.insert(index, defs)
        return root

    def exit_initialization_mode(self):
        self._start()

    def do_step(self, current_time: float, step_size: float) -> bool:
        if self._core is None:
            self._start()
        ratio = step_size * self._fs
        n = round(ratio)
        if n < 1 or abs(ratio - n) > STEP_TOLERANCE * n:
            return self._fail(f"communication step {step_size!r} s is not a whole number of sampling periods "
                              f"1/fs = {1.0 / self._fs!r} s")
        u = float(self.u)
        if not math.isfinite(u):
            return self._fail(f"input u={u!r} at t={current_time!r} s is not finite")
        step = self._core.step
        y = 0.0
        for _ in range(n):
            y = step(u)
        self.y = float(y)
        return True

    def _fail(self, message: str) -> bool:
        """Log ``message`` for the importing tool and raise: pythonfmu turns the exception into an error
        status of the FMI call (a plain ``False`` would only discard the step)."""
        self.log(message, Fmi2Status.error)
        raise RuntimeError(message)

    # ------------------------------------------------------------------ model
    def make_twin(self):
        """The twin described by the current parameter values (raises the twin's ConfigError if invalid)."""
        cfg = self._cfg
        module, _, qualname = cfg["twin_class"].partition(":")
        cls = importlib.import_module(module)
        for part in qualname.split("."):
            cls = getattr(cls, part)
        defaults = cls.Params()
        values, effects, seed = {}, set(), 0
        for v in cfg["variables"]:
            value = self._values[v["name"]]
            if v["kind"] == "param":
                values[v["field"]] = decode_value(value, getattr(defaults, v["field"]), v["name"])
            elif v["kind"] == "effect":
                if bool(value):
                    effects.add(v["field"])
            elif v["kind"] == "seed":
                seed = int(value)
            elif v["kind"] == "fs":
                fs = float(value)
                if not (math.isfinite(fs) and fs > 0):
                    raise ValueError(f"fs must be positive, got {fs!r}")
                self._fs = fs
        return cls(cls.Params(**values), effects, seed)

    def _start(self) -> None:
        from twins.fmu.cores import build_core

        try:
            twin = self.make_twin()
            self._core = build_core(twin, self._fs, self._cfg["core"], self.resources)
        except Exception as exc:  # the message reaches the importing tool's log
            self.log(f"{type(exc).__name__}: {exc}", Fmi2Status.error)
            raise
