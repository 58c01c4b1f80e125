"""narx-poly-sim: simulation-error refinement of a polynomial NARX recovers a known system's parameters from
output-error data, where the equation-error least squares (narx-poly's start) are biased; the sensitivity
Jacobian equals finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from sysid.base import load_model
from sysid.data.record import Record
from sysid.polynomial.polysim import NARXPolySim, simulate_sensitivity

TRUE = {"y(k-1)": 1.2, "y(k-2)": -0.5, "u(k-1)": 0.5, "u(k-1)^2": 0.2, "y(k-1)*u(k-1)": -0.1}


def plant(u: np.ndarray) -> np.ndarray:
    y = np.zeros(u.size)
    for t in range(2, u.size):
        y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + 0.5 * u[t - 1] + 0.2 * u[t - 1] ** 2 - 0.1 * y[t - 1] * u[t - 1]
    return y


@pytest.fixture(scope="module")
def output_error_fit():
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, 4000)
    y0 = plant(u)
    y = y0 + 0.1 * np.std(y0) * rng.standard_normal(u.size)  # white measurement noise: output error
    model = NARXPolySim(ny=2, nu=1, degree=2, max_terms=5, criterion="err", rho_p=1e-12, constant=False)
    return model.fit(Record(u=u, y=y, fs=1.0))


def test_recovers_true_parameters_where_least_squares_is_biased(output_error_fit):
    m = output_error_fit
    table = {row["term"]: row for row in m.term_table()}
    assert set(table) == set(TRUE)
    names = [row["term"] for row in m.term_table()]
    ls = dict(zip(names, m.theta_ls_[0]))
    for name, value in TRUE.items():
        assert abs(table[name]["parameter"] - value) < 4 * table[name]["stderr"] + 1e-3, name
    # the equation-error estimate of the autoregressive part is off by many standard errors of the refined one
    assert abs(ls["y(k-1)"] - 1.2) > 10 * table["y(k-1)"]["stderr"]
    assert abs(ls["y(k-2)"] + 0.5) > 10 * table["y(k-2)"]["stderr"]
    # the refined simulation error is the noise level (0.1 SD of y0 ≈ 0.1 SD of y), below the LS model's
    assert m.refine_info_["rms_sim"] < m.refine_info_["rms_ls"]
    assert m.refine_info_["rms_sim"] < 0.105


def test_sensitivity_equals_finite_differences(output_error_fit):
    m = output_error_fit
    rng = np.random.default_rng(5)
    u = rng.uniform(-1, 1, 300)
    y = plant(u)
    theta = np.concatenate(m.theta_)
    yh, S, div = simulate_sensitivity(m.structure_, m.terms_, theta, u, y)
    assert div == -1
    for i in range(theta.size):
        h = 1e-6
        tp, tm = theta.copy(), theta.copy()
        tp[i] += h
        tm[i] -= h
        fd = (
            simulate_sensitivity(m.structure_, m.terms_, tp, u, y, jacobian=False)[0]
            - simulate_sensitivity(m.structure_, m.terms_, tm, u, y, jacobian=False)[0]
        ) / (2 * h)
        np.testing.assert_allclose(S[:, 0, i], fd[:, 0], rtol=1e-5, atol=1e-7 * np.max(np.abs(fd)))
    # the compiled free run of the identifier is the same simulation
    np.testing.assert_allclose(m.predict(Record(u=u, y=y, fs=1.0), None), yh[:, 0], rtol=1e-12, atol=1e-12)


def test_save_load_and_no_refinement(output_error_fit, tmp_path):
    m = output_error_fit
    rec = Record(u=np.linspace(-1, 1, 200), y=plant(np.linspace(-1, 1, 200)), fs=1.0)
    back = load_model(m.save(tmp_path / "m.json"))
    np.testing.assert_array_equal(back.predict(rec, None), m.predict(rec, None))
    np.testing.assert_array_equal(back.theta_ls_[0], m.theta_ls_[0])
    # max_nfev=0 is narx-poly: the least-squares parameters
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, 4000)
    y0 = plant(u)
    y = y0 + 0.1 * np.std(y0) * rng.standard_normal(u.size)
    m0 = NARXPolySim(ny=2, nu=1, degree=2, max_terms=5, criterion="err", rho_p=1e-12, constant=False, max_nfev=0)
    m0.fit(Record(u=u, y=y, fs=1.0))
    np.testing.assert_array_equal(m0.theta_[0], m.theta_ls_[0])
