"""FROLS / polynomial NARX-NARMAX: exact recovery, MIMO, separate experiments, zero-start columns, prediction
modes, divergence, persistence, bad input, and a cross-check against SysIdentPy."""

import warnings

import numpy as np
import pytest

from sysid.base import load_model
from sysid.data.record import Record
from sysid.errors import DataError, DivergenceWarning, InputError
from sysid.evaluation.residuals import correlation_tests
from sysid.polynomial import frols as fr
from sysid.polynomial.narmax import NARMAXPoly, NARXPoly
from tests._polysys import TRUE_TERMS, narmax_record, narx_record, table


@pytest.mark.parametrize("criterion", ["bic", "aic", "fpe", "lilc", "err"])
def test_noise_free_narx_exact_recovery(criterion):
    rec = narx_record()
    m = NARXPoly(ny=2, nu=2, degree=2, criterion=criterion, rho_p=1e-8).fit(rec)
    got = table(m)
    assert set(got) == set(TRUE_TERMS)
    for k, v in TRUE_TERMS.items():
        assert abs(got[k] - v) < 1e-8
    assert m.n_parameters_ == 4
    # ERR of the selected terms sums to 1 for an exact model (eq. 2-21)
    assert abs(sum(r["err"] for r in m.term_table()) - 1.0) < 1e-9


def test_degree3_larger_lags_exact():
    m = NARXPoly(ny=4, nu=4, degree=3).fit(_degree3_record())
    want = {"y(k-1)": 0.4, "y(k-3)": -0.2, "u(k-2)": 0.7, "u(k-1)*u(k-3)^2": 0.15, "1": 0.05}
    got = table(m)
    assert set(got) == set(want)
    assert max(abs(got[k] - v) for k, v in want.items()) < 1e-8


def test_candidate_count_matches_formula():
    # M = (n + l)! / (n! l!) with n = ny + nu = 20, l = 2  -> 231 (constant included)
    regs = fr.make_regressors(10, 10)
    assert len(fr.candidate_terms(len(regs), 2)) == 231
    assert len(fr.candidate_terms(len(fr.make_regressors(2, 2, 3)), 3)) == 120


def test_gram_matrix_equals_dense_product_across_chunks_and_records():
    recs = [narx_record(700, seed=1), narx_record(500, seed=2)]
    s = fr.Structure(fr.make_regressors(3, 2), fr.candidate_terms(5, 2))
    G, n = fr.gram_matrix(recs, s, chunk=97)
    rows = []
    for r in recs:
        for k in range(3, len(r)):
            x = [r.y[k - 1], r.y[k - 2], r.y[k - 3], r.u[k - 1], r.u[k - 2]]
            rows.append([np.prod([x[i] for i in t]) for t in s.terms] + [r.y[k]])
    P = np.array(rows)
    assert n == P.shape[0] == 697 + 497
    np.testing.assert_allclose(G, P.T @ P, rtol=1e-12, atol=1e-9)


def test_mimo_one_model_per_output_shared_regressors():
    rng = np.random.default_rng(2)
    n = 2000
    u = rng.uniform(-1, 1, (n, 2))
    y = np.zeros((n, 2))
    for k in range(2, n):
        y[k, 0] = 0.5 * y[k - 1, 0] + 0.8 * u[k - 1, 0] + 0.2 * y[k - 1, 1] * u[k - 1, 1]
        y[k, 1] = -0.3 * y[k - 2, 1] + 0.6 * u[k - 1, 1] - 0.25 * u[k - 1, 0] ** 2
    rec = Record(u, y, fs=1.0)
    m = NARXPoly(ny=2, nu=2, degree=2).fit(rec)
    assert table(m, 0).keys() == {"y1(k-1)", "u1(k-1)", "y2(k-1)*u2(k-1)"}
    assert table(m, 1).keys() == {"y2(k-2)", "u2(k-1)", "u1(k-1)^2"}
    assert abs(table(m, 0)["y2(k-1)*u2(k-1)"] - 0.2) < 1e-8
    assert abs(table(m, 1)["u1(k-1)^2"] + 0.25) < 1e-8
    yfr = m.predict(rec, None)
    assert yfr.shape == y.shape
    np.testing.assert_allclose(yfr, y, atol=1e-8)


