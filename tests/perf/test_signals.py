"""Speed of signal generation and preprocessing at the dissertation's sizes ("multisine of 10 M points
at 100 MHz, and decimation of 10 M points: a few seconds at most on 2 cores").

Run: ``make bench`` or
``python -m pytest tests/perf/test_signals.py --benchmark-enable -p no:cacheprovider -o addopts=""``.
"""

import numpy as np
import pytest
import scipy.signal

from sysid.signals import excitation as S
from sysid.signals import preprocess as P

N = 10_000_000  # 0.1 s at 100 MHz, the length of the dissertation's acoustic recordings
FS = 100e6


@pytest.fixture(scope="module")
def x10m():
    return np.random.default_rng(0).standard_normal(N)


def test_multisine_10M_points_100MHz(benchmark):
    """The dissertation's acoustic multisine: 45 000 lines 900-1350 kHz, one 0.1 s period at 100 MHz."""
    u = benchmark.pedantic(S.thesis_acoustic_multisine, kwargs={"seed": 0}, rounds=3, iterations=1)
    assert u.size == N


def test_multisine_direct_sum_reference(benchmark):
    """Reference: eq. (2-1) summed term by term in the time domain, 100 of the 45 000 lines on 10^6 of the
    10^7 samples (the full direct sum is 450 x 10 = 4500 times this work)."""
    t = np.arange(1_000_000) / FS
    f = 900e3 + 10.0 * np.arange(100)
    ph = np.random.default_rng(0).uniform(0, 2 * np.pi, f.size)

    def direct():
        u = np.zeros_like(t)
        for fk, pk in zip(f, ph):
            u += np.cos(2 * np.pi * fk * t + pk)
        return u

    benchmark.pedantic(direct, rounds=1, iterations=1)


def test_chirp_10M_points(benchmark):
    u = benchmark.pedantic(S.thesis_chirp, args=(0.1,), rounds=3, iterations=1)
    assert u.size == N


def test_decimate_10M_points(benchmark, x10m):
    """Anti-aliased decimation by 10 (the dissertation's 10 M -> 1 M), 0.1 dB / >= 60 dB FIR (399 taps)."""
    y = benchmark.pedantic(P.decimate, args=(x10m, 10), rounds=3, iterations=1)
    assert y.size == N // 10


def test_decimate_scipy_reference(benchmark, x10m):
    """Reference: scipy.signal.decimate(x, 10, ftype='fir') (its default FIR does not meet the 60 dB spec)."""
    benchmark.pedantic(scipy.signal.decimate, args=(x10m, 10), kwargs={"ftype": "fir"}, rounds=3, iterations=1)


def test_resample_10M_points_to_6p75MHz(benchmark, x10m):
    """100 MHz -> 6.75 MHz (x 27/400, dissertation §3.2), 15 897-tap FIR."""
    y = benchmark.pedantic(P.resample, args=(x10m, FS, 6.75e6), rounds=3, iterations=1)
    assert y.size == 675_000


def test_moving_average_10M_points(benchmark, x10m):
    """The dissertation's 100-point moving average on 10 M samples."""
    benchmark.pedantic(P.moving_average, args=(x10m, 100), rounds=3, iterations=1)


def test_bandpass_10M_points(benchmark, x10m):
    """Fifth-order zero-phase Butterworth band-pass 900-1350 kHz at 100 MHz on 10 M samples."""
    benchmark.pedantic(P.bandpass, args=(x10m, FS, 900e3, 1350e3), rounds=3, iterations=1)


def test_suggest_rate_10M_points(benchmark, x10m):
    """Aguirre's covariance rule on 10 M samples (two FFT autocovariances)."""
    benchmark.pedantic(P.suggest_rate, args=(x10m,), kwargs={"max_lag": 100_000}, rounds=1, iterations=1)


def test_hampel_10M_points(benchmark, x10m):
    """Hampel identifier (21-sample window, compiled running median/MAD) on 10 M samples, with its report."""
    benchmark.pedantic(P.hampel, args=(x10m,), rounds=1, iterations=1)
