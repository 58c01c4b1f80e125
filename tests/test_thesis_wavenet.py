"""The wavelet-network NARX beside Table 5.2's NARX lines (benchmarks/thesis/wavenet.py): exact on a linear system
(its linear term is the least-squares ARX), and its wavelet units fit a static nonlinearity the linear term cannot."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.thesis.wavenet import WaveletNARX
from sysid.data.record import Record
from sysid.evaluation.metrics import r2


def _system(nonlinear: bool, n: int = 1500) -> Record:
    """y(t) = 0.6 y(t−1) − 0.2 y(t−2) + g(u(t−1)), g(u) = u (linear) or u + 0.8 exp(−4u²) (a bump)."""
    rng = np.random.default_rng(3)
    u = rng.uniform(-1.0, 1.0, n)
    g = u + (0.8 * np.exp(-4.0 * u**2) if nonlinear else 0.0)
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 0.6 * y[t - 1] - 0.2 * y[t - 2] + g[t - 1]
    return Record(u=u, y=y, fs=1.0)


def test_linear_system_is_reproduced_in_free_run():
    rec = _system(False)
    m = WaveletNARX(ny=2, nu=1, units=4).fit(rec)
    assert r2(rec.output, m.predict(rec, None), m.max_lag_) > 1 - 1e-9


def test_wavelet_units_fit_the_nonlinearity_the_linear_term_leaves():
    rec = _system(True)
    lin = WaveletNARX(ny=2, nu=1, units=0).fit(rec)
    wav = WaveletNARX(ny=2, nu=1, units=10).fit(rec)
    e_lin = rec.output[2:] - lin.predict(rec, 1)[2:]
    e_wav = rec.output[2:] - wav.predict(rec, 1)[2:]
    assert np.std(e_wav) < 0.4 * np.std(e_lin)  # 10 radial units in 3 dimensions: 0.27 measured
    frs_lin = r2(rec.output, lin.predict(rec, None), lin.max_lag_)
    frs_wav = r2(rec.output, wav.predict(rec, None), wav.max_lag_)
    assert frs_wav > 0.98 and 1 - frs_wav < 0.5 * (1 - frs_lin), (frs_wav, frs_lin)
    assert len(wav.centres_) == 10 and wav.n_parameters_ > 10
    with pytest.raises(ValueError, match="horizon"):
        wav.predict(rec, 5)
