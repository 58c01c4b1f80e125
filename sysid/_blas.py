"""Limit the threads of the OpenBLAS libraries bundled with numpy and scipy for a block of code.

Why: the one-pass Gram accumulation of FROLS is a long series of mid-sized BLAS calls. On a machine whose cores
are shared with other work, OpenBLAS's worker threads spin-wait for each other and a 2-thread ``dsyrk`` ran
8× slower than a 1-thread one here (2 cores, load ≈ 10). One thread is also within 2× of two on an idle
2-core machine. The thread count is taken from ``PIEZOTWIN_BLAS_THREADS`` (default 1); where the libraries
cannot be found (another BLAS build) nothing is changed.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
from collections.abc import Iterator

_LIBS: list[tuple[ctypes.CDLL, str, str]] | None = None


def _find() -> list[tuple[ctypes.CDLL, str, str]]:
    global _LIBS
    if _LIBS is not None:
        return _LIBS
    import numpy  # noqa: F401  (loads numpy's BLAS)
    import scipy.linalg  # noqa: F401  (loads scipy's BLAS)

    libs = []
    try:
        with open("/proc/self/maps") as fh:
            paths = sorted({line.split()[-1] for line in fh if "openblas" in line and line.strip().endswith(".so")})
    except OSError:
        paths = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for getter, setter in (("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
                               ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"),
                               ("openblas_get_num_threads", "openblas_set_num_threads")):
            if hasattr(lib, getter) and hasattr(lib, setter):
                libs.append((lib, getter, setter))
                break
    _LIBS = libs
    return libs


@contextlib.contextmanager
def blas_threads(n: int | None = None) -> Iterator[None]:
    """Run the block with ``n`` BLAS threads (default ``$PIEZOTWIN_BLAS_THREADS`` or 1), then restore."""
    if n is None:
        try:
            n = int(os.environ.get("PIEZOTWIN_BLAS_THREADS", "1"))
        except ValueError:
            n = 1
    saved = []
    try:
        for lib, getter, setter in _find():
            getattr(lib, getter).restype = ctypes.c_int
            saved.append((lib, setter, int(getattr(lib, getter)())))
            getattr(lib, setter)(ctypes.c_int(max(1, int(n))))
    except Exception:  # pragma: no cover - unknown BLAS build: leave it alone
        saved = []
    try:
        yield
    finally:
        for lib, setter, old in saved:
            getattr(lib, setter)(ctypes.c_int(old))
