"""Physics of the acoustic twin against closed forms and published numbers."""

import dataclasses

import numpy as np
import pytest
from scipy.signal import find_peaks

from twins.acoustic import AcousticTwin
from twins.acoustic.amplifier import amplifier_voltage
from twins.acoustic.channel import channel_parts, frequency_response, spreading_factor
from twins.acoustic.fluids import (
    FLUIDS,
    WATER_T2_TYPO_KWAVE,
    fluid_state,
    francois_garrison,
    water_absorption,
    water_density,
    water_sound_speed,
)
from twins.acoustic.layers import Layer, chain, input_impedance, layer_matrix, propagate_forward, slab_coefficients
from twins.acoustic.materials import PIEZOS, SOLIDS
from twins.acoustic.params import AcousticParams
from twins.acoustic.transducer import face_impedance, parallel_rc, plate_two_port, receive_voltage, transmit

# ------------------------------------------------------------------------------------------------ fluids


def test_water_sound_speed_marczak_published_values():
    assert water_sound_speed(24.0) == pytest.approx(1494.0, abs=0.5)  # notes B.4, Greenspan–Tschiegg 1494
    assert water_sound_speed(20.0) == pytest.approx(1482.34, abs=0.1)  # Del Grosso reference at 20 °C
    # k-Wave's T² typo (-5.779136e-2) is +0.12 m/s at 24 °C and misses the 20 °C reference by 0.12 m/s
    assert water_sound_speed(24.0, WATER_T2_TYPO_KWAVE) - water_sound_speed(24.0) == pytest.approx(0.1152, abs=2e-3)
    assert abs(water_sound_speed(20.0, WATER_T2_TYPO_KWAVE) - 1482.34) > 0.1


def test_water_density_and_absorption():
    assert water_density(24.0) == pytest.approx(997.29, abs=0.01)  # Jones & Harris (notes B.4)
    assert water_density(4.0) == pytest.approx(999.97, abs=0.01)  # maximum density of water
    a = water_absorption(1e6, 24.0)
    assert a / 1e12 == pytest.approx(22.4e-15, rel=0.01)  # notes B.5
    assert 20 * np.log10(np.e) * a == pytest.approx(0.194, abs=0.002)  # dB/m at 1 MHz
    assert water_absorption(1e6, 20.0) / 1e12 == pytest.approx(25.2e-15, rel=0.01)


def test_seawater_mackenzie_and_francois_garrison():
    sea = fluid_state("seawater", 24.0)
    assert sea.speed == pytest.approx(1531.9, abs=0.1)  # notes B.6 (Mackenzie 1981)
    assert sea.density == pytest.approx(1023.6, abs=0.5)  # UNESCO 1981
    db = 20 * np.log10(np.e) * francois_garrison(np.array([0.9e6, 1.0e6, 1.162e6, 1.35e6]), 24.0)
    np.testing.assert_allclose(db, [0.283, 0.321, 0.390, 0.483], atol=0.002)  # notes B.5
    fresh = 20 * np.log10(np.e) * francois_garrison(1e6, 24.0, salinity_psu=0.0)
    assert fresh == pytest.approx(0.196, abs=0.002)


def test_every_fluid_has_properties_and_temperature_law():
    for name in FLUIDS:
        a, mid, b = fluid_state(name, 23.0), fluid_state(name, 24.0), fluid_state(name, 25.0)
        assert 700 < a.density < 1300 and 900 < a.speed < 2000, name
        assert (b.speed - a.speed) / 2.0 == pytest.approx(mid.dc_dt, rel=0.02), name
        assert a.alpha(2e6) > a.alpha(1e6) > 0, name
    with pytest.raises(Exception, match="valid: water"):
        fluid_state("honey", 20.0)


# ------------------------------------------------------------------------------------------------ layers


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_energy_conserved_through_lossless_layers(seed):
    rng = np.random.default_rng(seed)
    f = np.linspace(0.1e6, 5e6, 301)
    layers = [Layer(rng.uniform(800, 9000), rng.uniform(1000, 6000), rng.uniform(1e-5, 1e-2)) for _ in range(4)]
    z1, z2 = 1.49e6, rng.uniform(1e6, 40e6)
    r, t = slab_coefficients(f, layers, z1, z2, area=rng.uniform(1e-5, 1e-2))
    np.testing.assert_allclose(np.abs(r) ** 2 + z1 / z2 * np.abs(t) ** 2, 1.0, atol=1e-12)
    assert np.ptp(np.abs(r)) > 0.1  # the stack really reflects, frequency-dependently


