"""Limit the threads of the BLAS libraries loaded by numpy and scipy for a block of code (``threadpoolctl``).

Why: the one-pass Gram accumulation of FROLS is a long series of mid-sized BLAS calls, and on cores shared with
other work OpenBLAS's threads spin-wait for each other, so one thread is the faster default (figures in
docs/running-at-scale.md). The thread count is taken from ``PIEZOTWIN_BLAS_THREADS`` (default 1).

The limiting itself is :func:`threadpoolctl.threadpool_limits` (the library scikit-learn uses), which finds every
loaded BLAS (OpenBLAS, MKL, BLIS, FlexiBLAS) and restores the previous counts on exit; a BLAS it does not know
is left alone, and so is every BLAS where threadpoolctl is not installed: the ``sysid`` package also runs inside an
exported FMU, whose host needs only numpy, scipy and numba (docs/fmu.md), and the limit changes speed, not results.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

import numpy  # noqa: F401  (loads numpy's BLAS before the limits are taken)
import scipy.linalg  # noqa: F401  (loads scipy's BLAS)

try:
    from threadpoolctl import threadpool_limits
except ImportError:  # pragma: no cover - an FMU host without threadpoolctl: threads left as they are
    threadpool_limits = None
__all__ = ["blas_threads"]


@contextlib.contextmanager
def blas_threads(n: int | None = None) -> Iterator[None]:
    """Run the block with ``n`` BLAS threads (default ``$PIEZOTWIN_BLAS_THREADS`` or 1), then restore."""
    if n is None:
        try:
            n = int(os.environ.get("PIEZOTWIN_BLAS_THREADS", "1"))
        except ValueError:
            n = 1
    if threadpool_limits is None:  # pragma: no cover
        yield
        return
    with threadpool_limits(limits=max(1, int(n)), user_api="blas"):
        yield
