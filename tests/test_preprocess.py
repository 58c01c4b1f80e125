"""Preprocessing (sysid.signals.preprocess) against closed forms and designed specifications."""

import numpy as np
import pytest
from scipy.signal import lfilter

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.signals import preprocess as P
from sysid.signals.cleaning import _hampel_1d


def tone_amp_phase(y: np.ndarray, f: float, fs: float, t0: float = 0.0) -> tuple[float, float]:
    """Least-squares amplitude and phase of a tone cos(2 pi f t + phi) in y (t = t0 + n/fs)."""
    t = t0 + np.arange(y.size) / fs
    A = np.c_[np.cos(2 * np.pi * f * t), -np.sin(2 * np.pi * f * t)]
    (c, s), *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(np.hypot(c, s)), float(np.arctan2(s, c))


# ---------------------------------------------------------------------------------------------- offset / trend
def test_remove_offset_and_detrend():
    n = np.arange(1000.0)
    x = 3.0 + 0.01 * n - 2e-5 * n**2
    assert abs(P.remove_offset(x).mean()) < 1e-12
    assert np.max(np.abs(P.detrend(x, order=2))) < 1e-9  # an exact quadratic is removed completely
    # a linear drift under a zero-mean tone: the result has no linear component left
    tone = np.sin(2 * np.pi * n / 50)
    y, coef = P.detrend(tone + 0.5 + 0.002 * n, order=1, return_coefficients=True)
    slope = np.polyfit(n, y, 1)[0]
    assert abs(slope) < 1e-12 and abs(y.mean()) < 1e-12
    assert coef.shape == (2, 1)
    # 2-D: per channel
    X = np.c_[x, 2 * x]
    np.testing.assert_allclose(P.detrend(X, 2), 0, atol=1e-8)


# ---------------------------------------------------------------------------------------------- Hampel
def test_hampel_finds_injected_outliers_and_reports_each_change():
    rng = np.random.default_rng(0)
    n = 20000
    clean = np.sin(2 * np.pi * np.arange(n) / 2000)
    x = clean + 0.01 * rng.standard_normal(n)
    idx = np.sort(rng.choice(np.arange(50, n - 50), size=25, replace=False))
    x_bad = x.copy()
    x_bad[idx] += rng.choice([-1, 1], size=idx.size) * rng.uniform(0.5, 2.0, size=idx.size)
    # strict threshold: exactly the injected samples are flagged
    y, ch = P.hampel(x_bad, window=10, n_sigma=6.0)
    assert [c["index"] for c in ch] == idx.tolist()
    assert np.max(np.abs(y[idx] - clean[idx])) < 0.05  # replaced by the local median
    # every change is reported, nothing else changes
    changed = np.flatnonzero(y != x_bad)
    assert changed.tolist() == [c["index"] for c in ch]
    for c in ch:
        assert c["value"] == x_bad[c["index"]] and c["replacement"] == y[c["index"]] and c["channel"] == 0
    # default threshold (3 sigma) still finds them all; its false alarms are small noise-level changes
    y3, ch3 = P.hampel(x_bad)
    flagged = {c["index"] for c in ch3}
    assert set(idx.tolist()) <= flagged
    false = [c for c in ch3 if c["index"] not in set(idx.tolist())]
    assert len(false) < 0.03 * n
    assert max(abs(c["value"] - c["replacement"]) for c in false) < 0.1


def test_hampel_two_channels():
    x = np.zeros((200, 2))
    x[:, 0] = np.linspace(0, 1, 200)
    x[:, 1] = np.linspace(1, 0, 200)
    x[40, 1] = 9.0
    y, ch = P.hampel(x, window=5)
    assert [(c["index"], c["channel"]) for c in ch] == [(40, 1)]
    assert y[40, 1] == np.median(x[35:46, 1])  # the local median (window includes the outlier)
    assert abs(y[40, 1] - (1 - 40 / 199)) < 1.5 / 199