def test_lossy_layers_absorb_and_single_interface_closed_form():
    f = np.linspace(0.5e6, 2e6, 50)
    lossy = [Layer(1150, 2600, 2e-3, 10.0, 1.0)]
    r, t = slab_coefficients(f, lossy, 1.49e6, 1.49e6)
    assert np.all(np.abs(r) ** 2 + np.abs(t) ** 2 < 1.0)
    # zero-thickness layer: R and T of a plain water/steel interface, (Z2 - Z1)/(Z2 + Z1) and 2 Z2/(Z2 + Z1)
    z1, z2 = 1.49e6, 45.9e6
    r0, t0 = slab_coefficients(f, [Layer(7990, 5750, 0.0)], z1, z2)
    np.testing.assert_allclose(r0, (z2 - z1) / (z2 + z1), atol=1e-12)
    np.testing.assert_allclose(t0, 2 * z2 / (z2 + z1), atol=1e-12)


def test_half_wave_plate_is_transparent():
    st = SOLIDS["ss316"]
    d = st.speed / (2 * 1.0e6)
    r, t = slab_coefficients(np.array([1.0e6]), [Layer(st.density, st.speed, d)], 1.49e6, 1.49e6)
    assert abs(r[0]) < 1e-9 and abs(abs(t[0]) - 1) < 1e-9


# ------------------------------------------------------------------------------------------------ transducer


def test_free_pzt4_plate_resonances_match_notes():
    """Notes B.3 check 1: a free 2 mm PZT-4 plate has f_s/f_p = 1018/1151 kHz (min/max |Z|)."""
    f = np.linspace(0.8e6, 1.4e6, 60001)
    tp = plate_two_port(f, PIEZOS["pzt4"], 2e-3, 0.070 * 0.025, 0.0)
    z = np.abs(tp.z22 - tp.z12**2 / tp.z11)  # both faces free (front force 0)
    fs_, fp_ = f[np.argmin(z)], f[np.argmax(z)]
    assert fs_ == pytest.approx(1018e3, abs=3e3)
    assert fp_ == pytest.approx(1151e3, abs=3e3)
    # IEEE Std 176: k_t² = (π/2)(f_s/f_p) tan((π/2)(f_p − f_s)/f_p); notes: k_t = 0.505, and = e33/√(c33D ε33S)
    kt = np.sqrt(np.pi / 2 * fs_ / fp_ * np.tan(np.pi / 2 * (fp_ - fs_) / fp_))
    assert kt == pytest.approx(0.505, abs=0.01)
    assert kt == pytest.approx(PIEZOS["pzt4"].kt, abs=0.01)


def test_piezo_with_zero_coupling_is_a_passive_layer():
    f = np.linspace(0.3e6, 3e6, 200)
    pz = dataclasses.replace(PIEZOS["pzt4"], e33=0.0, q_m=1e12, tan_delta=0.0)
    area, t, zb = 1e-3, 2e-3, 3e6 * 1e-3
    tp = plate_two_port(f, pz, t, area, zb)
    m = layer_matrix(f, Layer(pz.density, pz.speed, t), area)
    np.testing.assert_allclose(tp.z11, input_impedance(m, zb), rtol=1e-9)
    np.testing.assert_allclose(tp.z12, 0.0, atol=1e-12)


def test_reciprocity_tx_and_rx_with_equal_50_ohm_ports():
    """Notes B.3 check 3: Tx p/V into 50 Ω and Rx V/p with a 50 Ω load have the same spectral shape."""
    f = np.linspace(0.6e6, 1.6e6, 400)
    p = AcousticParams(rx_load_ohm=50.0, rx_load_capacitance_f=0.0)
    parts = channel_parts(f, p)
    ratio = parts["t_tx"] / parts["r_v"]
    np.testing.assert_allclose(np.abs(ratio) / np.abs(ratio).mean(), 1.0, rtol=1e-9)


def test_fabry_perot_series_equals_full_transfer_matrix_chain():
    """The twin's Fabry–Pérot split of the fluid gap is an identity of the 1-D chain: compare with an
    independent full-chain computation (Tx drives the whole stack, state propagated to the Rx)."""
    f = np.linspace(0.7e6, 1.5e6, 801)
    p = AcousticParams(diffraction=False, reverb_orders=-1)
    h = frequency_response(f, p, include_amplifier=False)
    g = p.plate_width_m * p.plate_height_m
    ep, st = SOLIDS["epoxy"], SOLIDS[p.steel]
    fl = fluid_state(p.fluid, p.temperature_c)
    layers = [
        Layer(ep.density, ep.speed, p.epoxy_thickness_m, ep.alpha0_np_m, ep.alpha_power),
        Layer(st.density, st.speed, p.steel_thickness_m, st.alpha0_np_m, st.alpha_power),
    ]

    class _Fluid(Layer):
        def wavenumber(self, ff):
            return 2 * np.pi * ff / fl.speed - 1j * fl.alpha(ff)

    stack = layers + [_Fluid(fl.density, fl.speed, p.distance_m)] + layers[::-1]
    mats = [layer_matrix(f, lay, g) for lay in stack]
    tp = plate_two_port(f, PIEZOS[p.piezo], p.pzt_thickness_m, g, p.backing_rayl * g)
    zl = parallel_rc(f, p.rx_load_ohm, p.rx_load_capacitance_f)
    z_rx_face = face_impedance(tp, zl)
    z_front = input_impedance(chain(mats), z_rx_face)
    force, u, _ = transmit(tp, z_front, p.source_resistance_ohm)
    for m in mats:
        force, u = propagate_forward(m, force, u)
    v_rx = receive_voltage(tp, zl) * u
    np.testing.assert_allclose(h, v_rx, rtol=1e-8, atol=1e-12 * np.abs(v_rx).max())
    # and the explicit (compiled) sum converges to the closed form where |R_tx R_rx| e^{-2αL} has decayed
    parts = channel_parts(f, p)
    loop = np.abs(parts["r_tx"] * parts["r_rx"] * np.exp(-2j * parts["k"] * p.distance_m))
    ok = loop**401 < 1e-9
    assert ok.sum() > 100
    p_sum = dataclasses.replace(p, reverb_orders=400)
    np.testing.assert_allclose(
        frequency_response(f, p_sum, include_amplifier=False)[ok], h[ok], rtol=1e-6, atol=1e-7 * np.abs(h).max()
    )


