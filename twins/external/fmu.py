"""A twin from an FMU: its parameters become the twin's, its input and output the record's ``u`` and ``y``.

:func:`fmu_twin_class` reads the FMU's model description (FMPy) and builds an
:class:`twins.external.twin.ExternalTwin` whose core simulates the FMU:

- **parameters**: every ``parameter`` variable becomes a field of the twin's parameter dataclass (Real → float
  with its ``unit``, ``min``/``max`` as range, ``start`` as default; Integer, Boolean, String likewise). The
  calibration parameters are ``names`` (``--param``), by default every Real with a declared range; a named
  parameter without one is refused, as is a String the run needs.
- **rate**: a Real parameter ``fs`` [Hz] (the convention of ``piezotwin export-fmu``) is set to the record's
  rate; the communication step is 1/fs.
- **samples**: ``u[k]`` is applied from t_k to t_{k+1} and the output read after that step is ``y[k]`` (as
  :func:`twins.fmu.check.fmu_simulate`, so an exported twin and its FMU give the same samples).
- **speed**: a co-simulation FMU is instantiated once and, per simulation, reset, given its parameters and
  stepped sample by sample through the FMI C functions of FMPy's ``FMU2Slave`` from a compiled loop
  (:mod:`.fmiloop`: FMPy's per-call Python costs more than a step of a fast FMU); a model-exchange FMU (or FMI 1/3)
  runs through ``fmpy.simulate_fmu`` with its own solver. A run repeated with the same input, rate and parameter
  values is answered from memory (:class:`_Results`): the diagnosis simulates the same core many times while it
  fits effects that act on the core's output (measured in docs/diagnosis.md).
- **effects the FMU declares**: ``effects={"overflow": ["x1_max", "overflow_share"]}`` (``--fmu-effect``) names
  a mechanism behind a Boolean switch (``effect_<id>`` or ``<id>``) with the ranged Reals it fits; the diagnosis
  tries it beside the generic effects, and its parameters leave the default calibration set.
- **failures**: an FMU that cannot be instantiated is refused at once (one line); a simulation that fails in a
  diagnosis raises :class:`sysid.errors.DataError`, a failed trial (the instance is re-created).
"""

from __future__ import annotations

import dataclasses
import math
import sys
import threading
from collections import OrderedDict
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from sysid.errors import ConfigError, DataError
from twins.base import EffectSpec
from twins.paramfields import pfield

from .fmiloop import fmi_functions, run_steps
from .twin import ExternalTwin, external_twin_class

__all__ = ["FMUCore", "fmu_twin_class"]

_PY_TYPES = {"Real": float, "Integer": int, "Boolean": bool, "String": str, "Enumeration": int}


def _num(v: Any) -> float | None:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _start(var: Any) -> Any:
    t = var.type
    s = var.start
    if t == "Real":
        return float(s) if s is not None else 0.0
    if t in ("Integer", "Enumeration"):
        return int(s) if s is not None else 0
    if t == "Boolean":
        return s if isinstance(s, bool) else str(s).strip().lower() in ("true", "1")
    return s