def test_separate_experiments_no_regressor_across_boundary():
    a, b = narx_record(800, seed=11), narx_record(800, seed=12)
    m = NARXPoly(ny=2, nu=2, degree=2).fit([a, b])
    got = table(m)
    assert set(got) == set(TRUE_TERMS) and max(abs(got[k] - v) for k, v in TRUE_TERMS.items()) < 1e-8
    # Control: gluing the two experiments into one record creates rows that mix them; the fit is then not exact.
    glued = Record(np.concatenate([a.u, b.u]), np.concatenate([a.y, b.y]), fs=1.0)
    m2 = NARXPoly(ny=2, nu=2, degree=2, criterion="err", rho_p=1e-12, max_terms=4).fit(glued)
    g2 = table(m2)
    assert set(g2) != set(TRUE_TERMS) or max(abs(g2[k] - v) for k, v in TRUE_TERMS.items()) > 1e-6


def test_zero_start_candidate_column_does_not_change_selection():
    ref = NARXPoly(ny=2, nu=2, degree=2).fit(narx_record(1500, seed=4))
    rec = narx_record(1500, seed=4, lead_zeros=300)  # data recorded from rest: every u column starts with zeros
    assert np.all(rec.u[:300] == 0.0)
    m = NARXPoly(ny=2, nu=2, degree=2).fit(rec)
    assert [r["term"] for r in m.term_table()] == [r["term"] for r in ref.term_table()]
    got = table(m)
    assert max(abs(got[k] - v) for k, v in TRUE_TERMS.items()) < 1e-8


@pytest.mark.parametrize("cls", [NARXPoly, NARMAXPoly])
def test_k_step_equals_one_step_and_free_run(cls):
    from sysid.polynomial import simulate as sim

    rec = narmax_record(600, seed=7)
    m = cls(ny=2, nu=2, degree=2, criterion="bic").fit(rec)
    y1 = m.predict(rec, 1)
    # the k-step machinery itself at k = 1 (predict(horizon=1) takes the one-step path)
    yk1, bad = sim.k_step(m.compiled(), rec.u.reshape(-1, 1), rec.y.reshape(-1, 1), 1)
    assert bad == -1
    np.testing.assert_array_equal(yk1[:, 0], y1)
    yk = m.predict(rec, len(rec))
    yf = m.predict(rec, None)
    np.testing.assert_array_equal(yk, yf)
    assert np.array_equal(yf[:2], rec.y[:2]) and np.array_equal(y1[:2], rec.y[:2])


def _naive_k_step(m, rec, k):
    """Independent reference: restart a free run from measured data at origin max(t-k+1, L) for every t."""
    L = m.max_lag_
    out = rec.y.copy()
    rows = m.term_table()
    for t in range(L, len(rec)):
        s = max(t - k + 1, L)
        y = rec.y.copy()
        for j in range(s, t + 1):
            env = {"y": lambda lag, j=j: y[j - lag], "u": lambda lag, j=j: rec.u[j - lag]}  # noqa: B023 (this t's y)
            acc = 0.0
            for r in rows:
                v = r["parameter"]
                if r["term"] != "1":
                    for f in r["term"].split("*"):
                        name, _, rest = f.partition("(k-")
                        lag, _, p = rest.partition(")")
                        v *= env[name](int(lag)) ** (int(p[1:]) if p else 1)
                acc += v
            y[j] = acc
        out[t] = y[t]
    return out


@pytest.mark.parametrize("k", [2, 3, 7])
def test_k_step_matches_naive_restart(k):
    rec = narx_record(150, seed=8, noise=0.02)
    m = NARXPoly(ny=2, nu=2, degree=2, criterion="aic").fit(rec)
    np.testing.assert_allclose(m.predict(rec, k), _naive_k_step(m, rec, k), rtol=1e-12, atol=1e-12)


def test_free_run_divergence_is_reported_not_raised():
    rng = np.random.default_rng(0)
    n = 400
    u = rng.uniform(-0.3, 0.3, n)
    y = np.zeros(n)
    for k in range(1, n):  # quadratic feedback: stable for small inputs, unbounded for large ones
        y[k] = 0.5 * y[k - 1] + u[k - 1] + 0.3 * y[k - 1] ** 2
    assert np.abs(y).max() < 1.0
    m = NARXPoly(ny=1, nu=1, degree=2).fit(Record(u, y, fs=1.0))
    assert set(table(m)) == {"y(k-1)", "u(k-1)", "y(k-1)^2"}
    big = Record(5.0 * np.ones(n) + u, np.zeros(n), fs=1.0)  # drive far outside the estimation range
    with pytest.warns(DivergenceWarning):
        yf = m.predict(big, None)
    assert m.diverged_at_ is not None
    assert np.isnan(yf[m.diverged_at_ :]).all() and np.isfinite(yf[: m.diverged_at_]).all()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m.predict(Record(u, y, fs=1.0), None)
    assert m.diverged_at_ is None