# ---------------------------------------------------------------------------------------------- missing samples
def test_fill_missing_linear_pchip_nearest():
    n = np.arange(100.0)
    x = 2.0 * n + 1.0
    x_nan = x.copy()
    holes = [0, 5, 6, 7, 50, 99]
    x_nan[holes] = np.nan
    y, filled = P.fill_missing(x_nan)
    assert filled == holes
    np.testing.assert_allclose(y[1:99], x[1:99], atol=1e-12)  # a line is interpolated exactly
    assert y[0] == x[1] and y[99] == x[98]  # ends held at the nearest valid sample
    s = np.sin(n / 10)
    s_nan = s.copy()
    s_nan[[30, 31, 60]] = np.nan
    yp, _ = P.fill_missing(s_nan, method="pchip")
    assert np.max(np.abs(yp - s)) < 1e-3
    yn, _ = P.fill_missing(np.array([1.0, np.nan, np.nan, np.nan, 5.0]), method="nearest")
    np.testing.assert_array_equal(yn, [1, 1, 1, 5, 5])
    with pytest.raises(DataError, match="infinite"):
        P.fill_missing(np.array([1.0, np.inf]))
    with pytest.raises(DataError, match="no valid"):
        P.fill_missing(np.array([np.nan, np.nan]))


# ---------------------------------------------------------------------------------------------- moving average
@pytest.mark.parametrize("span, mode", [(7, "centred"), (100, "centred"), (10, "causal")])
def test_moving_average_definition(span, mode):
    x = np.random.default_rng(1).standard_normal(400)
    y = P.moving_average(x, span, mode)
    before, after = (span // 2, (span - 1) // 2) if mode == "centred" else (span - 1, 0)
    ref = np.array([x[max(0, i - before) : min(400, i + after + 1)].mean() for i in range(400)])
    np.testing.assert_allclose(y, ref, atol=1e-12)


def test_moving_average_frequency_response_dissertation_filter():
    # span 100 at 100 MHz: |H(f)| = |sin(pi f N/fs) / (N sin(pi f/fs))| -> -13.5 dB at 1.35 MHz, null at 1 MHz
    fs, span = 100e6, 100
    n = 20000
    for f in (0.9e6, 1.35e6, 2.5e6):
        x = np.cos(2 * np.pi * f * np.arange(n) / fs)
        y = P.moving_average(x, span)[200:-200]
        a, _ = tone_amp_phase(y, f, fs, t0=200 / fs - 0.5 / fs)  # even span: half-sample lag
        h = abs(np.sin(np.pi * f * span / fs) / (span * np.sin(np.pi * f / fs)))
        assert a == pytest.approx(h, rel=1e-6)
    h135 = 20 * np.log10(abs(np.sin(np.pi * 1.35e6 * span / fs) / (span * np.sin(np.pi * 1.35e6 / fs))))
    assert -14 < h135 < -13


# ---------------------------------------------------------------------------------------------- decimation / resampling
def _check_rate_change(fn, fs, fs_out, n, passband_hz, stop_hz):
    nyq_out = fs_out / 2
    for f in passband_hz:
        x = np.cos(2 * np.pi * f * np.arange(n) / fs + 0.3)
        y, h = fn(x)
        edge = int(0.05 * y.size)  # filter transients at both ends (half the FIR: 20 output samples here)
        a, ph = tone_amp_phase(y[edge:-edge], f, fs_out, t0=edge / fs_out)
        assert abs(20 * np.log10(a)) < 0.1, f"in-band {f} Hz: {20 * np.log10(a):.4f} dB"
        assert abs(np.angle(np.exp(1j * (ph - 0.3)))) < 1e-3  # zero phase, first sample aligned
    for f in stop_hz:
        assert f > nyq_out
        x = np.cos(2 * np.pi * f * np.arange(n) / fs)
        y, h = fn(x)
        edge = int(0.05 * y.size)
        level = 20 * np.log10(np.sqrt(2) * np.std(y[edge:-edge]) + 1e-300)
        assert level < -60, f"{f} Hz above the new Nyquist {nyq_out} Hz: only {-level:.1f} dB down"


def test_decimate_passband_and_alias_rejection():
    fs, q = 1e6, 10
    nyq = fs / (2 * q)
    _check_rate_change(
        lambda x: P.decimate(x, q, return_filter=True),
        fs,
        fs / q,
        100_000,
        passband_hz=[1e3, 0.5 * nyq, 0.8 * nyq],
        stop_hz=[1.001 * nyq, 1.5 * nyq, 3.7 * nyq, 0.49 * fs],
    )
    y = P.decimate(np.ones(1001), q)
    assert y.size == 101
    with pytest.raises(ConfigError, match="q"):
        P.decimate(np.ones(10), 0)
    with pytest.raises(ConfigError, match="q"):
        P.decimate(np.ones(10), 2.5)


def test_resample_100mhz_to_6p75mhz():
    fs, fs_new = 100e6, 6.75e6  # dissertation §3.2: x 27/400
    nyq = fs_new / 2
    _check_rate_change(
        lambda x: P.resample(x, fs, fs_new, return_filter=True),
        fs,
        fs_new,
        200_000,
        passband_hz=[0.9e6, 1.35e6, 0.8 * nyq],
        stop_hz=[1.002 * nyq, 5e6, 20e6, 45e6],
    )
    assert P.resample(np.ones(400), fs, fs_new).size == 27
    with pytest.raises(ConfigError, match="ratio"):
        P.resample(np.ones(100), 1.0, np.pi)


def test_antialias_filter_design_specs():
    # the designed FIR meets the specs on a dense grid (independent of the time-domain checks above)
    from scipy.signal import freqz

    h = P.antialias_filter(1, 10)
    w, H = freqz(h, worN=2**16, fs=1.0)
    db = 20 * np.log10(np.abs(H) + 1e-300)
    assert np.max(np.abs(db[w <= 0.8 * 0.05])) < 0.1
    assert np.max(db[w >= 0.05]) < -60


# ---------------------------------------------------------------------------------------------- band-pass
def butterworth_bp_gain_db(f, fs, f1, f2, order):
    """|H|^2 of the analog Butterworth band-pass prototype mapped by the bilinear transform (pre-warped):
    Omega = 2 fs tan(pi f/fs); |H|^2 = 1 / (1 + ((Omega^2 - O1 O2) / (Omega (O2 - O1)))^(2n)); zero-phase
    filtering squares it once more."""
    W = lambda x: 2 * fs * np.tan(np.pi * x / fs)  # noqa: E731
    O, O1, O2 = W(np.asarray(f)), W(f1), W(f2)
    x = (O**2 - O1 * O2) / (O * (O2 - O1))
    return 2 * 10 * np.log10(1.0 / (1.0 + x ** (2 * order)))


def test_bandpass_zero_phase_ripple_and_rejection():
    fs, f1, f2, order = 1e6, 90e3, 135e3, 5  # the dissertation's band scaled by 1/10
    n = 100_000
    fc = np.sqrt(f1 * f2)
    freqs = [fc, 100e3, 125e3, f1, f2, 60e3, 45e3, 200e3, 270e3]
    for f in freqs:
        x = np.cos(2 * np.pi * f * np.arange(n) / fs + 0.2)
        y = P.bandpass(x, fs, f1, f2, order)[5000:-5000]
        a, ph = tone_amp_phase(y, f, fs, t0=5000 / fs)
        expect = butterworth_bp_gain_db(f, fs, f1, f2, order)
        got = 20 * np.log10(a)
        assert got == pytest.approx(expect, abs=0.05), f"{f} Hz: {got:.3f} dB vs design {expect:.3f} dB"
        if expect > -20:
            assert abs(np.angle(np.exp(1j * (ph - 0.2)))) < 1e-3  # zero phase
    # maximally flat pass band: within 0.1 dB over the middle of the band, -6.02 dB (-3 dB twice) at the edges
    mid = np.linspace(0.97 * fc, 1.03 * fc, 5)
    assert np.max(np.abs(butterworth_bp_gain_db(mid, fs, f1, f2, order))) < 0.1
    assert butterworth_bp_gain_db(f1, fs, f1, f2, order) == pytest.approx(-6.02, abs=0.01)
    # stop band: one octave below / above the band the design gives more than 60 dB
    assert (
        butterworth_bp_gain_db(45e3, fs, f1, f2, order) < -60 and butterworth_bp_gain_db(270e3, fs, f1, f2, order) < -60
    )


@pytest.mark.parametrize("fmin, fmax", [(200.0, 100.0), (0.0, 100.0), (100.0, 600.0)])
def test_bandpass_bad_edges(fmin, fmax):
    with pytest.raises(ConfigError):
        P.bandpass(np.ones(100), 1000.0, fmin, fmax)


# ---------------------------------------------------------------------------------------------- segmentation
def test_segment():
    x = np.arange(20.0)
    b = P.segment_bounds(20, 6, overlap=2)
    assert b == [(0, 6), (4, 10), (8, 14), (12, 18)]
    s = P.segment(x, 6, overlap=2)
    assert s.shape == (4, 6)
    for (a, e), row in zip(b, s):
        np.testing.assert_array_equal(row, x[a:e])
    s2 = P.segment(np.c_[x, -x], 5)
    assert s2.shape == (4, 5, 2) and np.array_equal(s2[1, :, 1], -x[5:10])
    with pytest.raises(ConfigError):
        P.segment_bounds(20, 6, overlap=6)


# ---------------------------------------------------------------------------------------------- Aguirre's rule
def test_suggest_rate_on_oversampled_sine_is_exact():
    # y = sin(2 pi n / P): r_yy(k) ~ cos(2 pi k/P)/2 has its first minimum at P/2; y'^2 - mean = -cos(4 pi n/P)/2,
    # whose autocovariance ~ cos(4 pi k/P)/8 has its first minimum at P/4. tau_m = P/4 = 250 -> factor 25.
    y = np.sin(2 * np.pi * np.arange(100_000) / 1000)
    s = P.suggest_rate(y, fs=1e6)
    assert (s["tau_linear"], s["tau_nonlinear"], s["tau_min"], s["factor"]) == (500, 250, 250, 25)
    assert s["factor_range"] == [13, 25] and s["fs_suggested"] == pytest.approx(40e3)


def test_suggest_rate_on_oversampled_resonator_recovers_expected_factor():
    # An oversampled lightly damped resonator driven by white Gaussian noise: the AR(2) process
    #   y[n] = 2 rho cos(th) y[n-1] - rho^2 y[n-2] + e[n],  th = 2 pi / 370 (370 samples per damped period),
    #   rho = exp(-zeta th / sqrt(1 - zeta^2)), zeta = 0.2.
    # Yule-Walker gives its autocovariance in closed form:
    #   r(k)/r(0) = rho^k [cos(th k) + c sin(th k)],  c = cos(th) (1 - rho^2) / ((1 + rho^2) sin(th)),
    # so r'(k) ~ -sin(th k) (for c from the recursion) and the first minimum of r is near k = pi/th = 185.
    # y is Gaussian, so (Isserlis) cov(y^2(n), y^2(n+k)) = 2 r(k)^2, whose first minimum is the first zero of
    # r: th k = pi - atan(1/c) ~ 105. tau_m = min(185, 105) = 105 -> Ts between tau_m/20 and tau_m/10 ->
    # the largest factor is floor(105/10) = 10 (the lags are computed from the closed form below).
    P_d, zeta = 370.0, 0.2
    th = 2 * np.pi / P_d
    rho = np.exp(-zeta * th / np.sqrt(1 - zeta**2))
    k = np.arange(1000)
    c = np.cos(th) * (1 - rho**2) / ((1 + rho**2) * np.sin(th))
    r = rho**k * (np.cos(th * k) + c * np.sin(th * k))

    def first_min(v):
        d = np.diff(v)
        return int(np.flatnonzero((d[:-1] <= 0) & (d[1:] > 0))[0] + 1)

    tau_lin, tau_nl = first_min(r), first_min(r**2)
    assert abs(tau_lin - 185) <= 2 and abs(tau_nl - 105) <= 2
    expected = min(tau_lin, tau_nl) // 10
    assert expected == 10

    e = np.random.default_rng(0).standard_normal(400_000)
    y = lfilter([1.0], [1.0, -2 * rho * np.cos(th), rho**2], e)[5000:] + 3.0  # an offset does not matter
    s = P.suggest_rate(y, fs=100e6)
    assert abs(s["tau_linear"] - tau_lin) <= 3 and abs(s["tau_nonlinear"] - tau_nl) <= 3
    assert s["factor"] == expected
    assert s["fs_suggested"] == pytest.approx(100e6 / expected)


def test_suggest_rate_white_noise_means_no_oversampling():
    s = P.suggest_rate(np.random.default_rng(2).standard_normal(50_000))
    assert s["factor"] == 1
    with pytest.raises(DataError, match="no minimum"):
        P.suggest_rate(np.linspace(0, 1, 1000))  # monotone autocovariance within N/2 lags


# ---------------------------------------------------------------------------------------------- record level
def test_apply_steps_in_order_and_recorded():
    rng = np.random.default_rng(3)
    n = 4000
    u = np.sin(2 * np.pi * np.arange(n) / 400) + 0.5
    y = 2 * u + 0.01 * rng.standard_normal(n)
    y[1234] = 50.0
    rec = Record(u=u, y=y, fs=1000.0, meta={"protocol": "test"})
    out = P.apply_steps(
        rec,
        [
            "remove_offset",
            ("outliers", {"window": 5, "n_sigma": 6, "signals": "y"}),
            {"step": "moving_average", "span": 3},
            {"step": "decimate", "q": 4},
            {"step": "segment", "length": 250, "overlap": 50},
            "suggest_rate",
        ],
    )
    log = out.meta["preprocessing"]
    assert [e["step"] for e in log] == [
        "remove_offset",
        "hampel",
        "moving_average",
        "decimate",
        "segment",
        "suggest_rate",
    ]
    assert log[0]["changes"]["offset"]["u"] == pytest.approx(0.5, abs=1e-9)
    assert [c["index"] for c in log[1]["changes"]["replaced"]["y"]] == [1234]
    assert log[3]["changes"]["fs_after"] == 250.0 and out.fs == 250.0 and len(out) == 1000
    assert log[4]["changes"]["n_segments"] == len(out.segments()) == 4
    assert "factor" in log[5]["changes"]
    assert out.meta["protocol"] == "test" and "preprocessing" not in rec.meta  # the input is untouched
    # same result as calling the array functions in that order
    ref = P.decimate(P.moving_average(P.remove_offset(u), 3), 4)
    np.testing.assert_allclose(out.u, ref, atol=1e-12)


def test_apply_steps_errors():
    rec = Record(u=np.ones(100), y=None, fs=10.0)
    with pytest.raises(ConfigError, match="unknown preprocessing step"):
        P.apply_steps(rec, ["sharpen"])
    with pytest.raises(ConfigError, match="unknown parameter"):
        P.apply_steps(rec, [{"step": "decimate", "q": 2, "factor": 3}])
    with pytest.raises(ConfigError, match="segment last"):
        P.apply_steps(rec, [{"step": "segment", "length": 10}, {"step": "decimate", "q": 2}])


def test_hampel_running_median_and_mad_match_numpy():
    # the compiled running median/MAD against numpy on every window (reflect-padded edges), with ties
    rng = np.random.default_rng(5)
    for x in (rng.standard_normal(300), np.round(rng.standard_normal(300), 1)):
        for k in (1, 3, 10):
            out, med, sigma = _hampel_1d(x, k, 3.0)
            pad = np.pad(x, k, mode="reflect")
            w = np.lib.stride_tricks.sliding_window_view(pad, 2 * k + 1)
            m_ref = np.median(w, axis=1)
            mad_ref = np.median(np.abs(w - m_ref[:, None]), axis=1)
            np.testing.assert_array_equal(med, m_ref)
            np.testing.assert_allclose(sigma, 1.482602218505602 * mad_ref, rtol=0, atol=1e-15)
            np.testing.assert_array_equal(out, np.abs(x - m_ref) > 3.0 * 1.482602218505602 * mad_ref)
