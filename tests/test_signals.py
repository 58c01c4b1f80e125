"""Excitation signals (sysid.signals) against closed forms: line spectra, crest factors, sweep laws, m-sequences."""

import numpy as np
import pytest
from scipy.signal import hilbert

from sysid.errors import ConfigError
from sysid.signals import excitation as S


def line_db(u: np.ndarray, n0: int) -> np.ndarray:
    """Magnitude (dB re the largest line) of the DFT of one period of length n0 (bins 0..n0/2)."""
    X = np.abs(np.fft.rfft(u[:n0]))
    return 20 * np.log10(np.maximum(X, 1e-300) / X.max())


# ---------------------------------------------------------------------------------------------- multisine
@pytest.mark.parametrize("phase", ["random", "schroeder"])
@pytest.mark.parametrize("periods", [1, 3])
def test_periodic_multisine_flat_lines_and_empty_elsewhere(phase, periods):
    fs, n0 = 1000.0, 1000
    u, info = S.multisine(
        fs, duration=periods * n0 / fs, band=(10, 200), phase=phase, periods=periods, seed=3, return_info=True
    )
    assert u.size == periods * n0 and info["period_samples"] == n0 and info["periodic"]
    # every period is the same signal
    for p in range(1, periods):
        np.testing.assert_allclose(u[p * n0 : (p + 1) * n0], u[:n0], atol=1e-12)
    # spectrum of the whole record: excited lines at p*m
    X = np.abs(np.fft.rfft(u))
    db = 20 * np.log10(np.maximum(X, 1e-300) / X.max())
    exc = periods * info["excited_bins"]
    np.testing.assert_array_equal(info["excited_bins"], np.arange(10, 201))
    assert db[exc].max() - db[exc].min() < 0.1
    others = np.setdiff1d(np.arange(X.size), exc)
    assert db[others].max() < -100
    # peak scaling: max|u| is the amplitude
    assert np.max(np.abs(u)) == pytest.approx(1.0, rel=1e-12)


def test_multisine_rms_amplitude_and_line_amplitude():
    u, info = S.multisine(1000.0, duration=1.0, band=(5, 100), amplitude=2.5, rms=True, seed=1, return_info=True)
    assert np.sqrt(np.mean(u**2)) == pytest.approx(2.5, rel=1e-12)
    # Parseval for a sum of nf cosines of amplitude A: rms^2 = nf A^2 / 2 (eq. 2-1)
    assert info["line_amplitude"] == pytest.approx(2.5 * np.sqrt(2.0 / info["n_components"]), rel=1e-12)
    assert info["crest_factor"] == pytest.approx(np.max(np.abs(u)) / 2.5, rel=1e-12)


def test_multisine_equals_eq_2_1_sum_of_cosines():
    fs = 200.0
    u, info = S.multisine(fs, duration=1.0, band=(3, 20), components=6, seed=7, return_info=True)
    t = np.arange(u.size) / fs
    ref = sum(
        info["line_amplitude"] * np.cos(2 * np.pi * f * t + p)
        for f, p in zip(info["frequencies_hz"], info["phases_rad"])
    )
    np.testing.assert_allclose(u, ref, atol=1e-12)
    assert info["n_components"] == 6 and info["frequencies_hz"][0] == 3 and info["frequencies_hz"][-1] == 20


def test_schroeder_crest_factor_below_median_of_random_phases():
    kw = dict(fs=2000.0, duration=1.0, band=(1, 500))
    cf_s = S.multisine(phase="schroeder", return_info=True, **kw)[1]["crest_factor"]
    cfs = [S.multisine(phase="random", seed=s, return_info=True, **kw)[1]["crest_factor"] for s in range(20)]
    assert cf_s < np.median(cfs)
    # and the phases follow phi_k = -k(k-1) pi / nf
    info = S.multisine(phase="schroeder", return_info=True, **kw)[1]
    k = np.arange(1, info["n_components"] + 1)
    np.testing.assert_allclose(np.exp(1j * info["phases_rad"]), np.exp(-1j * k * (k - 1) * np.pi / k.size), atol=1e-9)


def test_odd_grid_has_no_even_lines():
    u, info = S.multisine(1000.0, duration=1.0, band=(1, 300), grid="odd", seed=0, return_info=True)
    assert np.all(info["excited_bins"] % 2 == 1)
    db = line_db(u, 1000)
    assert db[0::2].max() < -100  # every even line (and DC) empty
    assert db[1:301:2].min() > -0.1


