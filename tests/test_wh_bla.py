"""Wiener–Hammerstein from the best split of the BLA (``wh-bla``): the blocks' exact Jacobian, exact recovery of a
noise-free Wiener–Hammerstein system, persistence, the per-sample stepper, refusals."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from sysid.base import load_model
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.nonlinear import wh_blocks as wb
from sysid.nonlinear.wiener_hammerstein import WienerHammerstein
from sysid.stepper import make_stepper


def true_system(u: np.ndarray) -> np.ndarray:
    """G1 = q⁻¹(1 + 0.5 q⁻¹)/(1 − 1.2 q⁻¹ + 0.5 q⁻²), f(x) = x + 0.3 x² − 0.2 x³ (a cubic: a cubic spline holds it
    exactly) of x / 4, G2 = (1 − 0.3 q⁻¹)/(1 − 0.5 q⁻¹ + 0.3 q⁻²), from rest."""
    x = np.r_[0.0, lfilter([1.0, 0.5], [1.0, -1.2, 0.5], u)[:-1]]
    x = x / 4.0  # RMS about 0.7: the BLA keeps the gain 1 − 0.6 E[x²] ≈ 0.7 far from zero
    w = x + 0.3 * x**2 - 0.2 * x**3
    return lfilter([1.0, -0.3], [1.0, -0.5, 0.3], w)


def record(n: int, seed: int, scale: float = 1.0) -> Record:
    u = scale * np.random.default_rng(seed).standard_normal(n)
    return Record(u=u, y=true_system(u), fs=1.0)


@pytest.fixture(scope="module")
def fitted():
    return WienerHammerstein(nb=3, nf=4, nk=1, knots=6, extra_zeros=1, warmup=10, max_nfev=300).fit(record(4000, 0))


def test_jacobian_equals_finite_differences():
    rng = np.random.default_rng(3)
    u = rng.standard_normal(600)
    g1 = wb.Filter(np.array([0.8, 0.3, -0.1]), np.array([1.0, -0.9, 0.3]), nk=2)
    g2 = wb.Filter(np.array([1.0, 0.4]), np.array([1.0, -0.6]), nk=1)
    f = wb.Spline.at_quantiles(g1(u), 5, 0.3)
    c = rng.standard_normal(f.n)
    free1, free2 = np.array([0, 2]), np.array([1])
    th = np.concatenate([g1.b[free1], g1.a[1:], c, g2.b[free2], g2.a[1:]])

    def sim(t):
        b1 = g1.b.copy()
        b1[free1] = t[:2]
        a1 = np.r_[1.0, t[2:4]]
        cc = t[4 : 4 + f.n]
        b2 = g2.b.copy()
        b2[free2] = t[4 + f.n : 5 + f.n]
        a2 = np.r_[1.0, t[5 + f.n :]]
        return wb.simulate(wb.Filter(b1, a1, 2), f, cc, wb.Filter(b2, a2, 1), u)[0]

    yh, J = wb.jacobian(g1, f, c, g2, u, free1, free2)
    np.testing.assert_allclose(yh, sim(th), rtol=0, atol=1e-12)
    h = 1e-6
    fd = np.column_stack([(sim(th + h * e) - sim(th - h * e)) / (2 * h) for e in np.eye(th.size)])
    np.testing.assert_allclose(J, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_spline_holds_a_cubic_and_continues_by_its_tangents():
    x = np.linspace(-2.0, 2.0, 400)
    f = wb.Spline.at_quantiles(x, 4, 0.5)
    target = x + 0.3 * x**2 - 0.2 * x**3
    c = np.linalg.lstsq(f.basis(x), target, rcond=None)[0]
    np.testing.assert_allclose(f(x, c), target, atol=1e-10)
    xo = np.array([f.hi + 1.0])  # one beyond the end: the tangent there
    slope = 1 + 0.6 * f.hi - 0.6 * f.hi**2
    end = f.hi + 0.3 * f.hi**2 - 0.2 * f.hi**3
    np.testing.assert_allclose(f(xo, c), end + slope, atol=1e-9)
    np.testing.assert_allclose(f.basis(xo) @ c, end + slope, atol=1e-9)


def test_root_groups_keep_conjugate_pairs_together():
    groups = wb.root_groups(np.roots(np.poly([0.5 + 0.2j, 0.5 - 0.2j, -0.3])))
    assert sorted(len(g) for g in groups) == [1, 2]
    assert len(list(wb.splits(np.array([0.1]), np.array([0.5 + 0.2j, 0.5 - 0.2j, -0.3])))) == 2**3


def test_recovers_a_noise_free_wiener_hammerstein_system(fitted):
    """From the BLA's split the refinement reaches the system itself: the free run on new data inside the
    estimation data's range equals it. The best split gives both BLA zeros to G1, so G2's zero comes from the
    extra numerator coefficient; the knots are placed again once the refinement has moved G1's gain."""
    val = record(3000, 1, scale=0.8)
    yh = fitted.predict(val, None)
    rel = np.sqrt(np.mean((yh - val.y)[10:] ** 2)) / np.std(val.y)
    assert rel < 1e-6, rel
    assert fitted.optimisation_["converged"] and fitted.optimisation_["rms"] < 1e-12
    assert fitted.split_ == {**fitted.split_, "g1_poles": 2, "g2_poles": 2}
    zeros = np.r_[fitted.g1_.zeros(), fitted.g2_.zeros()]
    for z in (-0.5, 0.3):
        assert np.min(np.abs(zeros - z)) < 1e-6
    poles = sorted(abs(p) for p in np.r_[fitted.g1_.poles(), fitted.g2_.poles()])
    np.testing.assert_allclose(
        poles, sorted(np.abs(np.r_[np.roots([1, -1.2, 0.5]), np.roots([1, -0.5, 0.3])])), atol=1e-6
    )


def test_save_load_predicts_identically(fitted, tmp_path):
    val = record(500, 2)
    for suffix in (".npz", ".json"):
        m = load_model(fitted.save(tmp_path / f"wh{suffix}"))
        np.testing.assert_array_equal(m.predict(val, None), fitted.predict(val, None))
        assert m.n_parameters_ == fitted.n_parameters_
    assert fitted.describe()["g1"]["nk"] == 1


def test_stepper_reproduces_the_free_run(fitted):
    u = np.random.default_rng(4).standard_normal(300)
    st = make_stepper(fitted)
    stepped = np.array([st.step(v) for v in u])
    free = fitted.predict(u)  # input only: from rest, the first max_lag_ outputs are zeros
    np.testing.assert_allclose(stepped, free, rtol=0, atol=1e-12)


def test_refuses_bad_options_and_data():
    est = record(400, 0)
    with pytest.raises(ConfigError, match="knots"):
        WienerHammerstein(knots=0).fit(est)
    with pytest.raises(ConfigError, match="xtol"):
        WienerHammerstein(xtol=-1.0).fit(est)
    two = Record(u=np.column_stack([est.u, est.u[::-1]]), y=est.y, fs=1.0)
    with pytest.raises(DataError, match="one input"):
        WienerHammerstein().fit(two)
    with pytest.raises(ConfigError, match="splits"):
        WienerHammerstein(nb=13, nf=12, split_samples=300, warmup=5).fit(record(2000, 0))
