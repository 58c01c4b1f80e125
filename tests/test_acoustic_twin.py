"""The acoustic twin end to end: time of flight, echoes, effects, protocols, calibration, sweep CLI."""

import json

import numpy as np
import pytest
from scipy.signal import hilbert

from sysid.errors import ConfigError
from twins.acoustic import AcousticTwin
from twins.acoustic.channel import wall_path_length
from twins.acoustic.fluids import water_sound_speed

FS = 100e6


@pytest.fixture(scope="module")
def bare():
    return AcousticTwin(effects=[])


# ------------------------------------------------------------------------------------------------ time of flight


def test_time_of_flight_through_100mm_water(bare):
    """Arrival-time difference between a 100 mm and a 0 mm gap, measured on the simulated response = d/c(T)."""
    tof = bare.time_of_flight() - bare.with_params(distance_m=0.0).time_of_flight()
    assert tof == pytest.approx(0.1 / water_sound_speed(24.0), rel=0.005)


def test_time_of_flight_temperature_sensitivity(bare):
    """dTOF/dT = −L/c² dc/dT ≈ −123 ns/K at 100 mm, 24 °C (notes B.5), central difference ±0.5 K."""
    slope = (
        bare.with_params(temperature_c=24.5).time_of_flight() - bare.with_params(temperature_c=23.5).time_of_flight()
    )
    assert slope == pytest.approx(-123e-9, rel=0.03)


def test_time_of_flight_linear_in_distance_with_slope_one_over_c(bare):
    d = np.array([0.05, 0.1, 0.15, 0.2, 0.3])
    tof = np.array([bare.with_params(distance_m=float(x)).time_of_flight() for x in d])
    slope, icpt = np.polyfit(d, tof, 1)
    assert slope == pytest.approx(1 / water_sound_speed(24.0), rel=0.002)
    assert np.max(np.abs(tof - (slope * d + icpt))) < 20e-9  # linear within 2 samples at 100 MHz
    assert icpt > 0  # the transducers' and plates' own group delay


def test_seawater_and_glycerol_change_time_of_flight(bare):
    tw = bare.with_params(fluid="glycerol")
    assert tw.time_of_flight() < bare.time_of_flight() - 10e-6  # 1912 m/s vs 1494 m/s: ≈ 15 µs earlier


# ------------------------------------------------------------------------------------------------ echoes


def _burst(n=20000, f0=1.1e6, width=3e-6, t0=10e-6):
    t = np.arange(n) / FS
    return 0.02 * np.exp(-0.5 * ((t - t0) / width) ** 2) * np.sin(2 * np.pi * f0 * t)


def test_wall_echo_appears_at_its_geometric_delay():
    p = dict(reverb_orders=0, wall_distance_m=0.03, wall_coupling=0.3)
    u = _burst()
    plain = AcousticTwin(effects=[]).with_params(**p).simulate(u, FS)
    echo = AcousticTwin(effects=["wall_echo"]).with_params(**p).simulate(u, FS)
    extra = echo - plain
    assert np.max(np.abs(extra)) > 0.01 * np.max(np.abs(plain))
    env_d, env_e = np.abs(hilbert(plain)), np.abs(hilbert(extra))
    delay = (np.argmax(env_e) - np.argmax(env_d)) / FS
    expected = (wall_path_length(0.1, 0.03) - 0.1) / water_sound_speed(24.0)
    assert delay == pytest.approx(expected, rel=0.01)


def test_reverberation_arrives_after_one_round_trip():
    """With 30 mm plates the echo off the steel face (R ≈ 0.94, flat) is 10 µs ahead of the plates' inner
    reverberation, so the first inter-plate echo peaks exactly one round trip 2L/c after the direct arrival.
    (With the thin default plates the stack's reflection has its own group delay of a few µs.)"""
    u = _burst(n=40000)
    p = dict(steel_thickness_m=0.03)
    y = AcousticTwin(effects=[]).with_params(reverb_orders=1, **p).simulate(u, FS)
    y0 = AcousticTwin(effects=[]).with_params(reverb_orders=0, **p).simulate(u, FS)
    env_r = np.abs(hilbert(y - y0))
    delay = (np.argmax(env_r) - np.argmax(np.abs(hilbert(y0)))) / FS
    assert delay == pytest.approx(2 * 0.1 / water_sound_speed(24.0), rel=0.01)


