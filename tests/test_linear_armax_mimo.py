"""MIMO ARMAX: a simulated 2×2 system with known polynomial matrices is recovered, and explicit orders, automatic
orders and the saved model behave as for one output."""

import numpy as np
import pytest

from sysid.base import load_model
from sysid.data.record import Record
from sysid.linear.arx import ARMAX

# y_o(t) = Σ_p A[o, p] y_p(t−1) + Σ_j B[o, j] u_j(t−1) + e_o(t) + C[o] e_o(t−1)
A = np.array([[0.6, 0.2], [-0.1, 0.5]])
B = np.array([[1.0, 0.4], [0.3, -0.8]])
C = np.array([0.5, -0.4])


def _simulate(n: int, seed: int, sigma: float = 0.3) -> Record:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 2))
    e = sigma * rng.standard_normal((n, 2))
    y = np.zeros((n, 2))
    for t in range(1, n):
        y[t] = A @ y[t - 1] + B @ u[t - 1] + e[t] + C * e[t - 1]
    return Record(u, y, fs=1.0)


def _truth(model: ARMAX, o: int) -> np.ndarray:
    """The true parameter of each of output o's terms, read from the term's (kind, channel, lag)."""
    s = model.structure_
    out = []
    for term in model.terms_[o]:
        kind, ch, lag = s.regressors[term[0]]
        assert lag == 1
        out.append({"y": A[o, ch], "u": B[o, ch], "e": C[o] if ch == o else np.nan}[kind])
    return np.array(out)


@pytest.mark.parametrize("method", ["pem", "els"])
def test_mimo_armax_recovers_a_2x2_system(method):
    rec = _simulate(20_000, seed=1)
    m = ARMAX(ny=1, nu=1, ne=1, method=method).fit(rec)
    assert m.n_outputs_ == 2 and len(m.terms_) == 2
    for o in range(2):
        truth = _truth(m, o)
        assert truth.size == 5 and np.isfinite(truth).all()  # 2 y lags, 2 u lags, own noise lag only
        th, sd = m.theta_[o], m.stderr_[o]
        assert np.all(np.abs(th - truth) < 4 * sd + 1e-12), (o, th, truth, sd)
        assert np.all(np.abs(th - truth) < 0.03)


def test_mimo_armax_one_step_residuals_are_the_innovations():
    """With the true system's noise, the one-step prediction error is white: close to the simulated e."""
    rec = _simulate(20_000, seed=2, sigma=0.3)
    m = ARMAX(ny=1, nu=1, ne=1).fit(rec)
    res = (rec.y - m.predict(rec, 1))[200:]
    assert np.allclose(res.std(axis=0), 0.3, rtol=0.03)
    for o in range(2):
        r = res[:, o] - res[:, o].mean()
        assert abs(np.dot(r[1:], r[:-1]) / np.dot(r, r)) < 0.03


def test_mimo_armax_free_run_and_saved_model(tmp_path):
    est, val = _simulate(10_000, seed=3), _simulate(4_000, seed=4)
    m = ARMAX(ny=1, nu=1, ne=1).fit(est)
    yh = m.predict(val, None)
    assert yh.shape == (len(val), 2)
    m2 = load_model(m.save(tmp_path / "armax2.json"))
    np.testing.assert_array_equal(m2.predict(val, 3), m.predict(val, 3))


def test_mimo_armax_chooses_orders_when_none_given():
    rec = _simulate(6_000, seed=5)
    m = ARMAX(max_order=4).fit(rec)
    assert m.chosen_orders_["ne"] == 2 and m.chosen_orders_["ny"] == m.ny >= 1


def test_identify_cli_fits_a_mimo_armax_from_csv_columns(tmp_path, capsys):
    import json

    from benchmarks.cli import main

    rec = _simulate(4_000, seed=6)
    path = tmp_path / "mimo.csv"
    np.savetxt(
        path, np.c_[np.arange(len(rec)) / 100.0, rec.u, rec.y], delimiter=",", header="t,f1,f2,a1,a2", comments=""
    )
    assert (
        main(
            [
                "identify",
                "armax",
                "--est",
                str(path),
                "--u-col",
                "f1,f2",
                "--y-col",
                "a1,a2",
                "--set",
                "ny=1,nu=1,ne=1",
                "--json",
                "-o",
                str(tmp_path / "m.json"),
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["n_parameters"] == 10
    m = load_model(tmp_path / "m.json")
    for o in range(2):
        assert np.all(np.abs(m.theta_[o] - _truth(m, o)) < 5 * m.stderr_[o])
