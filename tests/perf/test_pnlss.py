"""Speed of the PNLSS simulation with its sensitivity Jacobian (the cost of one search step of ``pnlss``): the
compiled forward recursion of :mod:`sysid.nonlinear.pnlss_sim` against the same recursion written with numpy per sample.

Run with ``make bench`` (or ``pytest tests/perf/test_pnlss.py --benchmark-enable``). Both compute the same
Jacobian (checked here to 1e-10); the reference loop is the plain NumPy form of eq. 18-20 of Paduart et al. 2010.
"""

from __future__ import annotations

import numpy as np
import pytest

from sysid.nonlinear import pnlss_sim as ps

N = 5000
NX, DEGREE = 2, 3


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(0)
    fac = ps.monomials(NX + 1, DEGREE)
    A = np.array([[0.6, 0.3], [-0.3, 0.6]])
    B, C, D = np.array([[1.0], [0.5]]), np.array([[1.0, 0.2]]), np.array([[0.1]])
    E, F = 0.01 * rng.standard_normal((NX, len(fac))), 0.01 * rng.standard_normal((1, len(fac)))
    u = rng.uniform(-1, 1, (N, 1))
    return A, B, C, D, E, F, fac, u


def _numpy_reference(A, B, C, D, E, F, fac, u):
    """∂y/∂[vec A, vec B, vec E, x0, vec C, vec D, vec F] by the recursion, one NumPy step per sample."""
    n, m, p, K = A.shape[0], B.shape[1], C.shape[0], len(fac)
    Ps, Po = n * (n + m + K) + n, p * (n + m + K)
    mask = fac >= 0
    S = np.zeros((n, Ps))
    S[:, Ps - n :] = np.eye(n)
    x = np.zeros(n)
    J = np.zeros((len(u), p, Ps + Po))
    for t in range(len(u)):
        z = np.concatenate([x, u[t]])
        f = np.where(mask, z[np.maximum(fac, 0)], 1.0)
        val = f.prod(axis=1)
        dval = np.zeros((K, n))
        for j in range(fac.shape[1]):
            rest = np.where(mask, f, 1.0)
            rest[:, j] = 1.0
            r = fac[:, j]
            ok = (r >= 0) & (r < n)
            np.add.at(dval, (np.flatnonzero(ok), r[ok]), rest[ok].prod(axis=1))
        J[t, :, :Ps] = (C + F @ dval) @ S
        J[t, :, Ps:] = np.hstack([np.kron(np.eye(p), x), np.kron(np.eye(p), u[t]), np.kron(np.eye(p), val)])
        direct = np.hstack([np.kron(np.eye(n), x), np.kron(np.eye(n), u[t]), np.kron(np.eye(n), val), np.zeros((n, n))])
        S = (A + E @ dval) @ S + direct
        x = A @ x + B @ u[t] + E @ val
    return J


def test_pnlss_jacobian_5k_samples(benchmark, problem):
    benchmark.extra_info["items"] = N
    J = benchmark(lambda: ps.simulate(*problem[:6], problem[6], problem[6], problem[7], jacobian=True)[1])
    ref = _numpy_reference(*problem)
    assert np.max(np.abs(J - ref)) < 1e-10 * np.max(np.abs(ref))


def test_pnlss_jacobian_numpy_reference(benchmark, problem):
    benchmark.extra_info["items"] = N
    benchmark.pedantic(lambda: _numpy_reference(*problem), rounds=1, iterations=1)