def test_odd_odd_grid_and_detection_lines_reveal_distortion():
    fs, n0 = 1000.0, 1000
    u, info = S.multisine(
        fs, duration=1.0, band=(1, 120), grid="odd-odd", detection_fraction=0.25, seed=5, return_info=True
    )
    exc, det = info["excited_bins"], info["detection_bins"]
    assert np.all(exc % 4 == 1) and np.all(det % 4 == 1)
    cand = np.arange(1, 121, 4)  # 30 candidate lines, blocks of 4 -> 7 detection lines, one per block
    assert det.size == cand.size // 4 and np.intersect1d(exc, det).size == 0
    np.testing.assert_array_equal(np.union1d(exc, det), cand)
    for b in range(cand.size // 4):
        assert np.isin(cand[4 * b : 4 * b + 4], det).sum() == 1
    db = line_db(u, n0)
    assert db[det].max() < -100 and db[exc].min() > -0.1
    # odd (cubic) distortion falls on m = 3 mod 4 and on the detection lines, never on even lines
    y3 = u + 0.3 * u**3
    d3 = line_db(y3, n0)
    assert d3[0::2].max() < -100
    assert d3[3::4][:60].max() > -60 and d3[det].max() > -80
    # even (quadratic) distortion falls on even lines
    y2 = u + 0.3 * u**2
    assert line_db(y2, n0)[2::2][:240].max() > -60
    # seeded: same seed same lines, another seed other lines
    det2 = S.multisine(
        fs, duration=1.0, band=(1, 120), grid="odd-odd", detection_fraction=0.25, seed=5, return_info=True
    )[1]["detection_bins"]
    det3 = S.multisine(
        fs, duration=1.0, band=(1, 120), grid="odd-odd", detection_fraction=0.25, seed=6, return_info=True
    )[1]["detection_bins"]
    np.testing.assert_array_equal(det, det2)
    assert not np.array_equal(det, det3)


def test_multisine_resolution_and_truncation():
    u, info = S.multisine(100.0, duration=8.0, band=(0.1, 5.0), resolution=0.1, seed=0, return_info=True)
    assert u.size == 800 and info["period_samples"] == 1000 and not info["periodic"]
    assert info["periods"] == pytest.approx(0.8)
    assert info["n_components"] == 50 and np.max(np.abs(u)) == pytest.approx(1.0)


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(band=(200, 100)), "fmin"),
        (dict(band=(10, 500)), "Nyquist"),
        (dict(band=(10, 20), components=50), "do not fit"),
        (dict(band=(10, 20), phase="bogus"), "phase"),
        (dict(band=(10, 20), grid="even"), "grid"),
        (dict(band=(10, 20), resolution=0.3), "resolution"),
        (dict(band=(10, 20), periods=3), "periods"),
        (dict(band=(10, 20), detection_fraction=0.9), "detection_fraction"),
        (dict(band=(10, 20), amplitude=-1), "amplitude"),
    ],
)
def test_multisine_bad_arguments(kw, match):
    with pytest.raises(ConfigError, match=match):
        S.multisine(1000.0, duration=1.0, **kw)


def test_thesis_cantilever_multisine():
    u, info = S.thesis_cantilever_multisine(seed=0, return_info=True)
    assert u.size == 80_000  # 8 s at 10 kHz (Figure 3.3)
    assert np.max(np.abs(u)) == pytest.approx(100.0, rel=1e-12)  # +-100 V
    assert info["n_components"] == 5000
    np.testing.assert_allclose(info["frequencies_hz"], 0.1 * np.arange(1, 5001))
    assert not np.array_equal(u, S.thesis_cantilever_multisine(seed=1))


@pytest.mark.slow
def test_thesis_acoustic_multisine():
    u, info = S.thesis_acoustic_multisine(seed=0, return_info=True)
    assert u.size == 10_000_000 and info["period_samples"] == 10_000_000  # 0.1 s at 100 MHz
    assert info["n_components"] == 45_000
    assert info["frequencies_hz"][0] == 900e3 and info["frequencies_hz"][-1] == pytest.approx(1349.99e3)
    assert np.max(np.abs(u)) == pytest.approx(0.4)
    db = line_db(u, u.size)
    assert db[info["excited_bins"]].min() > -0.1
    v = S.thesis_acoustic_multisine(seed=0, truncate=5000)
    np.testing.assert_array_equal(v, u[:5000])


