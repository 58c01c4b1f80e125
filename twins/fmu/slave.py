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
import os
import sys
from pathlib import Path
from typing import Any
from xml.etree.ElementTree import Element, SubElement

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from twins.fmu import native
from twins.fmu.spec import CONFIG_NAME, FORMAT, decode_value

__all__ = ["FastIO", "PiezoSlave", "TwinSlave", "load_fmu_config", "release_wrapper_state"]

#: relative tolerance on ``step_size * fs`` being a whole number of samples
STEP_TOLERANCE = 1e-6


def release_wrapper_state(resources: str | Path) -> bool:
    """Drop the global ``PyState`` reference of the pythonfmu 0.7 wrapper binary that is running this slave.

    Why: the wrapper (``binaries/linux64/<model>.so``) keeps a global ``std::shared_ptr<PyState>``. At process
    exit glibc runs its C++ static destructor (an ``atexit`` handler, which frees the ``PyState``) and then
    the library's ``__attribute__((destructor))`` ``onLibraryUnload``, which assigns ``nullptr`` to the
    already destroyed pointer and so releases the freed control block a second time: a 4-byte decrement
    inside a freed 144-byte heap chunk. glibc notices at the next heap consolidation, usually in
    libgfortran's exit handler ("corrupted double-linked list", exit status 134). It happens whenever the
    wrapper is still mapped at exit, which is the rule once a library loaded later (numba's llvmlite,
    scipy) binds one of its ``STB_GNU_UNIQUE`` symbols, so ``dlclose`` cannot unmap it.
    (At ``dlclose`` the order is the safe one: ``onLibraryUnload`` first, then the static destructor.)

    Fix: call the wrapper's exported ``finalizePythonInterpreter()`` once the instance exists. It resets the
    pointer properly (the ``PyState`` is destroyed now and its worker thread, finished long ago in a
    Python host, is joined); both exit-time destructors then find ``nullptr`` and do nothing. The instance
    does not use the ``PyState``; a later instantiation by the same binary creates a new one (and this
    runs again). Done only where the importing tool is itself a Python program (``sys.orig_argv`` is set,
    so the wrapper did not start the interpreter): in a C host the ``PyState`` owns the interpreter and
    destroying it would finalise Python. Returns True if the reference was dropped.

    C host (a simulation tool written in C/C++ that loads the binary with ``dlopen``, the interpreter started
    by the wrapper): the static destructor runs ``Py_Finalize`` only after the exit handlers of every library
    loaded later (numpy, scipy, llvmlite) and the same double release follows (segmentation fault or glibc
    abort at exit in 3 of 3 runs for every FMU of this project; the acoustic FMU crashes while the
    interpreter's thread is joined). There the fix is :func:`_finalize_at_exit`: the same
    ``finalizePythonInterpreter()`` registered to run at process exit before those handlers and the static
    destructor, with the binary pinned in memory so the registered address stays valid.
    """
    if sys.platform != "linux":
        return False
    if not getattr(sys, "orig_argv", None):
        return _finalize_at_exit(resources)
    import ctypes

    folder = Path(resources).parent / "binaries" / "linux64"
    mode = getattr(os, "RTLD_NOLOAD", 4) | getattr(os, "RTLD_LAZY", 1)
    for binary in sorted(folder.glob("*.so")):
        try:  # RTLD_NOLOAD: a handle only for the binary already loaded by the importing tool
            lib = ctypes.CDLL(str(binary), mode=mode)
        except OSError:
            continue
        try:
            finalize = lib.finalizePythonInterpreter
        except AttributeError:
            continue  # not the pythonfmu 0.7 wrapper (e.g. the libpython loader in front of it)
        finalize.restype, finalize.argtypes = None, []
        finalize()
        try:
            import _ctypes

            _ctypes.dlclose(lib._handle)  # give back the reference RTLD_NOLOAD took: unloading stays possible
        except (ImportError, AttributeError, OSError):
            pass
        return True
    return False


