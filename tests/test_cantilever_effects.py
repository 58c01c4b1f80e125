"""Each effect of the cantilever catalog, switched on alone over the noise-free core, changes the output in
its stated way and not where it should not."""

import math

import numpy as np
import pytest
from scipy.signal import welch

from benchmarks.cli.list_cmd import collect
from twins.cantilever import CantileverTwin
from twins.cantilever.figures import last_period, loop_metrics

FS = 10_000.0


def sine(f, periods, fs=FS, amp=100.0, offset=0.0):
    n = int(round(periods * fs / f))
    return offset + amp * np.sin(2 * np.pi * f * np.arange(n) / fs)


def pair(effect, u, fs=FS, base=(), **params):
    """Outputs without and with ``effect`` (core + ``base`` effects) for input ``u``."""
    off = CantileverTwin(effects=list(base)).with_params(**params)
    on = off.with_effects(set(base) | {effect})
    return off.simulate(u, fs), on.simulate(u, fs)


def test_catalog_complete_with_params_signatures_and_default():
    required = {
        "creep",
        "rate_dependent_hysteresis",
        "asymmetric_hysteresis",
        "second_mode",
        "sensor_lowpass",
        "sensor_quantization",
        "input_delay",
        "thermal_drift",
        "saturation",
        "measurement_noise",
    }
    assert required <= set(CantileverTwin.EFFECTS)
    fields = set(CantileverTwin.Params.__dataclass_fields__)
    for e in CantileverTwin.EFFECTS.values():
        assert e.signature and "\n" not in e.signature
        assert e.params and set(e.params.values()) <= fields, e.id
    assert CantileverTwin.default_effects() == {
        "creep",
        "second_mode",
        "sensor_lowpass",
        "sensor_quantization",
        "measurement_noise",
    }
    rows = [r for r in collect("effects") if r["twin"] == "cantilever"]
    assert {r["id"] for r in rows if r["default_on"]} == CantileverTwin.default_effects()
    assert "Default configuration" in CantileverTwin.__doc__


def test_creep_slow_tail_after_steps_nothing_at_rest():
    fs = 1000.0
    u = np.r_[np.zeros(500), np.full(5000, 60.0)]
    off, on = pair("creep", u, fs)
    assert np.array_equal(off[:500], on[:500])  # u = 0: identical
    d = on - off
    assert d[600] > 0 and d[-1] > 2 * d[600]  # grows over seconds after the step
    assert np.all(np.diff(d[510:]) >= -1e-12)  # monotone tail


def test_second_mode_only_at_high_frequency():
    u_slow = sine(2.0, 2, 2000.0)
    off, on = pair("second_mode", u_slow, 2000.0)
    assert np.max(np.abs(on - off)) < 2e-3 * np.ptp(off)
    rec = CantileverTwin().generate("thesis-multisine", duration_s=2.0)
    off, on = pair("second_mode", rec.u)
    f, p = welch(on - off, fs=FS, nperseg=2048)
    f2 = CantileverTwin().params.f1_hz * CantileverTwin().params.mode_ratio
    hi = f > 2000
    assert f[hi][np.argmax(p[hi])] == pytest.approx(f2, rel=0.05)


def test_sensor_lowpass_butterworth_phase_and_nothing_at_low_frequency():
    off, on = pair("sensor_lowpass", sine(2.0, 2, 2000.0), 2000.0)
    assert np.max(np.abs(on - off)) < 2e-3 * np.ptp(off)
    f, fs = 500.0, 50_000.0
    u = sine(f, 50, fs)
    off, on = pair("sensor_lowpass", u, fs)
    sl = last_period(u.size, fs, f)
    lag = loop_metrics(u[sl], on[sl], f, fs)["phase_deg"] - loop_metrics(u[sl], off[sl], f, fs)["phase_deg"]
    r = f / CantileverTwin().params.sensor_bandwidth_hz
    assert lag == pytest.approx(math.degrees(math.atan2(math.sqrt(2) * r, 1 - r * r)), abs=0.2)


def test_quantization_on_grid_and_within_half_step():
    u = sine(20.0, 3)
    tw = CantileverTwin(effects=[])
    off, on = pair("sensor_quantization", u)
    q = tw.params.quant_um
    assert np.allclose(on / q, np.round(on / q), atol=1e-6)
    assert np.max(np.abs(on - off)) <= q / 2 + 1e-12


def test_measurement_noise_white_gaussian_sigma_uncorrelated_with_input():
    u = sine(5.0, 10, FS)
    off, on = pair("measurement_noise", u)
    e = on - off
    sigma = CantileverTwin().params.noise_um
    assert np.std(e) == pytest.approx(sigma, rel=0.03)
    assert abs(np.mean(e)) < 4 * sigma / np.sqrt(e.size)
    assert abs(np.corrcoef(e, u)[0, 1]) < 0.03
    assert abs(np.corrcoef(e[1:], e[:-1])[0, 1]) < 0.03


def test_input_delay_is_a_pure_fractional_delay():
    tau = 2.5 / FS
    u = sine(20.0, 3)
    off, on = pair("input_delay", u, input_delay_s=tau)
    assert np.all(on[:2] == 0.0)  # nothing arrives before τ (u[0] = 0 anyway; u[1] > 0 is still in the line)
    t = np.arange(u.size) / FS
    shifted = np.interp(t - tau, t, off, left=0.0)
    assert np.max(np.abs(on[10:] - shifted[10:])) < 1e-3 * np.ptp(off)
    assert np.max(np.abs(on - off)) > 1e-3 * np.ptp(off)  # it does change the output


