"""narx-poly-sim: simulation-error refinement of a polynomial NARX recovers a known system's parameters from
output-error data, where the equation-error least squares (narx-poly's start) are biased; the sensitivity
Jacobian equals finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from sysid.base import load_model
from sysid.data.record import Record
from sysid.errors import ConfigError
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


def feedback_plant(u: np.ndarray) -> np.ndarray:
    """A nonlinear feedback of the output: y(k) = 1.5 y(k-1) − 0.7 y(k-2) + 0.5 u(k-1) + 0.25 u(k-2) − 0.3 y(k-1)³
    (a sampled lightly damped oscillator whose restoring force stiffens with its displacement)."""
    y = np.zeros(u.size)
    for t in range(2, u.size):
        y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + 0.5 * u[t - 1] + 0.25 * u[t - 2] - 0.3 * y[t - 1] ** 3
    return y


def test_monomials_of_the_output_alone_keep_the_input_linear_and_recover_a_feedback_system():
    """``monomials_of="y"``: no candidate multiplies an input regressor (degree 3 over ny = nu = 2: 1 + 4 linear +
    7 products of y(k-1), y(k-2) = 12 candidates against 35), and from output-error data the refinement finds the
    true terms and parameters within 4 standard errors; the model then follows an input twice as large (beyond
    the estimation range) to 2 % of its spread, as the true structure must."""
    rng = np.random.default_rng(3)
    u = 0.3 * rng.uniform(-1, 1, 4000)
    y0 = feedback_plant(u)
    y = y0 + 0.02 * np.std(y0) * rng.standard_normal(u.size)
    model = NARXPolySim(ny=2, nu=2, degree=3, max_terms=None, criterion="bic", monomials_of="y", max_nfev=200)
    model.fit(Record(u=u, y=y, fs=1.0))
    assert len(model.structure_.terms) == 12
    assert len(NARXPolySim(ny=2, nu=2, degree=3)._structure(1, 1, 0, 3, True).terms) == 35
    table = {row["term"]: row for row in model.term_table()}
    assert not any("u" in name and ("*" in name or "^" in name) for name in table)
    want = {"y(k-1)": 1.5, "y(k-2)": -0.7, "u(k-1)": 0.5, "u(k-2)": 0.25, "y(k-1)^3": -0.3}
    assert set(want) <= set(table)
    for name, value in want.items():
        assert abs(table[name]["parameter"] - value) < 4 * table[name]["stderr"] + 1e-3, name
    u2 = 0.6 * np.random.default_rng(4).uniform(-1, 1, 2000)
    y2 = feedback_plant(u2)
    assert np.max(np.abs(y2)) > 1.2 * np.max(np.abs(y0))  # the test leaves the estimation range
    err = model.predict(Record(u=u2, y=y2, fs=1.0), None) - y2
    assert np.sqrt(np.mean(err**2)) < 0.02 * np.std(y2)


def test_a_model_of_output_monomials_is_built_from_set_strings_and_survives_save_and_load(tmp_path):
    """``--set monomials_of=y`` reaches the model, and a saved model keeps its structure (same free run)."""
    u = 0.3 * np.random.default_rng(3).uniform(-1, 1, 1000)
    rec = Record(u=u, y=feedback_plant(u), fs=1.0)
    given = {"ny": "2", "nu": "2", "degree": "3", "max_terms": "20", "monomials_of": "y", "max_nfev": "20"}
    model = NARXPolySim.from_assignments(given).fit(rec)
    back = load_model(model.save(tmp_path / "m.json"))
    assert back.get_params()["monomials_of"] == "y"
    assert len(model.structure_.terms) == 12
    assert [r["term"] for r in back.term_table()] == [r["term"] for r in model.term_table()]
    np.testing.assert_array_equal(back.predict(rec, None), model.predict(rec, None))


def test_monomials_of_rejects_an_unknown_choice():
    with pytest.raises(ConfigError, match="monomials_of"):
        NARXPolySim(monomials_of="u").fit(Record(u=np.zeros(100), y=np.zeros(100), fs=1.0))


def test_a_diverging_start_with_many_terms_is_refined_on_enough_samples():
    """The continuation in the data length starts on at least one sample more than there are parameters: a
    least-squares start that diverges within its first few samples is refined, not refused (it used to raise
    scipy's 'fewer residuals than variables')."""
    from tests._polysys import duffing

    u = 0.8 * np.random.default_rng(1).standard_normal(3000)
    model = NARXPolySim(ny=3, nu=4, degree=3, max_terms=None, max_nfev=50).fit(Record(u=u, y=duffing(u), fs=2.0))
    assert model.refine_info_["start_diverged_at"] >= 0
    assert min(model.refine_info_["continuation_lengths"]) > model.n_parameters_
