"""What does not change between the simulations of a diagnosis, computed once.

A diagnosis simulates the same record thousands of times with one or two parameters changed (a pre-scan sweeps
one field, a least-squares fit perturbs one at a time). Two parts of :meth:`CantileverTwin.simulate` depend on few
of them and are cached here (their cost in docs/diagnosis.md, "Speed"):

- the exact discretisation (Φ, G0, G1) of the linear part, a function of (A, B, h) only — the same for every
  simulation that changes no modal or sensor parameter (:func:`discretise`, an LRU of 64 systems);
- the reading before the additive drift (``thermal_drift``, ``slow_drift``): the drift is added after the sensor
  and before the quantiser, so a simulation that changes only drift parameters reuses the kernel's output for the
  same input, configuration and noise (:class:`BaseOutputs`, an LRU of 4 records). :func:`add_drift` adds the drift
  and quantises with the kernel's own arithmetic (same expressions, compiled by numba), so the result is bit for
  bit the kernel's (``tests/test_discrepancy_families.py`` checks it against the stepper).
"""

from __future__ import annotations

import functools
import hashlib
import math
from collections import OrderedDict
from typing import Any

import numpy as np
from numba import njit

from twins.cantilever import kernels as K
from twins.cantilever.kernels import F_DCOS, F_DOMEGA, F_DRATE, F_DRIFT, F_DRIFTTAU, F_DSIN, F_Q, F_T

__all__ = ["discretise", "BaseOutputs", "BASE_OUTPUTS", "add_drift", "input_key"]


@functools.lru_cache(maxsize=64)
def _discretise(a: bytes, b: bytes, n: int, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    A = np.frombuffer(a, dtype=np.float64).reshape(n, n)
    B = np.frombuffer(b, dtype=np.float64)
    return K.foh_discretise(A, B, h)


def discretise(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`kernels.foh_discretise` of (A, B, h), computed once per distinct system (copies: the cache's own
    arrays are never handed out)."""
    A = np.ascontiguousarray(A, dtype=np.float64)
    B = np.ascontiguousarray(B, dtype=np.float64)
    Phi, G0, G1 = _discretise(A.tobytes(), B.tobytes(), A.shape[0], float(h))
    return Phi.copy(), G0.copy(), G1.copy()


def input_key(u: np.ndarray) -> bytes:
    """A digest of the input samples (BLAKE2b, 16 bytes): two records with the same digest are the same input."""
    return hashlib.blake2b(np.ascontiguousarray(u).tobytes(), digest_size=16).digest() + str(u.shape).encode()


class BaseOutputs:
    """LRU of the kernel's output without drift and quantiser, by (input digest, fs, configuration key)."""

    def __init__(self, size: int = 4):
        self.size = size
        self._d: OrderedDict[Any, np.ndarray] = OrderedDict()

    def get(self, key: Any) -> np.ndarray | None:
        out = self._d.get(key)
        if out is not None:
            self._d.move_to_end(key)
        return out

    def put(self, key: Any, y: np.ndarray) -> None:
        self._d[key] = y
        self._d.move_to_end(key)
        while len(self._d) > self.size:
            self._d.popitem(last=False)

    def clear(self) -> None:
        self._d.clear()


#: the process's cache of base outputs (small: a diagnosis works on two records at a time)
BASE_OUTPUTS = BaseOutputs()


@njit(cache=True)
def add_drift(base, fcfg, quant_on, out):  # pragma: no cover - compiled
    """out[k] = base[k] + drift(t_k), quantised: the arithmetic of :func:`kernels.run_block`'s output stage."""
    T = fcfg[F_T]
    drift = fcfg[F_DRIFT]
    drift_tau = fcfg[F_DRIFTTAU]
    d_rate = fcfg[F_DRATE]
    d_sin = fcfg[F_DSIN]
    d_cos = fcfg[F_DCOS]
    d_omega = fcfg[F_DOMEGA]
    q = fcfg[F_Q]
    tkf = 0.0
    for k in range(base.shape[0]):
        y = base[k]
        tk = tkf * T
        y += (
            drift * (-math.expm1(-tk / drift_tau))
            + d_rate * tk
            + d_sin * math.sin(d_omega * tk)
            + d_cos * (1.0 - math.cos(d_omega * tk))
        )
        if quant_on:
            y = q * math.floor(y / q + 0.5)
        out[k] = y
        tkf += 1.0
