"""The thesis preset (:mod:`benchmarks.thesis.preset`): the twins' defaults are untouched, the preset's choices are
the dissertation's stated sizes, its data-set-1 window is in periodic steady state at the frequency §5.1 names,
data set 2's excitation repeats period after period, Figure 3.4's peak lands within ± 50 Hz of 750 Hz, and Table
5.3's grid sample is the stated draw."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.thesis import grid, preset
from benchmarks.thesis.plan import TIERS
from benchmarks.thesis.runner import ROW_IDS, tasks_for


def _rel_rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2)))


def test_defaults_unchanged_and_the_preset_is_the_stated_geometry():
    from twins.acoustic.params import AcousticParams
    from twins.cantilever.params import CantileverParams

    a, c = AcousticParams(), CantileverParams()
    pa, pc = preset.acoustic_params(), preset.cantilever_params()
    assert a.distance_m == 0.100 and c.f1_hz == 700.0  # the twins' defaults (and their floors) stay
    # §3.2: the actuators 100 mm apart, each behind its epoxy bond and steel plate
    assert pa.distance_m == pytest.approx(0.100 - 2 * (a.steel_thickness_m + a.epoxy_thickness_m), abs=1e-12)
    assert pa.distance_m == pytest.approx(0.0873, abs=1e-6)
    assert {k for k in vars(a) if getattr(a, k) != getattr(pa, k)} == {"distance_m"}
    assert pc.f1_hz == 750.0 and {k for k in vars(c) if getattr(c, k) != getattr(pc, k)} == {"f1_hz"}
    assert AcousticParams().distance_m == 0.100  # replace() left the defaults alone
    assert all(choice and passage for choice, passage in preset.CHOICES)


def test_periodic_chirp_is_the_protocols_sweep_repeated():
    from twins.acoustic.protocols import chirp_prefix

    n = 20000
    assert np.allclose(preset.periodic_chirp(np.arange(n)), chirp_prefix(100e6, 0.1, 900e3, 1350e3, 0.040, n))
    period = int(0.1 * 100e6)
    k = np.arange(-500, 500)
    assert np.allclose(preset.periodic_chirp(k), preset.periodic_chirp(k + period))
    assert preset.window_start_s() == pytest.approx(50e3 / 450e3 * 0.1)


def test_data_set_1_window_is_in_periodic_steady_state_at_950_khz():
    """A longer lead-in changes nothing in the window (the response to the sweep before it is complete), while a
    record from rest differs; the window's output peaks where §5.1 says data set 1's measured output does."""
    from benchmarks.thesis.acoustic import DS1_STEPS
    from sysid.signals.preprocess import apply_steps

    def ds1(lead):
        return apply_steps(preset.dataset1_record(0.0003, lead), DS1_STEPS)[:2000]

    base = ds1(None)
    lead = float(base.meta["lead_in_s"]) if "lead_in_s" in base.meta else None
    longer, rest = ds1(2 * (lead or 5e-3)), ds1(0.0)
    assert _rel_rms(longer.output, base.output) < 0.02
    assert _rel_rms(rest.output, base.output) > 0.3
    y = base.output - base.output.mean()
    f = np.fft.rfftfreq(8 * y.size, 1 / base.fs)
    peak = f[np.argmax(np.abs(np.fft.rfft(y * np.hanning(y.size), 8 * y.size)))]
    assert peak == pytest.approx(preset.DS1_WINDOW_HZ, abs=10e3)


def test_data_set_2_excitation_and_response_repeat_period_after_period():
    """The preset's twin records the multisine after its warm-up: two consecutive 0.5 ms periods agree (to the
    measurement noise and the 8-bit ADC)."""
    from twins.acoustic import AcousticTwin

    rec = AcousticTwin(params=preset.acoustic_params(), seed=0).generate("thesis-multisine", duration=0.001)
    m = int(round(5000 / 10e6 * rec.fs))
    assert np.allclose(rec.u[:m], rec.u[m : 2 * m])
    assert _rel_rms(rec.output[:m], rec.output[m : 2 * m]) < 0.05


def test_figure_3_4_peak_within_50_hz_of_750_with_the_preset():
    from benchmarks.thesis.cantilever import output_peak_task

    r = output_peak_task(TIERS["quick"], preset=True)
    assert r["f1_hz"] == preset.F1_HZ
    assert abs(r["peak_hz"] - 750.0) <= 50.0


def test_preset_fits_only_for_chapter_5_and_figure_3_4():
    keys = tasks_for(ROW_IDS, TIERS["full"])
    pre = [k for k in keys if k.startswith("preset/")]
    assert pre and not any(k.startswith(("preset/cant/", "preset/cant-")) and k != "preset/cant/peak" for k in pre)
    assert sum(k.startswith("preset/ds2/75x2-sigmoid/") for k in pre) == 75
    assert not any(k.startswith("preset/") for k in tasks_for(["table-4.2/4x25", "fig-3.9/peak"], TIERS["full"]))


def test_grid_sample_is_the_stated_draw():
    assert grid.grid_size() == 16**2 * 8 * 20 * 3  # Table 5.3: 16 lag values, 1-8 layers, 20 widths, 3 activations
    a, b = grid.sample(12, 0), grid.sample(12, 0)
    assert a == b and len({grid.label(c) for c in a}) == 12 and a != grid.sample(12, 1)
    for c in a:
        assert c["nu"] in grid.LAGS and c["ny"] in grid.LAGS and c["activation"] in grid.ACTIVATIONS
        assert len(c["hidden"]) in grid.LAYERS and c["hidden"][0] in grid.WIDTHS
    assert grid.config(0) == {"nu": 2, "ny": 2, "hidden": [2], "activation": "sigmoid"}
    assert len(grid.grid_tasks(a)) == 2 * 12