def test_spreading_follows_the_aperture():
    """Near field for the 70 × 25 mm plates (≤ 0.3 dB at 100 mm), spherical 1/z far field for a small piston."""
    f = np.array([1.0e6])
    plate = AcousticParams()
    loss_db = -20 * np.log10(np.abs(spreading_factor(f, 0.1, 1494.0, plate)))
    assert 0.0 < loss_db[0] < 0.3
    small = AcousticParams(aperture="circular", aperture_radius_m=1e-3)
    d1, d2 = spreading_factor(f, 0.5, 1494.0, small), spreading_factor(f, 1.0, 1494.0, small)
    assert abs(d2[0]) / abs(d1[0]) == pytest.approx(0.5, rel=0.01)
    ka2_2z = (2 * np.pi * 1e6 / 1494.0) * 1e-3**2 / 2 / 1.0  # piston far field on axis: k a² / (2 z)
    assert abs(d2[0]) == pytest.approx(ka2_2z, rel=0.01)


# ------------------------------------------------------------------------------------------------ default stack


def test_default_stack_peaks_like_figure_3_9():
    f = np.linspace(0.9e6, 1.35e6, 9001)
    db = 20 * np.log10(np.abs(AcousticTwin().frequency_response(f, direct_only=True, include_amplifier=False)))
    idx, _ = find_peaks(db)
    top = np.sort(f[idx[np.argsort(db[idx])[::-1][:2]]])
    assert top[0] == pytest.approx(940e3, abs=10e3)
    assert top[1] == pytest.approx(1162e3, abs=15e3)


# ------------------------------------------------------------------------------------------------ amplifier


def _harmonics(y, fs, f0, n=6):
    spec = np.abs(np.fft.rfft(y)) / y.size
    k0 = int(round(f0 * y.size / fs))
    return np.array([spec[k0 * m] for m in range(1, n + 1)])


@pytest.mark.parametrize("model", ["rapp", "cubic"])
def test_compression_makes_odd_harmonics_only(model):
    fs, f0, n = 100e6, 1e6, 10000  # 100 whole periods
    x = 0.6 * np.sin(2 * np.pi * f0 * np.arange(n) / fs)  # 190 V: beyond A_sat = 105 V (cubic clips)
    h = _harmonics(amplifier_voltage(x, 50.0, model, 105.0, 2.5, 0.0), fs, f0)
    assert h[2] / h[0] > 1e-3  # 3rd
    assert h[4] / h[0] > 1e-6  # 5th
    assert h[1] / h[0] < 1e-12 and h[3] / h[0] < 1e-12  # no 2nd, 4th
    lin = _harmonics(amplifier_voltage(x, 50.0, None), fs, f0)
    assert h[0] < lin[0]  # gain compression
    assert lin[0] == pytest.approx(2 * 10**2.5 * 0.6 / 2, rel=1e-9)  # V_oc = 2 G_v x (one-sided amplitude/2)


def test_even_term_makes_even_harmonics():
    fs, f0, n = 100e6, 1e6, 10000
    x = 0.2 * np.sin(2 * np.pi * f0 * np.arange(n) / fs)
    h = _harmonics(amplifier_voltage(x, 50.0, None, 105.0, 2.5, 0.05), fs, f0)
    a = 10**2.5 * 0.2
    assert h[1] / h[0] == pytest.approx(0.05 * a / (2 * 105.0), rel=1e-6)  # HD2 = k2 a / (2 A_sat)
    assert h[2] / h[0] < 1e-12


def test_compiled_rapp_equals_its_formula():
    x = np.random.default_rng(0).standard_normal(20000) * 0.4
    v = 10**2.5 * x
    for p, k2 in ((2.5, 0.0), (2.3, 0.03)):
        ref = v / (1 + np.abs(v / 105.0) ** (2 * p)) ** (1 / (2 * p))
        ref = 2 * (ref + k2 * ref**2 / 105.0)
        np.testing.assert_allclose(amplifier_voltage(x, 50.0, "rapp", 105.0, p, k2), ref, rtol=1e-12, atol=1e-10)