def _finalize_at_exit(resources: str | Path) -> bool:
    """C host: make exit run the wrapper's ``finalizePythonInterpreter()`` before its static destructor.

    Exit handlers run in the reverse order of registration; the wrapper's static destructor was registered
    when the binary was loaded, so a handler registered now (``__cxa_atexit`` with no DSO handle: run at
    exit only) runs first. It resets the global ``PyState`` pointer properly (``Py_Finalize`` in the
    interpreter's own thread, which is then joined); the static destructor and ``onLibraryUnload`` then find
    ``nullptr`` and release nothing twice. The binary is made ``RTLD_NODELETE`` so that a host's ``dlclose``
    cannot unmap the function before exit. Registered once per binary and process (the marker lives in
    ``sys``, which survives pythonfmu's re-execution of the slave module). No Python code runs at exit.
    Returns True if the handler is registered (now or before).
    """
    import ctypes

    folder = Path(resources).parent / "binaries" / "linux64"
    done = sys.__dict__.setdefault("_piezotwin_fmu_exit_finalize", set())
    mode = getattr(os, "RTLD_NOLOAD", 4) | getattr(os, "RTLD_NODELETE", 0x1000) | getattr(os, "RTLD_LAZY", 1)
    for binary in sorted(folder.glob("*.so")):
        key = str(binary.resolve())
        if key in done:
            return True
        try:
            lib = ctypes.CDLL(str(binary), mode=mode)  # the loaded binary, now never unmapped
        except OSError:
            continue
        try:
            finalize = lib.finalizePythonInterpreter
        except AttributeError:
            continue  # the libpython loader (twins.fmu.shim): the wrapper is the other binary
        libc = ctypes.CDLL(None)
        register = libc.__cxa_atexit
        register.restype = ctypes.c_int
        register.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        # void (*)(void) called as void (*)(void *): the extra argument is ignored (x86-64 / aarch64 SysV ABI)
        if register(ctypes.cast(finalize, ctypes.c_void_p), None, None) != 0:
            return False
        done.add(key)
        return True
    return False


def read_config(resources: str | Path, name: str, fmt: str) -> dict[str, Any]:
    """The JSON configuration ``name`` in an FMU's ``resources/``, refused unless its ``format`` is ``fmt``."""
    path = Path(resources) / name
    cfg = json.loads(path.read_text())
    if cfg.get("format") != fmt:
        raise RuntimeError(f"{path}: not a {fmt} FMU configuration")
    return cfg


def load_fmu_config(resources: str | Path) -> dict[str, Any]:
    return read_config(resources, CONFIG_NAME, FORMAT)


def _resolve(path: str):
    """``"module:Qual.Name"`` -> the object."""
    module, _, qualname = path.partition(":")
    obj = importlib.import_module(module)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


class _Attrs:
    """Extra XML attributes (unit, min, max) for the element a pythonfmu variable writes."""

    def __init__(self, var, extra: dict[str, Any]):
        self.var, self.extra = var, {k: v for k, v in extra.items() if v is not None}

    def to_xml(self) -> Element:
        node = type(self.var).to_xml(self.var)
        child = node[0]
        for key, value in self.extra.items():
            # repr: the shortest text that reads back as the same double (pythonfmu writes 16 digits)
            child.set(key, repr(float(value)) if isinstance(value, float) else str(value))
        return node


def _with_attrs(var, **extra):
    wrapper = _Attrs(var, extra)
    var.to_xml = wrapper.to_xml  # instance attribute shadows the class method
    return var


_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}


class FastIO:
    """``set_real``/``get_real`` of the input ``u`` (value reference 0) and the output ``y`` (1) without
    pythonfmu's generic loop over variables: a host's step is a set, a ``do_step`` and a get, so these two
    calls are on the per-sample path. Same effect as the generic ones; other value references go there.

    ``u`` and ``y`` live in the loader's block once the slave has attached to it (:mod:`twins.fmu.native`):
    the loader then answers the host's set and get of them in C, and these methods only serve hosts that
    load pythonfmu's wrapper directly."""

    _block: Any = None  # the loader's block (twins.fmu.native.Block), or None
    _arms = False  # the core may have a native step (the loader disarms it before every call it forwards)
    _u_value = 0.0
    _y_value = 0.0

    @property
    def u(self) -> float:
        b = self._block
        return b.u if b is not None else self._u_value

    @u.setter
    def u(self, value: float) -> None:
        b = self._block
        if b is not None:
            b.u = value
        else:
            self._u_value = value

    @property
    def y(self) -> float:
        b = self._block
        return b.y if b is not None else self._y_value

    @y.setter
    def y(self, value: float) -> None:
        b = self._block
        if b is not None:
            b.y = value
        else:
            self._y_value = value

    def _check_io_refs(self) -> None:
        if [self.vars[0].name, self.vars[1].name] != ["u", "y"]:
            raise RuntimeError("u and y must be the first two variables registered")

    def set_real(self, vrs, values):
        if len(vrs) == 1 and vrs[0] == 0:
            self.u = values[0]
        else:
            super().set_real(vrs, values)

    def get_real(self, vrs):
        if len(vrs) == 1 and vrs[0] == 1:
            return [float(self.y)]
        return super().get_real(vrs)