@pytest.mark.parametrize(
    "cls,kw", [(NARXPoly, dict(ny=2, nu=2, degree=2)), (NARMAXPoly, dict(ny=2, nu=2, ne=2, degree=2))]
)
def test_save_load_round_trip(tmp_path, cls, kw):
    rec = narmax_record(1200)
    m = cls(**kw).fit(rec)
    path = m.save(tmp_path / "m.json")
    m2 = load_model(path)
    assert type(m2) is cls and m2.get_params() == m.get_params()
    for h in (1, 4, None):
        np.testing.assert_array_equal(m2.predict(rec, h), m.predict(rec, h))


def test_bad_input_is_refused_clearly():
    rec = narx_record(100)
    with pytest.raises(DataError, match="too few"):
        NARXPoly(ny=10, nu=10, degree=2).fit(rec[:30])
    with pytest.raises(DataError, match="too few for the lags"):
        NARXPoly(ny=10, nu=2).fit(rec[:8])
    with pytest.raises(DataError, match="constant"):
        NARXPoly().fit(Record(np.ones(100), rec.y, fs=1.0))
    with pytest.raises(InputError, match="NaN"):
        Record(np.where(np.arange(100) == 5, np.nan, rec.u), rec.y, fs=1.0)
    bad = narx_record(100)
    bad.u[7] = np.nan  # mutated after construction: fit still refuses it
    with pytest.raises(DataError, match="non-finite"):
        NARXPoly().fit(bad)
    with pytest.raises(InputError, match="criterion"):
        NARXPoly(criterion="xyz").fit(rec)


def test_narmax_els_recovers_noise_term_and_whitens_residuals():
    rec = narmax_record()
    narx = NARXPoly(ny=2, nu=2, degree=2).fit(rec)
    e_narx = rec.y - narx.predict(rec, 1)
    assert not correlation_tests(e_narx[2:], rec.u[2:])["passed"]
    r_ee = correlation_tests(e_narx[2:], rec.u[2:])["tests"][0]
    assert r_ee["name"] == "r_ee" and 1 in r_ee["failing_lags"]

    for crit, kw in (("err", dict(rho_p=1e-2, rho_n=1e-4)), ("bic", {})):
        m = NARMAXPoly(ny=2, nu=2, ne=2, degree=2, criterion=crit, **kw).fit(rec)
        rows = {r["term"]: r for r in m.term_table()}
        assert "e(k-1)" in rows
        assert abs(rows["e(k-1)"]["parameter"] - 0.8) < 3 * rows["e(k-1)"]["stderr"]
        for k, v in {"y(k-1)": 0.5, "u(k-1)": 1.0, "u(k-1)^2": -0.3, "y(k-1)*u(k-1)": 0.1}.items():
            assert abs(rows[k]["parameter"] - v) < 3.5 * rows[k]["stderr"]
        e = rec.y - m.predict(rec, 1)
        assert correlation_tests(e[2:], rec.u[2:])["passed"], crit
        assert np.std(e[2:]) < 0.9 * np.std(e_narx[2:])


def _degree3_record():
    rng = np.random.default_rng(5)
    n = 3000
    u = rng.uniform(-1, 1, n)
    y = np.zeros(n)
    for k in range(4, n):
        y[k] = 0.4 * y[k - 1] - 0.2 * y[k - 3] + 0.7 * u[k - 2] + 0.15 * u[k - 1] * u[k - 3] ** 2 + 0.05
    return Record(u, y, fs=1.0)


