"""The acoustic chain's caches change no simulation: cached and uncached outputs agree to 1e-12, and
the crosstalk taps added to the chain are the closed form ΔH = (g_r + τ_d·jω)·B(f)·G_out."""

from __future__ import annotations

import numpy as np
import pytest

from twins.acoustic import AcousticTwin
from twins.acoustic import chaincache as cc
from twins.acoustic.amplifier import amplifier_bandwidth

FS = 5e6


def _u(n: int = 4000, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return 0.3 * np.tanh(rng.standard_normal(n))


# configurations a diagnosis visits in turn: the core held while an input- or output-side effect moves, the
# core moved, effects switched on and off (each pair shares the cached chain or the cached h, or neither)
_STEPS = [
    ({}, None),
    ({"amp_sat_v": 80.0, "amp_smoothness": 1.3}, None),
    ({"amp_sat_v": 80.0, "amp_smoothness": 1.3, "amp_asymmetry": 0.2}, None),
    ({"wall_distance_m": 0.025, "wall_coupling": 0.2}, {"wall_echo"}),
    ({"wall_distance_m": 0.031, "wall_coupling": 0.2}, {"wall_echo"}),
    ({"wall_distance_m": 0.031, "wall_echo_path": "copy", "wall_echo_cutoff_hz": 1.5e6}, {"wall_echo"}),
    ({"crosstalk_capacitance_f": 5e-12}, {"crosstalk"}),
    ({"crosstalk_resistive": 0.03, "crosstalk_derivative_s": 4e-9}, {"crosstalk"}),
    ({"pzt_thickness_m": 2.17e-3}, None),
    ({"temperature_offset_k": 2.0}, {"temperature_offset"}),
    ({"output_gain": 1.1}, {"misalignment"}),
    ({}, None),
]


def test_cached_simulations_equal_uncached():
    base = AcousticTwin.from_options(seed=0, without=["measurement_noise", "adc_quantization"])
    u = _u()
    cc.CHAIN.clear()
    cc.LINEAR.clear()
    for _rep in range(2):  # the second pass runs on entries made by the first (and evicted ones)
        for changes, extra in _STEPS:
            tw = base.with_params(**changes)
            if extra:
                tw = tw.with_effects(set(tw.effects) | extra)
            y = tw.simulate(u, FS)
            with cc.disabled():
                ref = type(tw)(tw.params, tw.effects, tw.seed).simulate(u, FS)
            scale = float(np.max(np.abs(ref)))
            assert scale > 0
            np.testing.assert_allclose(y, ref, rtol=0, atol=1e-12 * scale, err_msg=str(changes))
    assert cc.CHAIN.hits > 0 and cc.LINEAR.hits > 0  # the cache was used, not bypassed


def test_cache_entries_are_read_only():
    tw = AcousticTwin.from_options(seed=0)
    h = tw.impulse_response(FS)
    with pytest.raises(ValueError):
        h[0] = 1.0


def test_crosstalk_taps_closed_form():
    """The in-phase and derivative taps add (g_r + τ_d·jω) times the amplifier bandwidth B(f) and the output
    gain to H, and nothing else (the capacitive path set to zero)."""
    tw = AcousticTwin.from_options(effects="crosstalk", seed=0, set_=["crosstalk_capacitance_f=0", "output_gain=1.3"])
    f = np.linspace(0.2e6, 2.4e6, 301)
    g, tau = 0.04, 6e-9
    dh = tw.with_params(crosstalk_resistive=g, crosstalk_derivative_s=tau).frequency_response(
        f
    ) - tw.frequency_response(f)
    want = (g + tau * 2j * np.pi * f) * amplifier_bandwidth(f, tw.params.amp_f_low_hz, tw.params.amp_f_high_hz) * 1.3
    np.testing.assert_allclose(dh, want, rtol=1e-9, atol=1e-12)
    # without the effect the taps do nothing
    off = AcousticTwin.from_options(effects="none", seed=0, set_=["crosstalk_resistive=0.2"])
    np.testing.assert_array_equal(
        off.frequency_response(f), off.with_params(crosstalk_resistive=0.0).frequency_response(f)
    )


def test_wall_echo_copy_is_a_delayed_copy_of_the_received_signal():
    """Variant ``copy``: H = H₀·(1 + a·e^{−jωΔτ}/(1 + jf/f_e)) with Δτ = (√(L² + 4w²) − L)/c, a = R·κ."""
    tw = AcousticTwin.from_options(effects="none", seed=0)
    f = np.linspace(0.3e6, 2.4e6, 211)
    w, a, fe = 0.028, 0.9 * 0.2, 2.0e6
    echo = tw.with_params(
        wall_distance_m=w, wall_reflection=0.9, wall_coupling=0.2, wall_echo_path="copy", wall_echo_cutoff_hz=fe
    ).with_effects({"wall_echo"})
    L, c = tw.params.distance_m, tw.spectrum_metrics(points=16)["sound_speed_m_s"]
    dtau = (np.hypot(L, 2 * w) - L) / c
    h0 = tw.frequency_response(f)
    want = h0 * (1 + a * np.exp(-2j * np.pi * f * dtau) / (1 + 1j * f / fe))
    np.testing.assert_allclose(echo.frequency_response(f), want, rtol=1e-9, atol=1e-12 * np.abs(h0).max())