class PiezoSlave(FastIO, Fmi2Slave):
    """What the twin and the identified-model slaves share: the header of the FMU (name, description, version,
    default experiment at ``1/fs``), the input ``u`` and output ``y`` with their units, the unit definitions
    of the model description, the check of the communication step and of the input, and the error path.

    A subclass calls :meth:`_header` from its ``__init__`` and implements ``_start`` (build what steps) and
    ``_step(u, n)`` (advance ``n`` samples with input ``u``, return ``y``). ``whole_steps``: a communication step
    may be any whole number of sampling periods (True) or exactly one (False: a discrete-time model)."""

    author = "PiezoTwin"
    license = "MIT"
    whole_steps = True

    def _header(self, cfg: dict[str, Any], description: str, u_text: str, y_text: str) -> None:
        """Configuration ``cfg`` (with ``fs``, ``units`` and ``project_version``), description and the
        registered ``u`` (input, continuous) and ``y`` (output, discrete, exact start 0) variables."""
        self._cfg = cfg
        self.modelName = self.__class__.__name__
        self.description = description
        self.version = str(cfg.get("project_version", ""))
        self._fs = float(cfg["fs"])
        self.default_experiment = DefaultExperiment(start_time=0.0, step_size=1.0 / self._fs)
        self._block = native.attach(self.resources)
        self._armed: Any = None  # what the loader's armed native step uses (kept alive here)
        self.u = 0.0
        self.y = 0.0
        units = cfg.get("units", {})
        self._units = {x for x in (units.get("u"), units.get("y")) if x}
        self.register_variable(
            _with_attrs(
                Real("u", causality=Fmi2Causality.input, variability=Fmi2Variability.continuous, description=u_text),
                unit=units.get("u") or None,
            )
        )
        # initial=exact: the output is defined from the start, so InitialUnknowns is consistent (notes C.4)
        self.register_variable(
            _with_attrs(
                Real(
                    "y",
                    causality=Fmi2Causality.output,
                    variability=Fmi2Variability.discrete,
                    initial=Fmi2Initial.exact,
                    description=y_text,
                ),
                unit=units.get("y") or None,
            )
        )
        self._check_io_refs()
        self._step_samples: tuple[float | None, int] = (None, 0)  # (communication step, samples per step) last checked
        if self._block is not None:
            self._block.attached = 1  # from now on the loader answers the host's set of u and get of y

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
        try:
            self._start()
        except BaseException:
            self._before_raise()
            raise

    def do_step(self, current_time: float, step_size: float) -> bool:
        try:
            if self._stepping() is None:
                self._start()
            checked, n = self._step_samples
            if step_size != checked:  # a host keeps its step: checked once
                n = self._samples_per_step(step_size)
            u = float(self.u)
            if not math.isfinite(u):
                return self._fail(f"input u={u!r} at t={current_time!r} s is not finite")
            self.y = float(self._step(u, n, current_time))
            if self._arms and self._block is not None:  # the next steps of this size in C, until a call reaches Python
                self._armed = native.arm(self._block, step_size, self._native_step() if n == 1 else None)
            return True
        except BaseException:
            self._before_raise()
            raise

    def _native_step(self) -> tuple[int, Any] | None:
        """(address of ``double f(int64_t *ctx, double u)``, ctx) that does what ``_step(u, 1, t)`` does for a
        finite ``u`` (:mod:`twins.fmu.native`), or None: every step in Python."""
        return None

    def _samples_per_step(self, step_size: float) -> int:
        """Sampling periods in the communication step ``step_size``, which must be a whole number of them (or
        exactly one where not ``whole_steps``); remembered, so that a host's constant step is checked once."""
        ratio = step_size * self._fs
        n = round(ratio)
        if not self.whole_steps and abs(ratio - 1.0) > STEP_TOLERANCE:
            return self._fail(
                f"communication step {step_size!r} s must be 1/fs = {1.0 / self._fs!r} s (a discrete-time model)"
            )
        if n < 1 or abs(ratio - n) > STEP_TOLERANCE * n:
            return self._fail(
                f"communication step {step_size!r} s is not a whole number of sampling periods "
                f"1/fs = {1.0 / self._fs!r} s"
            )
        self._step_samples = (step_size, n)
        return n

    def _fail(self, message: str) -> Any:
        """Log ``message`` for the importing tool and raise: pythonfmu turns the exception into an error
        status of the FMI call (a plain ``False`` would only discard the step)."""
        self.log(message, Fmi2Status.error)
        raise RuntimeError(message)

    def _before_raise(self) -> None:
        """Keep pythonfmu 0.7's error path from freeing live objects.

        On a Python exception its C++ wrapper (``handle_py_exception``) releases its references to the slave
        class, the instance and the log queue, and releases them once more when the instance is freed
        (``cleanPyObject`` twice); the second release would free objects still in use. One extra reference
        to each before the exception propagates balances the count (at worst it keeps three small objects
        alive after an error). The abort at exit seen with these FMUs had another cause: see
        :func:`release_wrapper_state`.
        """
        import ctypes

        for obj in (type(self), self, self.log_queue):
            ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))