def test_crosstalk_arrives_before_the_acoustic_wave():
    u = _burst(n=5000)  # 50 µs: before the ≈ 76 µs arrival
    quiet = AcousticTwin(effects=[]).with_params(reverb_orders=0).simulate(u, FS)
    xt = AcousticTwin(effects=["crosstalk"]).with_params(reverb_orders=0).simulate(u, FS)
    assert np.max(np.abs(quiet)) < 1e-3 * np.max(np.abs(xt))
    assert np.max(np.abs(xt)) > 1e-3


# ------------------------------------------------------------------------------------------------ linear chain


def test_fft_convolution_equals_direct_convolution_and_no_wrap():
    tw = AcousticTwin(effects=[]).with_params(reverb_orders=1)
    fs = 20e6
    v = np.random.default_rng(0).standard_normal(3000)
    h = tw.impulse_response(fs)
    np.testing.assert_allclose(tw.linear(v, fs), np.convolve(v, h)[:3000], atol=1e-10 * np.abs(h).max())
    # h decays before the end of its grid (no circular wrap of a summed arrival)
    tail = h[-h.size // 10 :]
    assert np.sqrt(np.mean(tail**2)) < 1e-3 * np.max(np.abs(h))


def test_overlap_save_blocks_equal_direct_convolution(monkeypatch):
    import twins.acoustic.twin as tmod

    monkeypatch.setattr(tmod, "_OLS_MIN_BLOCK", 256)  # force many overlap-save blocks on a short record
    tw = AcousticTwin(effects=[]).with_params(reverb_orders=0)
    fs = 5e6
    h = tw.impulse_response(fs)
    v = np.random.default_rng(1).standard_normal(5 * h.size + 123)
    np.testing.assert_allclose(tw.linear(v, fs), np.convolve(v, h)[: v.size], atol=1e-10 * np.abs(h).max())


def test_simulate_is_measure_of_linear_of_amplifier():
    tw = AcousticTwin(seed=3)
    u = _burst(n=2000)
    fs = FS
    y = tw.simulate(u, fs)
    again = tw.measure(tw.linear(tw.amplifier(u), fs), fs, np.random.default_rng(3))
    np.testing.assert_array_equal(y, again)
    np.testing.assert_array_equal(y, AcousticTwin(seed=3).simulate(u, fs))  # seeded: reproducible


def test_measurement_noise_and_adc():
    tw = AcousticTwin(effects=["measurement_noise"]).with_params(noise_v=0.1)
    y = tw.measure(np.zeros(200000), FS, np.random.default_rng(0))
    assert np.std(y) == pytest.approx(0.1, rel=0.01)
    adc = AcousticTwin(effects=["adc_quantization"]).with_params(adc_bits=8, adc_range_v=1.0)
    q = adc.measure(np.linspace(-2, 2, 10001), FS)
    lsb = 2.0 / 256
    np.testing.assert_allclose(q / lsb, np.round(q / lsb), atol=1e-9)
    assert q.max() <= 1.0 - lsb + 1e-12 and q.min() >= -1.0
    assert len(np.unique(q)) == 256


def test_misalignment_loses_gain_growing_with_frequency(bare):
    f = np.array([0.9e6, 1.35e6])
    h0 = np.abs(bare.frequency_response(f, direct_only=True))
    mis = AcousticTwin(effects=["misalignment"]).with_params(misalignment_offset_m=2.5e-3, misalignment_tilt_deg=0.5)
    h1 = np.abs(mis.frequency_response(f, direct_only=True))
    loss = h1 / h0
    assert np.all(loss < 0.9)
    assert loss[1] < loss[0]


def test_time_of_flight_effects_share_an_ambiguity_group():
    groups = {AcousticTwin.EFFECTS[k].group for k in ("temperature_offset", "distance_offset", "fluid_mismatch")}
    assert groups == {"time_of_flight"}
    base = AcousticTwin(effects=[])
    for eff in ("temperature_offset", "distance_offset", "fluid_mismatch"):
        assert abs(AcousticTwin(effects=[eff]).time_of_flight() - base.time_of_flight()) > 50e-9, eff


def test_effect_catalog_complete():
    need = {
        "wall_echo",
        "amplifier_compression",
        "amplifier_even_distortion",
        "crosstalk",
        "temperature_offset",
        "distance_offset",
        "fluid_mismatch",
        "misalignment",
        "adc_quantization",
        "measurement_noise",
    }
    assert need <= set(AcousticTwin.EFFECTS)
    fields = set(AcousticTwin.Params.__dataclass_fields__)
    for e in AcousticTwin.EFFECTS.values():
        assert e.signature and set(e.params.values()) <= fields


# ------------------------------------------------------------------------------------------------ protocols


def test_chirp_100ms_protocol_and_recipe():
    tw = AcousticTwin()
    rec = tw.generate("thesis-chirp-100ms", duration=0.4e-3)
    assert rec.fs == FS and len(rec) == 40000
    assert np.ptp(rec.u) == pytest.approx(0.080, rel=1e-3)  # 80 mVpp
    pre = tw.generate("thesis-chirp-100ms", duration=0.4e-3, preprocess=True)
    assert pre.fs == pytest.approx(6.75e6) and len(pre) == 2000
    steps = [s["step"] for s in pre.meta["preprocessing"]]
    assert steps == ["moving_average", "resample", "bandpass", "truncate"]


def test_chirp_prefix_is_the_start_of_the_sysid_chirp():
    from sysid.signals.excitation import chirp
    from twins.acoustic.protocols import chirp_prefix

    full = chirp(2e6, 0.1, 900e3, 950e3, amplitude=0.04)  # 2e5 samples: cheap
    np.testing.assert_allclose(chirp_prefix(2e6, 0.1, 900e3, 950e3, 0.04, 5000), full[:5000], atol=1e-12)


def test_multisine_protocol_is_a_repeated_5000_point_piece():
    rec = AcousticTwin().generate("thesis-multisine", duration=1.2e-3, warmup_s=0.0)
    u = rec.u
    period = 50000  # 5000 points at 10 MS/s = 0.5 ms = 50 000 samples at 100 MHz
    np.testing.assert_allclose(u[:period], u[period : 2 * period], atol=1e-12)
    assert np.max(np.abs(u)) <= 0.4 + 1e-9
    spec = np.abs(np.fft.rfft(u[:period])) ** 2
    f = np.fft.rfftfreq(period, 1 / FS)
    inband = spec[(f >= 0.85e6) & (f <= 1.4e6)].sum() / spec.sum()
    assert inband > 0.8  # the truncation leaks some power outside the band, as in the dissertation


def test_chirp_1ms_protocol_repeats_every_ms():
    rec = AcousticTwin(effects=[]).generate("thesis-chirp-1ms", duration=2.0e-3, warmup_s=1e-3)
    assert np.ptp(rec.u) == pytest.approx(0.150, rel=1e-3)
    np.testing.assert_allclose(rec.u[:100000], rec.u[100000:200000], atol=1e-12)


def test_vna_sweep_matches_frequency_response_and_is_fast_enough_to_be_interactive():
    tw = AcousticTwin()
    rec = tw.generate("vna-sweep", points=2000)
    assert len(rec) == 2000 and rec.units["y"] == "dB"
    h = tw.frequency_response(rec.u, include_amplifier=False)
    np.testing.assert_allclose(rec.y, 20 * np.log10(np.abs(h)), atol=1e-9)
    pre = tw.generate("vna-sweep", points=200, preprocess=True)
    assert np.all(pre.y[pre.u > 1.6e6] < rec.y[::10][pre.u > 1.6e6])  # the recipe's filters cut out-of-band


def test_bad_protocol_options_refused():
    tw = AcousticTwin()
    with pytest.raises(ConfigError, match="valid"):
        tw.generate("thesis-chirp-1ms", bogus=1)
    with pytest.raises(ConfigError, match="valid"):
        tw.generate("nope")
    with pytest.raises(ConfigError, match="out of range"):
        AcousticTwin.from_options(set_=["distance_m=-1"])
    with pytest.raises(ConfigError, match="not one of"):
        AcousticTwin.from_options(set_=["fluid=honey"])


# ------------------------------------------------------------------------------------------------ calibration


def test_calibrate_vna_record_recovers_stack():
    truth = AcousticTwin.from_options(set_=["pzt_thickness_m=0.00212,steel_thickness_m=0.0064,output_gain=0.8"])
    rec = truth.generate("vna-sweep", f_start=0.85e6, f_stop=1.4e6, points=500, gated=True)
    res = AcousticTwin().calibrate(rec)
    assert res.fitted["pzt_thickness_m"] == pytest.approx(0.00212, rel=1e-4)
    assert res.fitted["steel_thickness_m"] == pytest.approx(0.0064, rel=1e-4)
    assert res.fitted["output_gain"] == pytest.approx(0.8, rel=1e-3)


def test_calibrate_time_record_from_h1_estimate():
    truth = AcousticTwin(effects=["measurement_noise"]).with_params(pzt_thickness_m=0.00213, reverb_orders=2)
    rec = truth.generate("thesis-chirp-1ms", duration=3e-3, warmup_s=1e-3, fs=20e6)
    start = AcousticTwin(effects=[]).with_params(reverb_orders=2)
    res = start.calibrate(rec, names=["pzt_thickness_m"])
    assert res.fitted["pzt_thickness_m"] == pytest.approx(0.00213, rel=3e-3)
    assert res.scores["estimation"]["r2"] > 0.9


# ------------------------------------------------------------------------------------------------ CLI


def test_sweep_cli_json(capsys):
    from benchmarks.cli import main

    assert main(["sweep", "acoustic", "distance_m=0.05,0.2", "--no-identify", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    rows = out["rows"]
    assert [r["value"] for r in rows] == [0.05, 0.2]
    for key in ("peak_frequency_hz", "peak_gain_db", "bandwidth_hz", "time_of_flight_s"):
        assert all(isinstance(r[key], float) for r in rows)
    assert rows[1]["time_of_flight_s"] - rows[0]["time_of_flight_s"] == pytest.approx(0.15 / 1494.0, rel=0.005)


def test_sweep_cli_report_and_errors(tmp_path, capsys):
    from benchmarks.cli import main

    assert main(["sweep", "acoustic", "fluid=water,glycerol", "--report", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "identified_model_r2" in text
    assert (tmp_path / "sweep_fluid_spectra.png").stat().st_size > 1000
    assert (tmp_path / "sweep_fluid_metrics.png").stat().st_size > 1000
    data = json.loads((tmp_path / "sweep_fluid.json").read_text())
    assert "identified_model_r2" in data["rows"][0]
    assert main(["sweep", "acoustic", "nope=1"]) == 2
    assert main(["sweep", "acoustic", "fluid=honey"]) == 2
    assert "valid" in capsys.readouterr().err


def test_calibrate_cli_on_a_vna_file(tmp_path, capsys):
    from benchmarks.cli import main
    from sysid.data.io import write_record

    truth = AcousticTwin.from_options(set_=["steel_thickness_m=0.0061"])
    write_record(truth.generate("vna-sweep", f_start=0.85e6, f_stop=1.4e6, points=400), tmp_path / "vna.npz")
    assert (
        main(
            [
                "calibrate",
                "acoustic",
                "--data",
                str(tmp_path / "vna.npz"),
                "--fit",
                "steel_thickness_m,output_gain",
                "--json",
                "-o",
                str(tmp_path / "p.json"),
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["parameters"]["steel_thickness_m"]["value"] == pytest.approx(0.0061, rel=1e-4)
    again = AcousticTwin.from_options(params_file=tmp_path / "p.json")
    assert again.params.steel_thickness_m == pytest.approx(0.0061, rel=1e-4)


def test_fmu_interface_stages():
    tw = AcousticTwin()
    h = tw.frequency_response(np.array([0.0, 940e3, 1162e3]))
    assert h.dtype == complex and h[0] == 0 and np.all(np.abs(h[1:]) > 0.1)
    assert tw.amplifier(np.array([0.01]))[0] == pytest.approx(2 * 10**2.5 * 0.01, rel=1e-4)
    with pytest.raises(NotImplementedError):
        tw.make_stepper(100e6)


def test_calibrate_time_of_flight_parameter_by_output_error():
    """A temperature offset only moves the phase: fitted on the time record (output error), not on |H|."""
    truth = AcousticTwin(effects=["measurement_noise", "temperature_offset"]).with_params(
        temperature_offset_k=1.7, reverb_orders=1
    )
    rec = truth.generate("thesis-chirp-1ms", duration=0.5e-3, warmup_s=1e-3, fs=20e6)
    start = AcousticTwin(effects=["temperature_offset"]).with_params(reverb_orders=1, temperature_offset_k=0.0)
    res = start.calibrate(rec, names=["temperature_offset_k"])
    assert res.fitted["temperature_offset_k"] == pytest.approx(1.7, abs=0.01)
    assert "output error" in res.message and res.twin.effects == start.effects
