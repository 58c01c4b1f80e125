"""ARX (least squares) and ARMAX (prediction-error method, extended least squares)."""

import numpy as np
import pytest
from scipy.signal import lfilter

from sysid.base import load_model
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.linear.arx import ARMAX, ARX

A = [1.0, -1.5, 0.7]
B = [1.0, 0.5]  # applied to u(t - nk)
C = [1.0, 0.6, 0.2]


def _armax(n=6000, seed=1, nk=1, sigma=0.3, c=C):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    e = sigma * rng.standard_normal(n)
    b = np.concatenate([np.zeros(nk), B])
    y = lfilter(b, A, u) + lfilter(c, A, e)
    return Record(u, y, fs=1.0)


@pytest.mark.parametrize("nk", [0, 1, 3])
def test_arx_noise_free_exact(nk):
    rng = np.random.default_rng(0)
    u = rng.standard_normal(500)
    y = lfilter(np.concatenate([np.zeros(nk), B]), A, u)
    m = ARX(ny=2, nu=2, nk=nk).fit(Record(u, y, fs=1.0))
    p = m.polynomials()
    np.testing.assert_allclose(p["A"], A, atol=1e-10)
    np.testing.assert_allclose(p["B"], B, atol=1e-10)
    np.testing.assert_allclose(m.predict(Record(u, y, fs=1.0), None), y, atol=1e-9)


def test_arx_white_equation_error_within_standard_errors():
    rng = np.random.default_rng(4)
    n = 5000
    u = rng.standard_normal(n)
    y = lfilter([0.0] + B, A, u) + lfilter([1.0], A, 0.2 * rng.standard_normal(n))
    m = ARX(ny=2, nu=2).fit(Record(u, y, fs=1.0))
    p = m.polynomials()
    assert np.all(np.abs(p["A"][1:] - np.array(A[1:])) < 3 * p["A_stderr"][1:])
    assert np.all(np.abs(p["B"] - np.array(B)) < 3 * p["B_stderr"])


@pytest.mark.parametrize("method", ["pem", "els"])
def test_armax_recovers_a_b_c_within_standard_errors(method):
    rec = _armax()
    m = ARMAX(ny=2, nu=2, ne=2, method=method).fit(rec)
    p = m.polynomials()
    for key, true in (("A", A), ("B", B), ("C", C)):
        est, se = np.atleast_1d(p[key]), np.atleast_1d(p[key + "_stderr"])
        sl = slice(1, None) if key in ("A", "C") else slice(None)
        assert np.all(se[sl] > 0)
        z = np.abs(est[sl] - np.array(true)[sl]) / se[sl]
        assert np.all(z < 3.0), (key, est, se)


def test_armax_arx_would_be_biased():
    # The reason for ARMAX: least squares ARX is biased under coloured noise (its A lies many SE away).
    rec = _armax(sigma=0.6, c=[1.0, 0.9, 0.3])
    p = ARX(ny=2, nu=2).fit(rec).polynomials()
    assert np.max(np.abs(p["A"][1:] - np.array(A[1:])) / p["A_stderr"][1:]) > 5
    q = ARMAX(ny=2, nu=2, ne=2).fit(rec).polynomials()
    assert np.max(np.abs(q["A"][1:] - np.array(A[1:])) / q["A_stderr"][1:]) < 3


def test_armax_prediction_modes_and_round_trip(tmp_path):
    rec = _armax(2000, seed=5)
    m = ARMAX(ny=2, nu=2, ne=2).fit(rec)
    y1 = m.predict(rec, 1)
    # one-step residual of ARMAX = C^{-1}(A y - B u): compare with the filter formula
    p = m.polynomials()
    L = m.max_lag_
    v = lfilter(p["A"], [1.0], rec.y) - lfilter([0.0] + list(p["B"]), [1.0], rec.u)
    v[:L] = 0.0
    e = lfilter([1.0], p["C"], v)
    np.testing.assert_allclose((rec.y - y1)[L:], e[L:], atol=1e-9)
    np.testing.assert_array_equal(m.predict(rec, len(rec)), m.predict(rec, None))
    m2 = load_model(m.save(tmp_path / "armax.json"))
    for h in (1, 5, None):
        np.testing.assert_array_equal(m2.predict(rec, h), m.predict(rec, h))
    a2 = load_model(ARX().fit(rec).save(tmp_path / "arx.json"))
    np.testing.assert_array_equal(a2.predict(rec, 3), ARX().fit(rec).predict(rec, 3))


def test_linear_bad_input():
    rec = _armax(200)
    with pytest.raises(DataError, match="too few"):
        ARX(ny=8, nu=8).fit(rec[:8])
    with pytest.raises(DataError, match="constant"):
        ARMAX(ny=2, nu=2, ne=2).fit(Record(np.zeros(200), rec.y, fs=1.0))
    with pytest.raises(ConfigError, match="method"):
        ARMAX(method="magic").fit(rec)


@pytest.mark.parametrize("method", ["pem", "els"])
def test_armax_is_scale_invariant(method):
    """u in kN-like units (×1e3) and y in mm-like units (×1e-3): A and C unchanged, B scaled by 1e-6, and the
    ELS convergence test is relative (no absolute floor that B ~ 1e-6 would fall under)."""
    rec = _armax(3000)
    a = ARMAX(ny=2, nu=2, ne=2, method=method).fit(rec).polynomials()
    b = ARMAX(ny=2, nu=2, ne=2, method=method).fit(Record(rec.u * 1e3, rec.y * 1e-3, fs=1.0)).polynomials()
    np.testing.assert_allclose(b["A"], a["A"], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(b["C"], a["C"], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(b["B"], np.asarray(a["B"]) * 1e-6, rtol=1e-6)