@pytest.mark.parametrize("case", ["degree2-lags2", "degree3-lags4-constant"])
def test_sysidentpy_cross_check_terms_and_parameters(case):
    pytest.importorskip("sysidentpy", reason="SysIdentPy is not installed: cross-check skipped")
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS
    from sysidentpy.parameter_estimation import LeastSquares

    if case == "degree2-lags2":
        rec, lags, degree, true = narx_record(1000, seed=21), 2, 2, TRUE_TERMS
    else:
        rec, lags, degree = _degree3_record(), 4, 3
        true = {"y(k-1)": 0.4, "y(k-3)": -0.2, "u(k-2)": 0.7, "u(k-1)*u(k-3)^2": 0.15, "1": 0.05}
    n_terms = len(true)
    ref = FROLS(
        order_selection=False,
        n_terms=n_terms,
        ylag=lags,
        xlag=lags,
        estimator=LeastSquares(),
        basis_function=Polynomial(degree=degree),
        model_type="NARMAX",
    )
    ref.fit(X=rec.u.reshape(-1, 1), y=rec.y.reshape(-1, 1))

    def code_name(code):  # SysIdentPy's regressor codes: 1000 + j = y(k-j), 2000 + j = x1(k-j), 0 = none
        facs = []
        for c in sorted((int(c) for c in code if c != 0), key=lambda c: (c // 1000 != 1, c)):
            facs.append(("y" if c // 1000 == 1 else "u") + f"(k-{c % 1000})")
        out = []
        for f in dict.fromkeys(facs):
            n = facs.count(f)
            out.append(f if n == 1 else f"{f}^{n}")
        return "*".join(out) or "1"

    ref_terms = [code_name(c) for c in ref.final_model]
    ref_theta = dict(zip(ref_terms, ref.theta.ravel()))
    m = NARXPoly(ny=lags, nu=lags, degree=degree, criterion="err", rho_p=1e-10, max_terms=n_terms).fit(rec)
    ours = m.term_table()
    assert [r["term"] for r in ours] == ref_terms  # same terms, same order of selection
    for r in ours:
        assert abs(r["parameter"] - ref_theta[r["term"]]) <= 1e-6 * abs(ref_theta[r["term"]])
    np.testing.assert_allclose([r["err"] for r in ours], np.asarray(ref.err[:n_terms]).ravel(), rtol=1e-6)
    assert set(ref_terms) == set(true)
    # and our default (BIC, no term count given) finds exactly the true model too
    assert set(table(NARXPoly(ny=lags, nu=lags, degree=degree).fit(rec))) == set(true)


def test_incremental_order_selection_equals_refits():
    """The criterion of every model size, from the single FROLS pass, equals N ln(SSR_k/N) + k ln N of a
    separate least-squares refit (numpy lstsq) on the first k selected terms."""
    rec = narx_record(800, seed=9, noise=0.05)
    m = NARXPoly(ny=2, nu=2, degree=2, criterion="bic", max_terms=8).fit(rec)
    s = m.structure_
    G, n = fr.gram_matrix([rec], s)
    res = fr.frols(G, len(s.terms), 0, n, "bic", max_terms=8)
    X = np.vstack([x for x, _ in fr.lagged_chunks([rec], s)])
    P = fr.term_columns(X, s.terms)
    y = rec.y[2:]
    for k in range(1, 9):
        A = P[:, res.scored[:k]]
        ssr = np.sum((y - A @ np.linalg.lstsq(A, y, rcond=None)[0]) ** 2)
        assert res.criterion_values[k - 1] == pytest.approx(n * np.log(ssr / n) + k * np.log(n), rel=1e-9)
    assert m.n_parameters_ == int(np.argmin(res.criterion_values)) + 1


def test_bic_default_finds_true_structure_aic_overfits():
    sizes = {"bic": [], "aic": []}
    for seed in range(4):
        rec = narx_record(5000, seed=seed, noise=0.02)
        for c in sizes:
            m = NARXPoly(ny=2, nu=2, degree=2, criterion=c).fit(rec)
            sizes[c].append(m.n_parameters_)
            if c == "bic":
                assert set(table(m)) == set(TRUE_TERMS)
    assert NARXPoly().criterion == "bic"
    assert sum(sizes["aic"]) > sum(sizes["bic"])


def test_narmax_k_step_limits():
    rec = narmax_record(800)
    m = NARMAXPoly(ny=2, nu=2, ne=2, degree=2).fit(rec)
    y1 = m.predict(rec, 1)
    # one-step residuals are the recursion e(t) = y(t) - ŷ(t|t-1) used by the noise terms
    np.testing.assert_array_equal(m.predict(rec, 1), y1)
    np.testing.assert_array_equal(m.predict(rec, len(rec)), m.predict(rec, None))
    y3 = m.predict(rec, 3)
    assert np.std((rec.y - y1)[2:]) < np.std((rec.y - y3)[2:]) <= np.std((rec.y - m.predict(rec, None))[2:]) * 1.01


def test_large_offset_keeps_precision_and_matches_sysidentpy():
    """Output offset 1000× its variation: the centred Gram keeps the orthogonalisation exact (parameters to
    1e-9 relative) and the selection equals SysIdentPy's Householder FROLS term for term."""
    rng = np.random.default_rng(0)
    n, off = 2000, 1e3
    u = rng.uniform(-1, 1, n)
    y = np.full(n, off)
    for k in range(2, n):
        y[k] = 0.5 * y[k - 1] + 0.9 * u[k - 2] - 0.3 * u[k - 1] ** 2 + 0.5 * off
    rec = Record(u, y, fs=1.0)
    G, N = fr.gram_matrix([rec], NARXPoly(ny=2, nu=2).fit(rec).structure_)
    X = np.vstack([x for x, _ in fr.lagged_chunks([rec], NARXPoly(ny=2, nu=2).fit(rec).structure_)])
    P = np.c_[fr.term_columns(X, fr.candidate_terms(4, 2)), y[2:]]
    Pc = P - P.mean(axis=0)
    np.testing.assert_allclose(G.centred, Pc.T @ Pc, rtol=1e-9, atol=1e-9 * np.abs(Pc.T @ Pc).max())
    m = NARXPoly(ny=2, nu=2, degree=2, criterion="err", rho_p=1e-14, max_terms=5).fit(rec)
    got = table(m)
    for k, v in {"1": 0.5 * off, "y(k-1)": 0.5, "u(k-2)": 0.9, "u(k-1)^2": -0.3}.items():
        assert abs(got[k] - v) <= 1e-9 * abs(v)
    pytest.importorskip("sysidentpy", reason="SysIdentPy is not installed: cross-check skipped")
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS
    from sysidentpy.parameter_estimation import LeastSquares

    ref = FROLS(
        order_selection=False, n_terms=5, ylag=2, xlag=2, estimator=LeastSquares(), basis_function=Polynomial(degree=2)
    )
    ref.fit(X=u[:, None], y=y[:, None])
    codes = {
        (0, 0): "1",
        (2002, 1001): "y(k-1)*u(k-2)",
        (1001, 0): "y(k-1)",
        (2001, 2001): "u(k-1)^2",
        (2002, 0): "u(k-2)",
    }
    assert [r["term"] for r in m.term_table()] == [codes[tuple(int(c) for c in row)] for row in ref.final_model]
    np.testing.assert_allclose(
        [r["err"] for r in m.term_table()], np.asarray(ref.err[:5]).ravel(), rtol=1e-5, atol=1e-15
    )


def test_mimo_narmax_noise_term_per_output():
    rng = np.random.default_rng(2)
    n = 4000
    u = rng.uniform(-1, 1, (n, 2))
    e = 0.05 * rng.standard_normal((n, 2))
    y = np.zeros((n, 2))
    for k in range(2, n):
        y[k, 0] = 0.5 * y[k - 1, 0] + 0.8 * u[k - 1, 0] + 0.2 * y[k - 1, 1] * u[k - 1, 1] + 0.7 * e[k - 1, 0] + e[k, 0]
        y[k, 1] = -0.3 * y[k - 2, 1] + 0.6 * u[k - 1, 1] - 0.25 * u[k - 1, 0] ** 2 + e[k, 1]
    rec = Record(u, y, fs=1.0)
    m = NARMAXPoly(ny=2, nu=2, ne=1, degree=2).fit(rec)
    rows = {(r["output"], r["term"]): r for r in m.term_table()}
    assert {t for o, t in rows if o == 0} == {"y1(k-1)", "u1(k-1)", "y2(k-1)*u2(k-1)", "e1(k-1)"}
    assert {t for o, t in rows if o == 1} == {"y2(k-2)", "u2(k-1)", "u1(k-1)^2"}
    r = rows[(0, "e1(k-1)")]
    assert abs(r["parameter"] - 0.7) < 3 * r["stderr"]
    for h in (1, 3, None):
        assert m.predict(rec, h).shape == (n, 2)


def test_narmax_long_record_unstable_early_noise_model_is_survived():
    """At N = 1e5 the first ELS iteration (on the biased residuals of the process-only fit) proposes a noise
    model whose one-step recursion is unstable (MA coefficient > 1); ELS must fall back to the bounded residual
    and still converge to the true structure."""
    rec = narmax_record(100_000, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        m = NARMAXPoly(ny=2, nu=2, ne=3, degree=2).fit(rec)
    assert m.els_converged_
    rows = {r["term"]: r for r in m.term_table()}
    assert set(rows) == {"u(k-1)", "y(k-1)", "u(k-1)^2", "y(k-1)*u(k-1)", "e(k-1)"}
    assert abs(rows["e(k-1)"]["parameter"] - 0.8) < 3 * rows["e(k-1)"]["stderr"]


# ------------------------------------------------------------------ benchmark defects (scale, ELS stability)
def _cascaded_tanks_est():
    """The Cascaded Tanks estimation record (1024 samples, vendored in benchmarks/data): the real-data case on
    which ELS with > 2 iterations proposed noise models whose residual recursion diverges."""
    try:
        from benchmarks.datasets import load_dataset

        return load_dataset("cascaded-tanks")
    except Exception as exc:  # pragma: no cover - data not vendored in this checkout
        pytest.skip(f"cascaded-tanks data not available: {exc}")


@pytest.mark.parametrize("els_iter", [2, 5, 20])
def test_narmax_els_iterations_finite_and_one_step_finite_on_real_data(els_iter):
    ds = _cascaded_tanks_est()
    m = NARMAXPoly(ny=4, nu=4, ne=2, degree=3, max_terms=20, els_iter=els_iter)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # removed noise terms are reported
        m.fit(ds.est)
    assert all(np.isfinite(t).all() for t in m.theta_)
    for rec in [ds.est] + list(ds.tests.values()):
        with warnings.catch_warnings():
            warnings.simplefilter("error", DivergenceWarning)
            y1 = m.predict(rec, 1)
        assert np.isfinite(y1).all()
        # k = 1 through the k-step machinery equals the one-step path; k = N is the free run (noise terms zero)
        from sysid.polynomial import simulate as sim

        yk1, bad = sim.k_step(m.compiled(), rec.u.reshape(-1, 1), rec.y.reshape(-1, 1), 1)
        assert bad == -1
        np.testing.assert_array_equal(yk1[:, 0], y1)
        np.testing.assert_array_equal(m.predict(rec, len(rec)), m.predict(rec, None))
    assert m.els_status_ and m.describe()["els"]["status"] == m.els_status_


def test_narmax_more_els_iterations_same_or_better_fit():
    """Coloured (MA) noise: every ELS budget gives finite parameters and a finite one-step prediction on fresh
    data, and more iterations give the same or a better validation one-step error (the iterations settle;
    measured 0.01286 without noise terms, 0.01041 after 1 iteration, 0.010265 from 2 on; innovation var 0.01)."""
    rec = narmax_record(3000, seed=4, sigma=0.1)
    val = narmax_record(3000, seed=5, sigma=0.1)
    mse = {}
    for it in (0, 1, 2, 3, 5, 10, 20):
        m = NARMAXPoly(ny=2, nu=2, ne=2, degree=3, els_iter=it).fit(rec)
        assert all(np.isfinite(t).all() for t in m.theta_)
        yv = m.predict(val, 1)
        assert np.isfinite(yv).all()
        mse[it] = float(np.mean((val.y - yv)[2:] ** 2))
        if it >= 2:
            assert mse[it] <= mse[1] * (1 + 1e-3) < mse[0], (it, mse)
    assert m.els_converged_ and mse[20] == mse[10]
    assert "e(k-1)" in {r["term"] for r in m.term_table()}
    assert mse[20] < 1.05 * 0.1**2


def test_narmax_unstable_noise_model_is_reported_not_kept():
    """A noise model whose residual recursion diverges on the estimation data is never returned: the terms that
    make it diverge are removed (the process part, hence the free run, unchanged) and els_status_ says so."""
    ds = _cascaded_tanks_est()
    m = NARMAXPoly(ny=4, nu=4, ne=2, degree=3, max_terms=20, els_iter=20)
    with pytest.warns(UserWarning, match="residual recursion diverged"):
        m.fit(ds.est)
    from sysid.polynomial import simulate as sim

    _, e = sim.one_step(m.compiled(), ds.est.u.reshape(-1, 1), ds.est.y.reshape(-1, 1))
    assert np.isfinite(e).all() and np.abs(e).max() < np.abs(ds.est.y).max()
    assert m.els_unstable_, "this record is the reproduction: some ELS iteration proposes an unstable noise model"
    assert "unstable" in m.els_status_
    # the final model of this budget diverged before the fix: the removed terms are named and the warning says so
    assert m.els_removed_terms_ and all(t in m.els_status_ for t in m.els_removed_terms_)
    assert not set(m.els_removed_terms_) & set(m.noise_terms_[0])


@pytest.mark.parametrize("cls", [NARXPoly, NARMAXPoly])
def test_selection_is_scale_invariant(cls):
    """Bouc–Wen in SI units (force ~1e2 N, displacement ~1e-3 m): scaling u by 1e3 and y by 1e-3 selects the
    same terms and scales every parameter by the units of its term (θ' = θ · s_y / Π s)."""
    rec = narmax_record(3000, seed=3)
    su, sy = 1e3, 1e-3
    scaled = Record(rec.u * su, rec.y * sy, fs=1.0)
    kw = dict(ny=2, nu=2, degree=3) if cls is NARXPoly else dict(ny=2, nu=2, ne=2, degree=3)
    a = cls(**kw).fit(rec)
    b = cls(**kw).fit(scaled)
    ta, tb = a.term_table(), b.term_table()
    assert [r["term"] for r in ta] == [r["term"] for r in tb]
    s = a.structure_
    for term, ra, rb in zip(a.terms_[0], ta, tb):
        factor = sy
        for r in term:
            kind = s.regressors[r][0]
            factor /= su if kind == "u" else sy  # y and e are in y's units
        assert rb["parameter"] == pytest.approx(ra["parameter"] * factor, rel=1e-6, abs=0), ra["term"]
    np.testing.assert_allclose(b.predict(scaled, None), a.predict(rec, None) * sy, rtol=1e-6, atol=1e-9 * sy)


def test_least_squares_rank_check_is_per_column():
    """Columns of very different size (u³ ~ 1e6, y³ ~ 1e-12) are not dependent; a true duplicate is refused."""
    rng = np.random.default_rng(0)
    n = 2000
    u = 100.0 * rng.uniform(-1, 1, n)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = 0.9 * y[k - 1] + 1e-7 * u[k - 1] + 1e-11 * u[k - 1] ** 3  # y ~ 1e-4: y³ ~ 1e-12
    rec = Record(u, y, fs=1.0)
    s = fr.Structure(fr.make_regressors(1, 1), fr.candidate_terms(2, 3))
    terms = [(0,), (1,), (1, 1, 1), (0, 0, 0)]
    ls = fr.least_squares([rec], s, terms)
    assert np.isfinite(ls.theta).all()
    np.testing.assert_allclose(ls.theta[:3], [0.9, 1e-7, 1e-11], rtol=1e-6)
    with pytest.raises(DataError, match="linearly dependent"):
        fr.least_squares([rec], s, [(0,), (1,), (0,)])
    # non-finite regressors (a diverged residual recursion fed to ELS) never give NaN parameters silently
    s_e = fr.Structure(fr.make_regressors(1, 1, 1), fr.candidate_terms(3, 1))
    e = np.zeros((n, 1))
    e[500] = np.inf
    with pytest.raises(DataError, match="non-finite"):
        fr.least_squares([rec], s_e, [(0,), (1,), (2,)], e_list=[e])


def test_bouc_wen_in_si_units_is_identified():
    """The benchmark's reproduction: Bouc–Wen in N and m (u ~ 50 N rms, y ~ 7e-4 m rms) was refused as
    rank-deficient by a tolerance relative to the largest column; now it fits, close to the normalised fit."""
    try:
        from benchmarks.datasets import load_dataset

        ds = load_dataset("bouc-wen")
    except Exception as exc:  # pragma: no cover - data not vendored in this checkout
        pytest.skip(f"bouc-wen data not available: {exc}")
    est = ds.est[:8192]
    m = NARXPoly(ny=4, nu=4, degree=3).fit(est)
    assert all(np.isfinite(t).all() for t in m.theta_)
    test = ds.tests["multisine"]
    e = test.y[50:] - m.predict(test, None)[50:]
    # ARX's quick floor on this test is 2.03e-4 m (free run); the nonlinear model must stay below it
    assert np.sqrt(np.mean(e**2)) < 2.03e-4