def test_thermal_drift_exactly_additive_and_input_independent():
    p = CantileverTwin().params
    for u in (np.zeros(3000), sine(20.0, 6)):
        off, on = pair("thermal_drift", u, thermal_tau_s=0.1)
        t = np.arange(u.size) / FS
        np.testing.assert_allclose(on - off, p.thermal_drift_um * (1 - np.exp(-t / 0.1)), atol=1e-12)


def test_saturation_compresses_large_amplitudes_only():
    small = sine(2.0, 2, 2000.0, amp=10.0)
    off, on = pair("saturation", small, 2000.0)
    assert np.max(np.abs(on - off)) < 1e-3 * np.ptp(off)
    big = sine(2.0, 2, 2000.0, amp=100.0)
    off, on = pair("saturation", big, 2000.0)
    assert on.max() < off.max() - 0.01 * np.ptp(off) and on.min() > off.min() + 0.01 * np.ptp(off)
    d = np.abs(on - off)
    assert d[np.abs(big) < 30].max() < 0.2 * d[np.abs(big) > 90].max()


@pytest.mark.parametrize("model", ["bouc-wen", "prandtl-ishlinskii"])
def test_rate_dependent_hysteresis_widens_loops_at_high_rate_only(model):
    def width(tw_eff, f, fs, periods):
        u = sine(f, periods, fs)
        y = CantileverTwin(effects=tw_eff).with_params(hysteresis=model).simulate(u, fs)
        sl = last_period(u.size, fs, f)
        return loop_metrics(u[sl], y[sl], f, fs)["area"]

    slow = [width(e, 1.0, 2000.0, 2) for e in ([], ["rate_dependent_hysteresis"])]
    assert slow[1] == pytest.approx(slow[0], rel=0.02)
    fast = [width(e, 200.0, 40_000.0, 20) for e in ([], ["rate_dependent_hysteresis"])]
    assert fast[1] > 1.2 * fast[0]


@pytest.mark.parametrize("model", ["bouc-wen", "prandtl-ishlinskii"])
def test_asymmetric_hysteresis_only_for_negative_voltage(model):
    pos = sine(2.0, 2, 2000.0, amp=50.0, offset=50.0)  # 0 … 100 V, never negative
    off, on = pair("asymmetric_hysteresis", pos, 2000.0, hysteresis=model)
    assert np.array_equal(off, on)
    sym = sine(2.0, 2, 2000.0)
    off, on = pair("asymmetric_hysteresis", sym, 2000.0, hysteresis=model)
    d = on - off
    assert np.max(np.abs(d[sym < -20])) > 0.02 * np.ptp(off)
    # the negative half of the loop widens more than the positive half
    sl = last_period(sym.size, 2000.0, 2.0)

    def gap(u_, y_, at):
        up = np.gradient(u_) > 0
        iu, idn = np.argsort(u_[up]), np.argsort(u_[~up])
        return np.interp(at, u_[~up][idn], y_[~up][idn]) - np.interp(at, u_[up][iu], y_[up][iu])

    g_on = [gap(sym[sl], on[sl], a) for a in (-50.0, 50.0)]
    g_off = [gap(sym[sl], off[sl], a) for a in (-50.0, 50.0)]
    assert g_off[0] == pytest.approx(g_off[1], rel=0.02)  # the core loop is symmetric
    assert g_on[0] > 1.2 * g_on[1] and g_on[0] > 1.2 * g_off[0]


def test_amplifier_bandwidth_lag_grows_with_frequency():
    f, fs = 500.0, 50_000.0
    u = sine(f, 50, fs)
    off, on = pair("amplifier_bandwidth", u, fs)
    sl = last_period(u.size, fs, f)
    lag = loop_metrics(u[sl], on[sl], f, fs)["phase_deg"] - loop_metrics(u[sl], off[sl], f, fs)["phase_deg"]
    fa = CantileverTwin().params.amp_bandwidth_hz
    assert lag == pytest.approx(math.degrees(math.atan(f / fa)), abs=0.2)
    off, on = pair("amplifier_bandwidth", sine(2.0, 2, 2000.0), 2000.0)
    assert np.max(np.abs(on - off)) < 1e-3 * np.ptp(off)


def test_figures_write_pngs(tmp_path):
    from twins.cantilever.figures import plot_multisine_spectra, plot_sine_loops

    meas = CantileverTwin(effects=["rate_dependent_hysteresis", "second_mode", "sensor_lowpass"])
    rec = meas.generate("thesis-sines", freqs_hz="1-50-500", min_duration_s=0.1)
    assert [s["freq_hz"] for s in rec.meta["segments"]] == [1.0, 50.0, 500.0]
    p = plot_sine_loops(rec, CantileverTwin().noise_free(), tmp_path / "f43.png")
    assert p.stat().st_size > 10_000
    ms = meas.generate("thesis-multisine", duration_s=1.0)
    p = plot_multisine_spectra(ms, tmp_path / "f34.png", twin=meas)
    assert p.stat().st_size > 10_000
    with pytest.raises(ValueError, match="segments"):
        plot_sine_loops(ms, meas, tmp_path / "x.png")
