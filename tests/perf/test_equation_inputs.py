"""Speed of the cubic input staging of equation models (:func:`twins.equations.kernel.stage_inputs`), which every
trial of an input effect (a delay, a backlash, a drive limiter) repeats at each evaluation: the Silverbox real
case made 4 288 of them on its 65 062-sample estimation record (profile of 2026-11-29); here 65 062 samples at
4 RK4 sub-steps (9 stage times per sample).

Run: ``make bench`` or
``python -m pytest tests/perf/test_equation_inputs.py --benchmark-enable -p no:cacheprovider -o addopts=""``.
"""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from twins.equations.kernel import stage_inputs

N, SUB = 65_062, 4


@pytest.fixture(scope="module")
def u():
    return np.random.default_rng(0).standard_normal(N)


def _reference(u):
    frac = np.arange(2 * SUB + 1) / (2.0 * SUB)
    k = np.arange(u.size, dtype=float)
    out = CubicSpline(k, u)(np.minimum(k[:, None] + frac[None, :], k[-1]).ravel()).reshape(u.size, frac.size)
    out[-1, :] = u[-1]
    return out


def test_stage_inputs_cubic_65k(benchmark, u):
    benchmark.extra_info["reference"] = "test_stage_inputs_cubicspline_call_reference"
    out = benchmark.pedantic(stage_inputs, args=(u, SUB, "cubic"), rounds=20, iterations=1, warmup_rounds=1)
    assert np.max(np.abs(out - _reference(u))) < 1e-12


def test_stage_inputs_cubicspline_call_reference(benchmark, u):
    """Reference: the same values by CubicSpline.__call__ at every stage time (the code before 2026-11-29)."""
    benchmark.pedantic(_reference, args=(u,), rounds=20, iterations=1, warmup_rounds=1)