class TwinSlave(PiezoSlave):
    """A configured PiezoTwin twin as an FMI 2.0 co-simulation slave (input ``u``, output ``y``)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        cfg = load_fmu_config(self.resources)
        self._values: dict[str, Any] = {}
        self._tunable = {v["name"] for v in cfg["variables"] if v.get("tunable")}
        self._retune = False  # a tunable parameter changed since the last step
        self._core = None
        self._twin_cls = _resolve(cfg["twin_class"])  # import errors surface at instantiation
        release_wrapper_state(self.resources)  # pythonfmu 0.7: double release of its PyState at exit
        self._header(
            cfg,
            f"PiezoTwin {cfg['twin']} twin: {cfg['description']}",
            "input (drive voltage)",
            "output sample of the twin for the last input sample",
        )
        for v in cfg["variables"]:
            name = v["name"]
            self._values[name] = v["start"]
            var = _TYPES[v["type"]](
                name,
                causality=Fmi2Causality.parameter,
                variability=Fmi2Variability.tunable if v.get("tunable") else Fmi2Variability.fixed,
                description=v["description"],
                getter=(lambda n=name: self._values[n]),
                setter=(lambda x, n=name: self._set(n, x)),
            )
            extra = {}
            if v["type"] == "Real":
                extra = {"start": float(v["start"]), "unit": v.get("unit"), "min": v.get("min"), "max": v.get("max")}
                if v.get("unit"):
                    self._units.add(v["unit"])
            elif v["type"] == "Integer":
                extra = {"min": v.get("min"), "max": v.get("max")}
            self.register_variable(_with_attrs(var, **extra))

    # ------------------------------------------------------------------ FMI
    def _set(self, name: str, value: Any) -> None:
        if self._core is not None:
            if name not in self._tunable:
                self.log(f"parameter {name} is fixed after initialisation; change ignored", Fmi2Status.warning)
                return
            if value != self._values[name]:
                self._retune = True  # applied at the next doStep (several changes may come together)
        self._values[name] = value

    def _stepping(self):
        return self._core

    def _native_step(self) -> tuple[int, Any] | None:
        make = getattr(self._core, "native_step", None)
        return make() if make is not None and not self._retune else None

    def _step(self, u: float, n: int, current_time: float) -> float:
        core = self._core
        if core is None:  # do_step checks _stepping() first
            raise RuntimeError("doStep before the core was built")
        if self._retune:
            try:  # the new parameters act from this step on; the core keeps its dynamic state
                core.retune(self.make_twin())
            except Exception as exc:
                return self._fail(
                    f"tunable parameter change at t={current_time!r} s refused: {type(exc).__name__}: {exc}"
                )
            self._retune = False
        step = core.step
        if n == 1:
            return step(u)
        for _ in range(n):
            y = step(u)
        return y

    # ------------------------------------------------------------------ model
    def make_twin(self):
        """The twin described by the current parameter values (raises the twin's ConfigError if invalid)."""
        cfg = self._cfg
        cls = self._twin_cls
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
            self._step_samples = (None, 0)  # fs is set now
            self._core = build_core(twin, self._fs, self._cfg["core"], self.resources)
            self._arms = hasattr(self._core, "native_step")
        except Exception as exc:  # the message reaches the importing tool's log
            self.log(f"{type(exc).__name__}: {exc}", Fmi2Status.error)
            raise
