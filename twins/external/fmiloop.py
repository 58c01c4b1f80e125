"""The co-simulation loop of :class:`twins.external.fmu.FMUCore` compiled: ``fmi2SetReal(u)``, ``fmi2DoStep`` and
``fmi2GetReal(y)`` per sample, called from a numba loop through the FMU's C function pointers.

Each sample is still one step of the FMU through its FMI 2.0 C API, as any simulation tool does it; only the
host's side of the loop is compiled. Why: FMPy's ``setReal``/``doStep``/``getReal`` make two ctypes arrays and a
list per call and check and log every call in Python, which costs more than the step of a fast FMU (measured in
docs/diagnosis.md). The loop keeps the GIL: an FMU that runs Python (pythonfmu) takes it again as it does under
any Python host.
"""

from __future__ import annotations

import ctypes
from typing import Any

import numpy as np
from numba import njit

__all__ = ["fmi_functions", "run_steps"]

#: fmi2Status above which a call failed (fmi2Discard, fmi2Error, fmi2Fatal), as FMPy judges it
FMI2_WARNING = 1

_IO = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p)
_STEP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int)


def fmi_functions(dll: Any) -> tuple[Any, Any, Any]:
    """``fmi2SetReal``, ``fmi2DoStep``, ``fmi2GetReal`` of the loaded FMU ``dll`` as typed C function pointers."""

    def pointer(name: str, proto: Any) -> Any:
        return proto(ctypes.cast(dll[name], ctypes.c_void_p).value)

    return pointer("fmi2SetReal", _IO), pointer("fmi2DoStep", _STEP), pointer("fmi2GetReal", _IO)


@njit(cache=True)
def _loop(set_real, do_step, get_real, component, u, y, h, refs, io):  # pragma: no cover - compiled
    ru = refs.ctypes.data
    ry = ru + 4  # refs is uint32: [vr of u, vr of y]
    pu = io.ctypes.data
    py = pu + 8
    for k in range(u.size):
        io[0] = u[k]
        if set_real(component, ru, 1, pu) > FMI2_WARNING:
            return k
        if do_step(component, k * h, h, 1) > FMI2_WARNING:
            return k
        if get_real(component, ry, 1, py) > FMI2_WARNING:
            return k
        y[k] = io[1]
    return u.size


def run_steps(
    functions: tuple[Any, Any, Any], component: int, u: np.ndarray, h: float, vr_u: int, vr_y: int
) -> np.ndarray:
    """The outputs after each step ``k`` (at ``k·h``, length ``h``) with input ``u[k]``; a RuntimeError names the
    sample where an FMI call failed."""
    u = np.ascontiguousarray(u, dtype=float)
    y = np.empty(len(u))
    refs = np.array([vr_u, vr_y], dtype=np.uint32)
    io = np.zeros(2)
    k = _loop(*functions, component, u, y, float(h), refs, io)
    if k < len(u):
        raise RuntimeError(f"an FMI call failed at sample {k} (t = {k * h!r} s)")
    return y