class _Results:
    """Outputs of earlier runs by (input, rate, parameter values), least recently used dropped beyond ``limit`` bytes.

    Sound because every run starts from a reset instance given all its parameters (FMI 2.0: ``fmi2Reset`` returns
    the instance to its state after instantiation): the output is a function of the key. The key holds every
    value and a sample of the input; a hit is confirmed on the whole input, bit for bit."""

    def __init__(self, limit: int):
        self.limit, self.size = int(limit), 0
        self.items: OrderedDict[tuple, tuple[np.ndarray, np.ndarray]] = OrderedDict()
        self.hits = self.misses = 0

    @staticmethod
    def key(u: np.ndarray, fs: float, values: Mapping[str, Any]) -> tuple:
        sample = u[:: max(1, len(u) // 256)].tobytes()
        # repr: exact for floats (and tells 1, 1.0, True and -0.0 apart)
        return sample, len(u), repr(float(fs)), tuple(sorted((k, repr(v)) for k, v in values.items()))

    def get(self, key: tuple, u: np.ndarray) -> np.ndarray | None:
        item = self.items.get(key)
        if item is None or not np.array_equal(item[0].view(np.int64), u.view(np.int64)):
            self.misses += 1
            return None
        self.hits += 1
        self.items.move_to_end(key)
        return item[1].copy()

    def put(self, key: tuple, u: np.ndarray, y: np.ndarray) -> None:
        size = u.nbytes + y.nbytes
        if self.limit <= 0 or size > self.limit:
            return
        old = self.items.pop(key, None)
        if old is not None:
            self.size -= old[0].nbytes + old[1].nbytes
        self.items[key] = (u.copy(), y.copy())
        self.size += size
        while self.size > self.limit:
            _, (ou, oy) = self.items.popitem(last=False)
            self.size -= ou.nbytes + oy.nbytes


class FMUCore:
    """Simulates one FMU for input arrays: ``core(u, fs, params, effects) -> y`` (module docstring)."""

    #: memory for the inputs and outputs of earlier runs (0: none); 128 MB hold what a diagnosis of 80 000
    #: samples re-uses
    CACHE_BYTES = 128 << 20

    def __init__(self, path: str | Path, input_name: str | None = None, output_name: str | None = None):
        import fmpy

        self.path = Path(path)
        if not self.path.is_file():
            raise ConfigError(f"{self.path}: FMU not found")
        try:
            self.md = fmpy.read_model_description(str(self.path))
        except Exception as exc:  # noqa: BLE001 — a broken archive or description: one line
            raise ConfigError(f"{self.path}: not a readable FMU ({type(exc).__name__}: {exc})") from None
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.u_var = self._pick("input", input_name)
        self.y_var = self._pick("output", output_name)
        fs_var = self.vars.get("fs")
        self.fs_name = (
            "fs"
            if fs_var is not None
            and fs_var.causality == "parameter"
            and fs_var.type == "Real"
            and (fs_var.unit or "Hz") == "Hz"
            else None
        )
        self.params = [v for v in self.md.modelVariables if v.causality == "parameter" and v.name != self.fs_name]
        self.switches: dict[str, str] = {}  # effect id -> its Boolean switch parameter (declare_effects)
        self.cs = self.md.coSimulation is not None and self.md.fmiVersion == "2.0"
        self._lock = threading.Lock()
        self._slave: Any = None
        self._used = False
        self._functions: tuple[Any, Any, Any] | None = None  # the slave's FMI functions for the stepping loop
        self._unzip: str | None = None
        self.results = _Results(self.CACHE_BYTES)
        self._instantiate()

    def _pick(self, causality: str, name: str | None) -> Any:
        cands = [v for v in self.md.modelVariables if v.causality == causality]
        if name is not None:
            v = self.vars.get(name)
            if v is None or v.causality != causality:
                raise ConfigError(
                    f"{self.path}: no {causality} variable {name!r}; {causality}s: "
                    f"{', '.join(c.name for c in cands) or 'none'}"
                )
        elif len(cands) != 1:
            raise ConfigError(
                f"{self.path}: the FMU has {len(cands)} {causality}s "
                f"({', '.join(c.name for c in cands) or 'none'}); name one with --fmu-{causality}"
            )
        else:
            v = cands[0]
        if v.type != "Real":
            raise ConfigError(
                f"{self.path}: {causality} {v.name!r} is a {v.type} variable; only Real signals map to "
                "a record's column"
            )
        return v

    # ------------------------------------------------------------------ the instance
    def _instantiate(self) -> None:
        """Instantiate once (refused with one line when the FMU cannot be instantiated on this machine)."""
        if not self.cs:
            return
        from fmpy import extract
        from fmpy.fmi2 import FMU2Slave

        saved = list(sys.path)
        try:
            if self._unzip is None:
                self._unzip = extract(str(self.path))
            slave = FMU2Slave(
                guid=self.md.guid,
                unzipDirectory=self._unzip,
                modelIdentifier=self.md.coSimulation.modelIdentifier,
                instanceName="piezotwin",
            )
            slave.instantiate()
        except Exception as exc:  # noqa: BLE001 — a missing binary for this platform, a crash in the FMU's init
            raise ConfigError(f"{self.path}: the FMU fails to instantiate ({type(exc).__name__}: {exc})") from None
        finally:
            # a Python FMU (pythonfmu) puts its resources folder first on sys.path; processes started from this one
            # later (Dask workers, multiprocessing) would import the FMU's bundled copies of packages from it
            sys.path[:] = saved
        self._slave, self._used, self._functions = slave, False, None

    def _drop_instance(self) -> None:
        slave, self._slave = self._slave, None
        if slave is not None:
            try:
                slave.freeInstance()
            except Exception:  # noqa: BLE001 — an instance in error state may refuse even this; it is dropped
                pass

    # ------------------------------------------------------------------ one run
    def __call__(self, u: np.ndarray, fs: float, p: Any, effects: frozenset) -> np.ndarray:
        values = {v.name: getattr(p, v.name) for v in self.params if hasattr(p, v.name)}
        values.update({sw: eid in effects for eid, sw in self.switches.items()})
        if self.fs_name:
            values[self.fs_name] = float(fs)
        u = np.ascontiguousarray(u, dtype=float)
        key = _Results.key(u, fs, values)
        with self._lock:
            y = self.results.get(key, u)
            if y is not None:
                return y
            if not self.cs:
                y = self._run_fmpy(u, fs, values)
            else:
                if self._slave is None:
                    self._instantiate()
                try:
                    y = self._run_slave(u, fs, values)
                except Exception as exc:  # noqa: BLE001 — an FMU error status: a failed run, the instance re-made
                    self._drop_instance()
                    raise DataError(f"{self.path.name}: simulation failed ({type(exc).__name__}: {exc})") from None
            self.results.put(key, u, y)
            return y

    def _set(self, values: Mapping[str, Any]) -> None:
        s = self._slave
        by: dict[str, tuple[list[int], list[Any]]] = {
            "Real": ([], []),
            "Integer": ([], []),
            "Boolean": ([], []),
            "String": ([], []),
        }
        for name, val in values.items():
            v = self.vars[name]
            t = "Integer" if v.type == "Enumeration" else v.type
            by[t][0].append(v.valueReference)
            by[t][1].append(val)
        if by["Real"][0]:
            s.setReal(by["Real"][0], [float(x) for x in by["Real"][1]])
        if by["Integer"][0]:
            s.setInteger(by["Integer"][0], [int(x) for x in by["Integer"][1]])
        if by["Boolean"][0]:
            s.setBoolean(by["Boolean"][0], [bool(x) for x in by["Boolean"][1]])
        if by["String"][0]:
            s.setString(by["String"][0], [str(x) for x in by["String"][1]])

    def _run_slave(self, u: np.ndarray, fs: float, values: Mapping[str, Any]) -> np.ndarray:
        s = self._slave
        if self._used:
            s.reset()
        self._used = True
        self._set(values)
        s.setupExperiment(startTime=0.0)
        s.enterInitializationMode()
        s.exitInitializationMode()
        return self._steps(u, 1.0 / fs)

    def _steps(self, u: np.ndarray, h: float) -> np.ndarray:
        """One FMI step per sample, the loop compiled (:mod:`.fmiloop`); its C functions looked up once."""
        s = self._slave
        if self._functions is None:
            self._functions = fmi_functions(s.dll)
        return run_steps(self._functions, s.component, u, h, self.u_var.valueReference, self.y_var.valueReference)

    def _run_fmpy(self, u: np.ndarray, fs: float, values: Mapping[str, Any]) -> np.ndarray:
        """Model exchange (or FMI 1/3): ``fmpy.simulate_fmu`` with the input as a signal table."""
        import fmpy

        n = len(u)
        sig = np.zeros(n + 1, dtype=[("time", float), (self.u_var.name, float)])
        sig["time"] = np.arange(n + 1) / fs
        sig[self.u_var.name][:n] = u
        sig[self.u_var.name][n] = u[-1]
        try:
            res = fmpy.simulate_fmu(
                str(self.path),
                stop_time=n / fs,
                output_interval=1.0 / fs,
                input=sig,
                output=[self.y_var.name],
                start_values=dict(values),
                model_description=self.md,
            )
        except Exception as exc:  # noqa: BLE001
            raise DataError(f"{self.path.name}: simulation failed ({type(exc).__name__}: {exc})") from None
        y = np.asarray(res[self.y_var.name], dtype=float)
        if len(y) < n + 1:
            raise DataError(f"{self.path.name}: simulation stopped after {len(y) - 1} of {n} samples")
        return y[1 : n + 1]

    # ------------------------------------------------------------------ effects the FMU models itself
    def declare_effects(self, effects: Mapping[str, Iterable[str]] | None) -> dict[str, EffectSpec]:
        """Catalog entries of the effects the FMU models behind a Boolean switch (module docstring); refused with
        one line: no switch, a parameter the FMU lacks or that declares no range."""
        out: dict[str, EffectSpec] = {}
        for eid, pnames in dict(effects or {}).items():
            sw = next(
                (
                    n
                    for n in (f"effect_{eid}", eid)
                    if n in self.vars and self.vars[n].causality == "parameter" and self.vars[n].type == "Boolean"
                ),
                None,
            )
            if sw is None:
                raise ConfigError(
                    f"{self.path}: effect {eid!r} needs a Boolean parameter effect_{eid} (or {eid}) that switches it on"
                )
            pnames = list(dict.fromkeys(pnames))
            if not pnames:
                raise ConfigError(f"{self.path}: effect {eid!r} names no parameter to fit")
            for n in pnames:
                v = self.vars.get(n)
                if v is None or v.causality != "parameter" or v.type != "Real":
                    raise ConfigError(f"{self.path}: effect {eid!r}: no Real parameter {n!r}")
                if _num(v.min) is None or _num(v.max) is None or not float(v.max) > float(v.min):
                    raise ConfigError(f"{self.path}: effect {eid!r}: parameter {n!r} declares no range (min and max)")
            self.switches[eid] = sw
            desc = self.vars[sw].description or f"{eid}, modelled by the FMU"
            out[eid] = EffectSpec(eid, "fmu", desc, "", {n: n for n in pnames})
        return out

    # ------------------------------------------------------------------ the parameter dataclass
    def params_class(self, names: Iterable[str] | None) -> tuple[type, list[str]]:
        """(dataclass of the FMU's parameters, the calibration parameters); refusals as in the module docstring."""
        fields = []
        for v in self.params:
            if v.type == "String" and v.start is None:
                raise ConfigError(
                    f"{self.path}: String parameter {v.name!r} has no start value; the diagnosis "
                    "cannot set strings it does not know"
                )
            if v.type not in _PY_TYPES:
                continue
            lo, hi = (_num(v.min), _num(v.max)) if v.type in ("Real", "Integer") else (None, None)
            fields.append(
                (
                    v.name,
                    _PY_TYPES[v.type],
                    pfield(_start(v), v.unit or "", lo, hi, v.description or "", source=f"FMU {self.path.name}"),
                )
            )
        params_cls = dataclasses.make_dataclass(f"{_ident(self.md.modelName)}Params", fields)
        ranged = [
            v.name
            for v in self.params
            if v.type == "Real" and _num(v.min) is not None and _num(v.max) is not None and float(v.max) > float(v.min)
        ]
        if names is None:
            if not ranged:
                raise ConfigError(f"{self.path}: no Real parameter declares min and max; nothing to calibrate")
            return params_cls, ranged
        chosen = list(dict.fromkeys(names))
        for n in chosen:
            v = self.vars.get(n)
            if v is None or v.causality != "parameter":
                raise ConfigError(f"{self.path}: no parameter {n!r}; parameters with a range: {', '.join(ranged)}")
            if v.type != "Real":
                raise ConfigError(f"{self.path}: parameter {n!r} is {v.type}; only Real parameters are calibrated")
            if n not in ranged:
                raise ConfigError(
                    f"{self.path}: parameter {n!r} declares no range (min and max); it cannot be calibrated"
                )
        return params_cls, chosen


def _ident(text: str) -> str:
    s = "".join(c if c.isalnum() else "_" for c in str(text)).strip("_") or "Fmu"
    return s[0].upper() + s[1:] if not s[0].isdigit() else "Fmu" + s


def fmu_twin_class(
    path: str | Path,
    names: Iterable[str] | None = None,
    input_name: str | None = None,
    output_name: str | None = None,
    effects: Mapping[str, Iterable[str]] | None = None,
) -> type[ExternalTwin]:
    """The twin class of the FMU at ``path``: ``names`` the calibration parameters (default: every Real parameter
    with a declared range that no declared effect owns), ``input_name``/``output_name`` its signals (default: its
    only Real input/output), ``effects`` the mechanisms it models behind a switch (module docstring)."""
    core = FMUCore(path, input_name, output_name)
    model_effects = core.declare_effects(effects)
    params_cls, calib = core.params_class(names)
    if names is None:
        owned = {f for spec in model_effects.values() for f in spec.params.values()}
        calib = [c for c in calib if c not in owned]
    units = {"u": core.u_var.unit or "", "y": core.y_var.unit or ""}
    name = f"fmu:{Path(path).stem}"  # prefixed: never mistaken for a shipped twin of the same name
    return external_twin_class(
        name,
        core,
        params_cls,
        model_effects,
        calib,
        units,
        doc=f"FMU {Path(path).name} ({core.md.modelName}), {core.md.generationTool or ''}",
    )