# ---------------------------------------------------------------------------------------------- chirp / sine
def inst_freq(u: np.ndarray, fs: float) -> np.ndarray:
    ph = np.unwrap(np.angle(hilbert(u)))
    return np.diff(ph) * fs / (2 * np.pi)  # at t = (n + 1/2)/fs


@pytest.mark.parametrize("method, f0, f1", [("linear", 1e3, 20e3), ("linear", 30e3, 5e3), ("log", 2e3, 40e3)])
def test_chirp_instantaneous_frequency_follows_design_law(method, f0, f1):
    fs, T = 200e3, 0.05
    u = S.chirp(fs, T, f0, f1, amplitude=0.7, method=method)
    assert u.size == 10_000 and np.max(np.abs(u)) <= 0.7 + 1e-12
    f = inst_freq(u, fs)
    t = (np.arange(f.size) + 0.5) / fs
    law = f0 + (f1 - f0) * t / T if method == "linear" else f0 * (f1 / f0) ** (t / T)
    keep = slice(int(0.05 * f.size), int(0.95 * f.size))  # Hilbert edge effects
    assert np.max(np.abs(f[keep] / law[keep] - 1)) < 0.01


def test_thesis_chirps():
    u = S.thesis_chirp(0.001)  # 1 ms validation sweep, 150 mVpp
    assert u.size == 100_000 and np.ptp(u) == pytest.approx(0.150, rel=1e-6)
    f = inst_freq(u, 100e6)
    t = (np.arange(f.size) + 0.5) / 100e6
    keep = slice(5000, 95000)
    law = 900e3 + 450e3 * t / 1e-3
    assert np.max(np.abs(f[keep] / law[keep] - 1)) < 0.01
    with pytest.raises(ConfigError, match="0.1 s or 0.001 s"):
        S.thesis_chirp(0.5)


def test_periodic_chirp_eq_2_2():
    fs, T0 = 10e3, 0.1  # k1 = 100 Hz * T0 = 10, k2 = 2000 Hz * T0 = 200
    u = S.chirp(fs, 3 * T0, 100.0, 2000.0, periodic=True, periods=3)
    n0 = int(fs * T0)
    np.testing.assert_allclose(u[n0 : 2 * n0], u[:n0], atol=1e-12)
    t = np.arange(n0) / fs
    a, b = np.pi * (200 - 10) / T0**2, 2 * np.pi * 10 / T0  # eq. 2-2: a = pi (k2 - k1) f0^2, b = 2 pi k1 f0
    np.testing.assert_allclose(u[:n0], np.cos((a * t + b) * t), atol=1e-9)
    with pytest.raises(ConfigError, match="integer"):
        S.chirp(fs, T0, 105.0, 2000.0, periodic=True)


def test_sine_eq_2_3_and_crest_factor():
    u = S.sine(1000.0, 2.0, 12.5, amplitude=3.0, phase=0.4)
    t = np.arange(2000) / 1000.0
    np.testing.assert_allclose(u, 3.0 * np.cos(2 * np.pi * 12.5 * t + 0.4), atol=1e-12)
    assert S.crest_factor(S.sine(1000.0, 2.0, 12.5)) == pytest.approx(np.sqrt(2), rel=1e-9)  # peak sampled at t=0
    with pytest.raises(ConfigError, match="Nyquist"):
        S.sine(1000.0, 1.0, 600.0)


def test_stepped_sine_windows_and_continuity():
    fs = 10e3
    u, info = S.stepped_sine(fs, [10.0, 25.0, 100.0], amplitude=2.0, settle=0.2, cycles=5, return_info=True)
    for step in info["steps"]:
        assert step["measure_start"] - step["start"] == 2000
        n = step["stop"] - step["measure_start"]
        assert n == round(step["cycles"] * fs / step["freq_hz"])
        seg = u[step["measure_start"] : step["stop"]]
        X = np.abs(np.fft.rfft(seg)) * 2 / n
        assert X[step["cycles"]] == pytest.approx(2.0, rel=1e-9)  # whole periods: all power on one line
    assert u.size == info["steps"][-1]["stop"]
    # phase-continuous: no step larger than the fastest sine's slope allows
    assert np.max(np.abs(np.diff(u))) <= 2.0 * 2 * np.pi * 100.0 / fs * 1.0001


