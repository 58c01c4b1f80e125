"""Amplifier compression as a family: the Rapp curve with its smoothness spanning tanh-like to a hard
clip matches the closed-form curves of a tanh limiter, a cubic soft clip up to its turning point and a hard
clip within 1 % of their RMS; the asymmetry sets the two saturation levels; the hard-clip limit is exact."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from twins.acoustic.amplifier import amplifier_voltage
from twins.acoustic.params import AcousticParams
from twins.base import param_info

_P = param_info(AcousticParams)


def _family(x, sat, p, asym=0.0):
    """The matched-load voltage of the family at 0 dB gain (V_oc/2)."""
    return 0.5 * amplifier_voltage(x, 0.0, "rapp", sat, p, 0.0, asym)


def _fit(x, y):
    """Least squares over (A_sat, p) within the parameters' documented ranges, from a few starts."""
    lo_p, hi_p = _P["amp_smoothness"].bounds()
    best = None
    for p0 in (0.7, 1.3, 3.0, 10.0, 40.0):
        r = least_squares(
            lambda th: _family(x, th[0], th[1]) - y, [np.max(np.abs(y)), p0], bounds=([1e-3, lo_p], [1e3, hi_p])
        )
        if best is None or r.cost < best.cost:
            best = r
    return best.x, float(np.sqrt(np.mean(best.fun**2)) / np.sqrt(np.mean(y**2)))


CURVES = {
    # name: (curve of the drive v in [−1, 1], the compression at the peak it gives)
    "tanh (18 % at the peak)": lambda v: 0.62 * np.tanh(v / 0.62),
    "tanh (strong)": lambda v: 0.25 * np.tanh(v / 0.25),
    "cubic up to its turning point": lambda v: v - v**3 / 3.0,
    "cubic (20 % at the peak)": lambda v: v - v**3 / (3 * 1.3**2),
    "hard clip at 0.7": lambda v: np.clip(v, -0.7, 0.7),
    "hard clip at 0.4": lambda v: np.clip(v, -0.4, 0.4),
}


@pytest.mark.parametrize("name", list(CURVES))
def test_family_matches_closed_form_limiters(name):
    v = np.linspace(-1.0, 1.0, 2001)
    y = CURVES[name](v)
    (sat, p), err = _fit(v, y)
    assert err < 0.01, (name, err, sat, p)


def test_hard_clip_limit_is_exact_and_finite():
    v = np.array([-1e6, -3.0, -1.5, 1.5, 3.0, 1e6])  # 1e6: |v/A|^128 overflows, the limit ±A is taken
    out = _family(v, 1.0, 64.0)
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(np.abs(out), 1.0, rtol=2e-3)
    assert np.all(np.abs(out) <= 1.0)


def test_asymmetry_sets_two_saturation_levels():
    v = np.array([-50.0, 50.0])
    out = _family(v, 2.0, 3.0, asym=0.25)
    np.testing.assert_allclose(out, [-2.0 * 0.75, 2.0 * 1.25], rtol=1e-6)
    # monotone across zero, and odd again at a = 0
    x = np.linspace(-10, 10, 4001)
    assert np.all(np.diff(_family(x, 2.0, 1.5, asym=0.3)) > 0)
    np.testing.assert_allclose(_family(-x, 2.0, 1.5), -_family(x, 2.0, 1.5), rtol=0, atol=1e-15)


def test_cubic_variant_asymmetry_matches_its_formula():
    v = np.linspace(-300.0, 300.0, 61)
    a, sat = 0.2, 105.0
    v0 = np.where(v > 0, 1.5 * sat * (1 + a), 1.5 * sat * (1 - a))
    vc = np.clip(v, -v0, v0)
    np.testing.assert_allclose(
        0.5 * amplifier_voltage(v, 0.0, "cubic", sat, 2.5, 0.0, a), vc - vc**3 / (3 * v0**2), rtol=1e-12
    )
