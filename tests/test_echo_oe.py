"""oe-echo (sysid/linear/echo_oe.py): an output-error model whose denominator holds one round trip of an echo.

Checked against closed forms: a system B/(F − q^−τ C) written out here is found again — its delay and round trip
from the data (cepstrum), its frequency response to 1e-6 from noise-free data — and a system without an echo gives
no echo term. Stability holds by the loop-gain bound whatever the data.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from sysid.base import load_model
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.linear.echo_oe import EchoOE, echo_lags

NK, TAU = 30, 200
B = np.array([0.5, 0.3, -0.2])
F = np.array([1.0, -0.5, 0.2])
C = np.array([0.05, 0.3, 0.05])  # lags TAU-1 .. TAU+1; max |C/F| ≈ 0.57 < 1: a stable reverberation


def true_polys(echo: bool = True):
    b = np.r_[np.zeros(NK), B]
    a = np.zeros(TAU + 2)
    a[: F.size] = F
    if echo:
        a[TAU - 1 : TAU + 2] -= C
    return b, a


def record(n: int, seed: int, echo: bool = True, noise: float = 0.0) -> Record:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = lfilter(*true_polys(echo), u)
    return Record(u=u, y=y + noise * rng.standard_normal(n), fs=1.0)


def response(b, a, w):
    z = np.exp(-1j * w)
    return np.polyval(b[::-1], z) / np.polyval(a[::-1], z)


@pytest.fixture(scope="module")
def fitted():
    return EchoOE(nb=16, nf=2, echo_width=3).fit(record(6000, 0))


def test_delay_and_round_trip_are_found_in_the_data():
    found = echo_lags([record(6000, 0)])
    assert found["echo_lag"] == TAU and found["echo_snr"] > 8
    assert NK - 8 <= found["onset"] <= NK  # the envelope of a band-limited estimate rises a little early
    assert echo_lags([record(6000, 0, echo=False)])["echo_lag"] == 0  # no ripple on log|G|: no echo


def test_the_true_system_is_learned_exactly_from_noise_free_data(fitted):
    s = fitted.structure_
    assert s["echo_lag"] == TAU and s["nk"] <= NK and s["nk"] + s["nb"] >= NK + B.size
    w = np.linspace(0.01, np.pi - 0.01, 400)
    G_true = response(*true_polys(), w)
    G = fitted.frequency_response(w / (2 * np.pi), 1.0)["G"]
    assert np.max(np.abs(G - G_true) / np.abs(G_true)) < 1e-6
    assert fitted.loop_gain_ < 1.0
    val = record(3000, 1)
    assert fitted.score(val) > 1 - 1e-10
    assert f"echo round trip {TAU} samples (found: cepstral peak" in fitted.summary()


def test_noisy_data_give_the_response_to_the_noise_level():
    m = EchoOE(nb=16, nf=2, echo_width=3).fit(record(6000, 2, noise=0.05))
    w = np.linspace(0.01, np.pi - 0.01, 400)
    G_true = response(*true_polys(), w)
    G = m.frequency_response(w / (2 * np.pi), 1.0)["G"]
    assert np.sqrt(np.mean(np.abs(G - G_true) ** 2)) / np.sqrt(np.mean(np.abs(G_true) ** 2)) < 0.03


def test_without_an_echo_the_model_is_an_output_error_model():
    m = EchoOE(nb=16, nf=2, echo_width=3).fit(record(6000, 3, echo=False))
    assert m.structure_["echo_lag"] == 0 and m.c_.size == 0 and m.n_parameters_ == 16 + 2
    assert "no echo term" in m.summary()
    w = np.linspace(0.01, np.pi - 0.01, 200)
    G = m.frequency_response(w / (2 * np.pi), 1.0)["G"]
    G_true = response(*true_polys(echo=False), w)
    assert np.max(np.abs(G - G_true) / np.abs(G_true)) < 1e-6


def test_the_model_stays_stable_on_data_it_cannot_explain():
    """A nonlinear system with a spurious echo lag: whatever is fitted keeps |C/F| < 1, so a long free run from
    zero initial conditions stays bounded."""
    rng = np.random.default_rng(4)
    u = rng.standard_normal(4000)
    y = np.tanh(lfilter([0, 0.8], [1, -0.6], u)) ** 3
    m = EchoOE(nb=4, nf=2, nk=1, echo_lag=60, echo_width=2).fit(Record(u=u, y=y, fs=1.0))
    assert m.loop_gain_ < 1.0
    free = m.predict(rng.standard_normal(50_000))
    assert np.isfinite(free).all() and np.max(np.abs(free)) < 100 * np.max(np.abs(y))


def test_save_and_load_predict_identically(fitted, tmp_path):
    val = record(1000, 5)
    for suffix in (".npz", ".json"):
        m2 = load_model(fitted.save(tmp_path / f"m{suffix}"))
        assert np.array_equal(m2.predict(val, None), fitted.predict(val, None))
        assert m2.describe()["orders"]["echo_lag"] == TAU


def test_bad_input_is_refused_with_one_line():
    rec = record(2000, 6)
    with pytest.raises(ConfigError, match="one input and one output"):
        EchoOE().fit(Record(u=np.c_[rec.u, rec.u], y=rec.y, fs=1.0))
    with pytest.raises(ConfigError, match="nb must be an integer >= 1"):
        EchoOE(nb=0).fit(rec)
    with pytest.raises(ConfigError, match="echo_lag must be an integer >= 0"):
        EchoOE(echo_lag=-3).fit(rec)
    with pytest.raises(ConfigError, match="must exceed nf"):
        EchoOE(nb=4, nf=2, nk=1, echo_lag=10, echo_width=25).fit(rec)
    with pytest.raises(DataError, match="too few"):
        EchoOE(nb=4, nf=2, nk=1, echo_lag=TAU, echo_width=3).fit(record(150, 7))
    with pytest.raises(DataError, match="excites"):
        EchoOE().fit(Record(u=np.zeros(2000), y=rec.y, fs=1.0))
    with pytest.raises(ConfigError, match="not fitted"):
        EchoOE().predict(rec, None)
