"""Nonparametric FRF, BLA and the transfer-function fit against closed forms (frequency domain)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as ss

from sysid.data.io import atomic_path
from sysid.errors import DataError
from sysid.linear.bla import best_linear_approximation
from sysid.linear.frf import frf_periodic, frf_welch
from sysid.linear.tfest import tfest
from sysid.signals.excitation import multisine

FS = 1000.0
B, A = ss.cheby1(4, 1.0, 0.3)  # known 4th-order IIR; G(e^jw) from scipy.signal.freqz


def g_true(f):
    return ss.freqz(B, A, worN=np.asarray(f), fs=FS)[1]


def steady(u, b=B, a=A, periods=1):
    """Steady-state response to a periodic u (one extra period simulated first and dropped)."""
    n0 = u.size // periods
    y = ss.lfilter(b, a, np.concatenate([u[:n0], u]))
    return y[n0:]


# ---------------------------------------------------------------------------------------------- H1 / Welch
def test_h1_matches_freqz_and_coherence_closed_form():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(200_000)
    sigma_n = 0.1
    y = ss.lfilter(B, A, u) + sigma_n * rng.standard_normal(u.size)
    frf = frf_welch(u, y, FS, nperseg=512)
    G = g_true(frf.f_hz)
    band = (frf.f_hz > 0) & (frf.f_hz < 0.25 * FS)  # passband (DC is detrended away)
    assert np.max(np.abs(frf.G[band] - G[band])) < 0.03
    # coherence of y = G u + n with white u (S_uu = 1) and white n: |G|^2 / (|G|^2 + sigma_n^2)
    coh = np.abs(G) ** 2 / (np.abs(G) ** 2 + sigma_n**2)
    inner = (frf.f_hz > 5) & (frf.f_hz < 0.45 * FS)
    assert np.max(np.abs(frf.coherence[inner] - coh[inner])) < 0.05
    # Bendat & Piersol std: the observed error should be of the order of the predicted one
    ratio = np.sqrt(np.mean(np.abs(frf.G[inner] - G[inner]) ** 2) / np.mean(frf.std[inner] ** 2))
    assert 0.3 < ratio < 3.0


def test_h1_window_and_overlap_options():
    rng = np.random.default_rng(1)
    u = rng.standard_normal(50_000)
    y = ss.lfilter(B, A, u)
    for window, nover in (("hamming", 0), (("tukey", 0.25), 128)):
        frf = frf_welch(u, y, FS, window=window, nperseg=1024, noverlap=nover)
        band = (frf.f_hz > 0) & (frf.f_hz < 0.25 * FS)
        assert np.max(np.abs(frf.G[band] - g_true(frf.f_hz[band]))) < 0.05
        assert frf.info["noverlap"] == nover


# ---------------------------------------------------------------------------------------------- periodic
def test_periodic_frf_is_exact_on_a_noise_free_filter():
    u, info = multisine(FS, resolution=1.0, band=(1, 400), periods=4, seed=3, return_info=True)
    y = steady(u, periods=4)
    frf = frf_periodic(u, y, FS, 4)
    assert np.array_equal(frf.lines, info["excited_bins"])
    assert np.max(np.abs(frf.G - g_true(frf.f_hz)) / np.abs(g_true(frf.f_hz))) < 1e-9
    assert np.max(frf.std) < 1e-12


def test_periodic_std_matches_noise_closed_form():
    """var(G_hat) = sigma^2 / (n0 P |U_k|^2) for white output noise sigma (DFT scaled by 1/n0)."""
    P = 8
    u, info = multisine(FS, resolution=2.0, band=(2, 300), periods=P, seed=4, return_info=True)
    n0 = info["period_samples"]
    sigma = 0.05
    rng = np.random.default_rng(5)
    y = steady(u, periods=P) + sigma * rng.standard_normal(u.size)
    frf = frf_periodic(u, y, FS, P)
    U = info["line_amplitude"] / 2.0  # |DFT/n0| of a cosine of amplitude A is A/2
    predicted = sigma / (np.sqrt(n0 * P) * U)
    assert np.mean(frf.std) == pytest.approx(predicted, rel=0.15)
    err = np.abs(frf.G - g_true(frf.f_hz))
    assert np.sqrt(np.mean(err**2)) == pytest.approx(predicted, rel=0.25)


def test_period_drift_removal_keeps_the_periodic_part():
    from sysid.linear.frf import period_spectra

    u = multisine(FS, resolution=2.0, band=(2, 300), periods=4, seed=6)
    ramp = 0.3 + 0.01 * np.arange(u.size) / FS
    X = period_spectra(u + ramp, 4, drop=1, detrend=1)
    X0 = period_spectra(u, 4, drop=1)
    assert np.allclose(X[:, 1:], X0[:, 1:], atol=1e-12)  # the ramp is gone at every line but DC
    assert np.allclose(period_spectra(u, 4, detrend=2), period_spectra(u, 4), atol=1e-12)
    assert not np.allclose(period_spectra(u + ramp, 4, drop=1)[:, 1:], X0[:, 1:], atol=1e-6)


def test_periodic_refuses_a_record_that_is_not_whole_periods():
    u = np.zeros(1001)
    u[::10] = 1
    with pytest.raises(DataError, match="equal periods"):
        frf_periodic(u, u, FS, 3)


# ---------------------------------------------------------------------------------------------- BLA
def _realisations(nl, M=4, P=3, grid="odd", fraction=0.2, sigma=1e-3, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for m in range(M):
        u = multisine(
            FS,
            resolution=1.0,
            band=(1, 200),
            grid=grid,
            detection_fraction=fraction,
            periods=P,
            seed=100 + m,
            amplitude=1.0,
            rms=True,
        )
        x = steady(u, periods=P)
        out.append((u, nl(x) + sigma * rng.standard_normal(u.size)))
    return out


@pytest.mark.parametrize(
    "nl, verdict",
    [
        (lambda x: x, "linear"),
        (lambda x: x + 0.05 * x**3, "odd"),
        (lambda x: x + 0.05 * x**2, "even"),
        (lambda x: x + 0.05 * x**3 + 0.05 * x**2, "odd+even"),
    ],
)
def test_bla_verdicts_on_wiener_systems(nl, verdict):
    res = best_linear_approximation(_realisations(nl), FS, 3)
    assert res.nonlinearity["verdict"] == verdict
    if verdict == "linear":
        assert np.max(np.abs(res.G - g_true(res.f_hz))) < 0.01
    if "odd" in verdict:
        assert res.nonlinearity["odd_db"] > 20
    if "even" in verdict:
        assert res.nonlinearity["even_db"] > 20


def test_bla_of_a_cubic_wiener_system_is_the_bussgang_gain():
    """For Gaussian x = G u, y = x + c x^3 has BLA G (1 + 3 c sigma_x^2) (Bussgang; Pintelon & Schoukens §3.5);
    a random-phase multisine is asymptotically Gaussian."""
    c = 0.2
    reals = _realisations(lambda x: x + c * x**3, M=8, P=2, fraction=0.0, sigma=0.0, seed=1)
    sx2 = np.mean([np.var(steady(u, periods=2)) for u, _ in reals])
    res = best_linear_approximation(reals, FS, 2)
    ratio = res.G / g_true(res.f_hz)
    passband = res.f_hz < 140
    assert np.median(np.abs(ratio[passband])) == pytest.approx(1 + 3 * c * sx2, rel=0.02)
    # the distortion variance is what the realisations disagree by, far above the (zero) noise variance
    assert np.nanmedian(res.var_distortion) > 1e6 * np.nanmedian(res.var_noise)


def test_bla_noise_variance_closed_form_and_full_grid_note():
    sigma = 0.01
    reals = _realisations(lambda x: x, M=3, P=4, grid="full", fraction=0.1, sigma=sigma, seed=2)
    res = best_linear_approximation(reals, FS, 4)
    n0 = int(FS / 1.0)
    A = np.abs(np.fft.rfft(reals[0][0][:n0]) / n0)[res.lines].mean()
    predicted = sigma**2 / (n0 * 4 * A**2) / 3  # per realisation / M
    assert np.mean(res.var_noise) == pytest.approx(predicted, rel=0.2)
    assert res.nonlinearity["classified"] is False
    assert res.nonlinearity["verdict"] == "linear"
    assert any("full grid" in n for n in res.nonlinearity["notes"])


# ---------------------------------------------------------------------------------------------- tfest
def test_tfest_recovers_a_known_filter():
    f = np.linspace(1, 480, 300)
    b, a = ss.butter(3, 0.2)
    G = ss.freqz(b, a, worN=f, fs=FS)[1]
    tf = tfest(f, G, FS, nb=4, na=3)
    assert np.allclose(tf.a, a, atol=1e-6)
    assert np.allclose(tf.b, b, atol=1e-6)
    # with a pure delay of two samples
    tf2 = tfest(f, G * np.exp(-2j * np.pi * f / FS * 2), FS, nb=4, na=3, nk=2)
    assert np.allclose(tf2.b[2:], b, atol=1e-6) and np.allclose(tf2.b[:2], 0)
    assert np.all(np.abs(tf2.poles) < 1)


def test_atomic_path_leaves_no_partial_file(tmp_path):
    target = tmp_path / "out.csv"
    target.write_text("old\n")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("interrupted")
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]
    with atomic_path(target) as tmp:
        tmp.write_text("new\n")
    assert target.read_text() == "new\n"


# ---------------------------------------------------------------------------------------------- bla identifier
def test_bla_identifier_recovers_a_filter_and_round_trips(tmp_path):
    from sysid.base import load_model
    from sysid.data.record import Record
    from sysid.registry import get_identifier

    rng = np.random.default_rng(7)
    b, a = ss.butter(2, 0.1)
    u = rng.standard_normal(40_000) + 0.5  # operating point: mean input 0.5, output offset 2
    y = 2.0 + ss.lfilter(b, a, u - 0.5) + 0.01 * rng.standard_normal(u.size)
    rec = Record(u=u, y=y, fs=FS)
    model = get_identifier("bla")(nb=3, nf=2).fit(rec)
    assert np.allclose(model.a_, a, atol=0.02) and np.allclose(model.b_, b, atol=0.01)
    yh = model.predict(rec, horizon=None)
    assert np.sqrt(np.mean((yh - y)[50:] ** 2)) < 0.02
    assert np.array_equal(model.predict(rec, horizon=1), yh)  # output-error model: one-step = simulation
    path = model.save(tmp_path / "bla.json")
    assert np.array_equal(load_model(path).predict(rec, horizon=None), yh)
    # periodic (multisine realisations) mode on the same filter
    recs = []
    for m in range(2):
        um = multisine(FS, resolution=1.0, band=(1, 400), periods=3, seed=20 + m)
        recs.append(Record(u=um, y=steady(um, b, a, periods=3), fs=FS))
    pm = get_identifier("bla")(nb=3, nf=2, periods=3).fit(recs)
    assert np.allclose(pm.a_, a, atol=1e-6) and np.allclose(pm.b_, b, atol=1e-6)
    assert pm.describe()["nonlinearity"]["verdict"] == "linear"


def test_tfest_parameter_std_matches_monte_carlo():
    """Sandwich covariance of tfest from the periodic FRF's own std: the spread over 60 noise seeds agrees
    with the reported std, and ~95 % of the estimates lie within 2 std of the truth."""
    b, a = ss.butter(2, 0.1)
    u = multisine(FS, resolution=2.0, band=(2, 400), periods=4, seed=1)
    y0 = steady(u, b, a, periods=4)
    truth = np.concatenate([a[1:], b])
    rng = np.random.default_rng(0)
    est, sds = [], []
    for _ in range(60):
        frf = frf_periodic(u, y0 + 0.05 * rng.standard_normal(u.size), FS, 4)
        tf = tfest(frf.f_hz, frf.G, FS, nb=3, na=2, var=frf.std**2)
        est.append(np.concatenate([tf.a[1:], tf.b]))
        sds.append(np.concatenate([tf.info["std_a"], tf.info["std_b"]]))
    est, sds = np.array(est), np.array(sds)
    ratio = est.std(axis=0) / np.median(sds, axis=0)
    assert np.all((ratio > 0.7) & (ratio < 1.4))
    assert np.mean(np.abs(est - truth) < 2 * sds) > 0.88
