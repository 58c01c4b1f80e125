"""The slave's side of the per-sample calls the FMU's loader answers in C (:mod:`twins.fmu.shim`).

At instantiation (and after ``fmi2Reset``, which makes a new slave) the slave asks the loader, through its
exported ``piezotwin_instance()``, for the block of the instance being created and keeps its input ``u`` and
output ``y`` there (:class:`Block`). The host's ``fmi2SetReal(u)`` and ``fmi2GetReal(y)`` then never enter
Python. A core with a native step (``native_step()``: the address of ``double f(int64_t *ctx, double u)`` and
its ``ctx``) is armed after each step the slave takes in Python; the loader then runs ``fmi2DoStep`` of that
step size itself until any other call reaches the slave. Where the binary is not this project's loader (no
``gcc`` at export, another platform) nothing attaches and every call goes through pythonfmu as before.

Measured (docs/fmu.md, "Speed of the FMU step"): the cantilever FMU's step through FMPy's ``FMU2Slave``.
"""

from __future__ import annotations

import ctypes
import os
import sys
from pathlib import Path
from typing import Any

__all__ = ["Block", "attach", "arm"]

#: the loader's ``INST_MAGIC``: the block is one of this layout
MAGIC = 0x50545731
#: the wrapper beside the loader (:data:`twins.fmu.shim.WRAPPED_SUFFIX`)
_WRAPPED_SUFFIX = ".pythonfmu.so"


class Block(ctypes.Structure):
    """The loader's ``Inst`` (same fields, same order)."""

    _fields_ = [
        ("magic", ctypes.c_uint),
        ("attached", ctypes.c_int),
        ("u", ctypes.c_double),
        ("y", ctypes.c_double),
        ("h", ctypes.c_double),
        ("step", ctypes.c_void_p),
        ("ctx", ctypes.c_void_p),
        ("last_time", ctypes.c_double),
        ("stepped_here", ctypes.c_int),
        ("pad", ctypes.c_int),
        ("inner", ctypes.c_void_p),
    ]


_loaders: dict[str, Any] = {}


def _instance_function(resources: str | Path) -> Any:
    """``piezotwin_instance`` of the loader that the host has loaded from this FMU's ``binaries/linux64``."""
    folder = Path(resources).parent / "binaries" / "linux64"
    key = str(folder)
    if key in _loaders:
        return _loaders[key]
    found = None
    mode = getattr(os, "RTLD_NOLOAD", 4) | getattr(os, "RTLD_LAZY", 1)
    for binary in sorted(folder.glob("*.so")):
        if binary.name.endswith(_WRAPPED_SUFFIX):
            continue
        try:  # RTLD_NOLOAD: only a binary the host has loaded
            lib = ctypes.CDLL(str(binary), mode=mode)
        except OSError:
            continue
        fn = getattr(lib, "piezotwin_instance", None)
        if fn is not None:
            fn.restype, fn.argtypes = ctypes.c_void_p, []
            found = fn
            break
    _loaders[key] = found
    return found


def attach(resources: str | Path) -> Block | None:
    """The loader's block of the instance whose creation is running (None: not loaded through the loader)."""
    if sys.platform != "linux":
        return None
    fn = _instance_function(resources)
    address = fn() if fn is not None else None
    if not address:
        return None
    block = Block.from_address(address)
    return block if block.magic == MAGIC else None


def arm(block: Block, step_size: float, native: tuple[int, Any] | None) -> Any:
    """Let the loader run the communication step ``step_size`` with ``native`` (address, ctx array); returns what
    must stay alive while it is armed (the ctx), or None when there is no native step."""
    block.step = None
    if native is None:
        return None
    address, ctx = native
    block.h = float(step_size)
    block.ctx = ctx.ctypes.data
    block.step = address
    return ctx
