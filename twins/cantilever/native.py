"""One sample of the cantilever kernel as a C function: what the FMU's loader runs per ``fmi2DoStep``
(:mod:`twins.fmu.native`) instead of calling the slave's Python step.

``step(ctx, u)`` writes ``u`` into the stepper's input array, calls :func:`twins.cantilever.kernels.run_block`
on the stepper's 21 arrays, whose addresses and shapes ``ctx`` holds (:func:`native_step`), and returns the
output sample. It is the same compiled kernel on the same arrays as :meth:`CantileverStepper.step`, so the
output is bit-identical; the measurement noise, drawn per sample from numpy's generator, stays in Python (the
stepper offers no native step while it is on). Why: a call through numba's dispatcher checks the types of all
21 arrays each time, which costs more than the sample itself (measured in docs/fmu.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import carray, cfunc, njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from . import kernels as K

__all__ = ["native_step", "LAYOUT"]

#: (dtype, ndim) of each argument of ``run_block``, in order
LAYOUT = tuple(
    [(np.float64, 1)] * 3 + [(np.int64, 1)] + [(np.float64, 1)] * 7 + [(np.float64, 2)] + [(np.float64, 1)] * 9
)


def _pointer_typing(typingctx, address):
    """The integer ``address`` as a ``void *`` (numba intrinsic, called as ``_pointer(address)``)."""
    sig = types.voidptr(address)

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return sig, codegen


_pointer: Any = intrinsic(_pointer_typing)


@njit(inline="always")
def _vec(ctx, i):
    return carray(_pointer(ctx[i]), (ctx[i + 1],), np.float64)


@njit(inline="always")
def _ivec(ctx, i):
    return carray(_pointer(ctx[i]), (ctx[i + 1],), np.int64)


@njit(inline="always")
def _mat(ctx, i):
    return carray(_pointer(ctx[i]), (ctx[i + 1], ctx[i + 2]), np.float64)


@cfunc(types.float64(types.CPointer(types.int64), types.float64), cache=True)
def _step(ctx, u):
    uu = _vec(ctx, 0)
    out = _vec(ctx, 4)
    uu[0] = u
    K.run_block(
        uu,
        _vec(ctx, 2),
        out,
        _ivec(ctx, 6),
        _vec(ctx, 8),
        _vec(ctx, 10),
        _vec(ctx, 12),
        _vec(ctx, 14),
        _vec(ctx, 16),
        _vec(ctx, 18),
        _vec(ctx, 20),
        _mat(ctx, 22),
        _vec(ctx, 25),
        _vec(ctx, 27),
        _vec(ctx, 29),
        _vec(ctx, 31),
        _vec(ctx, 33),
        _vec(ctx, 35),
        _vec(ctx, 37),
        _vec(ctx, 39),
        _vec(ctx, 41),
    )
    return out[0]


def native_step(args: tuple) -> tuple[int, np.ndarray] | None:
    """(address of ``double step(int64_t *ctx, double u)``, ctx) for the kernel arguments ``args`` of a stepper
    (``u``, ``noise``, ``out`` first), or None when they do not have the expected types and layout. The arrays
    must outlive every call through the address (the stepper keeps them)."""
    if len(args) != len(LAYOUT):
        return None
    ctx: list[int] = []
    for a, (dtype, ndim) in zip(args, LAYOUT):
        if not (isinstance(a, np.ndarray) and a.dtype == dtype and a.ndim == ndim and a.flags.c_contiguous):
            return None
        ctx += [a.ctypes.data, *a.shape]
    address = _step.address
    return (int(address), np.array(ctx, dtype=np.int64)) if address else None