# ---------------------------------------------------------------------------------------------- PRBS / APRBS
@pytest.mark.parametrize("order", range(2, 19))
def test_prbs_is_maximum_length_sequence(order):
    u = S.prbs(1.0, order=order)
    N = 2**order - 1
    assert u.size == N and set(np.unique(u)) == {-1.0, 1.0}
    assert (u > 0).sum() == 2 ** (order - 1)  # balance of an m-sequence
    # two-valued circular autocorrelation: N at lag 0, -1 elsewhere (only m-sequences have it)
    r = np.real(np.fft.ifft(np.abs(np.fft.fft(u)) ** 2))
    assert r[0] == pytest.approx(N)
    np.testing.assert_allclose(r[1:], -1.0, atol=1e-6)


def test_prbs_options():
    u = S.prbs(100.0, order=5, periods=2, bit_samples=3, amplitude=2.0, offset=1.0)
    assert u.size == 2 * 31 * 3 and set(np.unique(u)) == {-1.0, 3.0}
    np.testing.assert_array_equal(u[:93], u[93:])
    assert S.prbs(100.0, order=5, duration=1.0).size == 100
    with pytest.raises(ConfigError):
        S.prbs(1.0, order=40)
    with pytest.raises(ConfigError):
        S.prbs(1.0, order=4, seed=0)


def test_aprbs_levels_and_holds():
    u, info = S.aprbs(1000.0, 5.0, low=-2.0, high=3.0, min_hold=0.01, max_hold=0.05, seed=4, return_info=True)
    assert u.size == 5000 and u.min() >= -2.0 and u.max() <= 3.0
    holds = np.diff(np.concatenate((info["changes"], [u.size])))
    assert holds[:-1].min() >= 10 and holds.max() <= 50
    np.testing.assert_array_equal(u, S.aprbs(1000.0, 5.0, low=-2.0, high=3.0, min_hold=0.01, max_hold=0.05, seed=4))
    v = S.aprbs(1000.0, 5.0, low=0.0, high=1.0, levels=3, seed=1)
    assert set(np.unique(v)) <= {0.0, 0.5, 1.0}
    with pytest.raises(ConfigError):
        S.aprbs(1000.0, 1.0, low=1.0, high=0.0)


# ---------------------------------------------------------------------------------------------- properties
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=40, deadline=None)
@given(
    n0=st.integers(16, 600),
    lo=st.floats(0, 0.45),
    width=st.floats(0.01, 0.5),
    grid=st.sampled_from(S.GRIDS),
    amp=st.floats(1e-3, 1e3),
    rms=st.booleans(),
    phase=st.sampled_from(S.PHASES),
    seed=st.integers(0, 10),
)
def test_multisine_invariants(n0, lo, width, grid, amp, rms, phase, seed):
    fs = 1000.0
    fmin = lo * fs / 2
    fmax = min(fmin + width * fs / 2, 0.999 * fs / 2)
    try:
        u, info = S.multisine(
            fs,
            duration=n0 / fs,
            band=(fmin, fmax),
            amplitude=amp,
            rms=rms,
            grid=grid,
            phase=phase,
            seed=seed,
            return_info=True,
        )
    except ConfigError as e:  # only refusal allowed: no grid line in a narrow band
        assert "no " in str(e) and "grid line" in str(e)
        return
    m = info["excited_bins"]
    df = fs / n0
    assert np.all(m * df >= fmin - 1e-9) and np.all(m * df <= fmax + 1e-9) and np.all(2 * m < n0)
    assert {"full": True, "odd": np.all(m % 2 == 1), "odd-odd": np.all(m % 4 == 1)}[grid]
    level = np.sqrt(np.mean(u**2)) if rms else np.max(np.abs(u))
    assert level == pytest.approx(amp, rel=1e-9)
    X = np.abs(np.fft.rfft(u))
    others = np.setdiff1d(np.arange(X.size), m)
    assert X[m].min() > 0.999 * X[m].max()
    if others.size:
        assert X[others].max() < 1e-9 * X[m].max()
