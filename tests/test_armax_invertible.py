"""ARMAX by the prediction-error method keeps its noise polynomial C invertible: where the optimum it reaches has
C outside the unit circle, C is reflected inside (the same noise spectrum up to a gain) rather than the fit refused.
"""

from __future__ import annotations

import numpy as np
import pytest

from sysid.linear.arx import _invertible, reflect_inside


@pytest.mark.parametrize("c", [[1.0, 2.5], [1.0, -0.3, -1.8], [1.0, 0.5, 1.44, -0.2], [1.0, 0.4]])
def test_reflection_keeps_the_spectrum_shape_and_puts_every_root_inside(c):
    """|C'(e^{jω})| = |C(e^{jω})| / Π|r_i| over the reflected roots r_i (|1 − r z⁻¹| = |r| |1 − z⁻¹/r̄| on |z| = 1)."""
    c = np.asarray(c)
    cr = reflect_inside(c)
    assert cr[0] == pytest.approx(1.0) and len(cr) == len(c)
    assert _invertible(cr)
    roots = np.roots(c)
    gain = np.prod([abs(r) for r in roots if abs(r) > 1.0])
    w = np.linspace(0.0, np.pi, 257)
    z = np.exp(-1j * np.outer(w, np.arange(len(c))))
    assert np.abs(z @ cr) * gain == pytest.approx(np.abs(z @ c), rel=1e-9, abs=1e-12)
    if np.all(np.abs(roots) < 1.0):  # nothing to reflect: the polynomial is returned as it is
        assert cr == pytest.approx(c)


def test_pem_on_a_narrow_band_record_returns_an_invertible_c_instead_of_refusing():
    """Data set 1 of the dissertation's §5.1 on the acoustic twin (a nearly noise-free 900 kHz tone after a dead
    time): PEM's optimum has C outside the unit circle for ARMAX(n_y = 5, n_u = 1, n_e = 2); the fit used to be
    refused ('non-invertible'), now it returns an invertible C and says what it did."""
    from benchmarks.thesis.acoustic import dataset1
    from sysid.registry import get_identifier

    rec = dataset1(True)
    m = get_identifier("armax")(ny=5, nu=1, ne=2).fit(rec)
    c = np.r_[1.0, m.theta_[0][-2:]]  # the ARMAX terms are the y lags, the u lags, then the e lags
    assert _invertible(c)
    assert "reflected" in m.pem_status_
    yh = m.predict(rec, 1)
    assert np.all(np.isfinite(yh))
