"""The diagnosis benchmark's own parts: cases drawn from seeds, the generator's mechanisms against closed forms,
the scoring rules on made-up rows, the CI comparison. (The diagnosis itself is run by ``bench-diagnosis``.)"""

import math

import numpy as np
import pytest

from benchmarks.diagnosis_bench import mechanisms as mech
from benchmarks.diagnosis_bench.calibrate import examples, fit, held_out
from benchmarks.diagnosis_bench.cases import KINDS, RECORDS, draw_case, excitation
from benchmarks.diagnosis_bench.check import compare
from benchmarks.diagnosis_bench.score import calibration, current, detection_limit, outcome, score
from twins.discrepancy import confidence


def test_a_seed_is_one_case_and_the_draws_cover_the_space():
    assert draw_case(17) == draw_case(17) and draw_case(17) != draw_case(18)
    cases = [draw_case(s) for s in range(400)]
    assert {c.model for c in cases} == set(RECORDS)
    assert {c.est_kind for c in cases} == set(KINDS) == {c.val_kind for c in cases}
    assert 0.05 < sum(c.mechanism is None for c in cases) / len(cases) < 0.16
    for c in cases:
        lo, hi = RECORDS[c.model]["fs"]
        assert lo <= c.fs <= hi and 0.003 <= c.noise <= 0.03
        if c.mechanism:
            s_lo, s_hi = mech.MECHANISMS[c.mechanism].size_range
            assert s_lo <= c.size <= s_hi and c.mechanism in mech.TWIN_MECHANISMS[c.family]
    acoustic = [c for c in cases if c.model == "acoustic"]
    assert min(c.n / c.fs for c in acoustic) >= 2.2e-4  # past the first arrival
    assert max(c.fs for c in acoustic) > 60e6 and min(c.fs for c in acoustic) < 8e6


@pytest.mark.parametrize("kind", KINDS)
def test_excitations_have_the_drawn_peak(kind):
    c = draw_case(3)
    u = excitation(c, kind, np.random.default_rng(0))
    assert u.shape == (c.n,) and np.isclose(np.max(np.abs(u - c.centre)), c.peak)


def test_delay_line_shifts_a_sine_by_its_delay():
    fs, f, d = 1000.0, 7.0, 0.0123
    t = np.arange(4000) / fs
    out = mech.apply_input("delay", np.sin(2 * math.pi * f * t), fs, {"delay_s": d})
    np.testing.assert_allclose(out[100:], np.sin(2 * math.pi * f * (t[100:] - d)), atol=2e-3)


@pytest.mark.parametrize("shape", ["tanh", "cubic", "hardclip", "rapp"])
def test_limiter_compresses_the_peak_by_the_size(shape):
    peak, comp = 3.0, 0.15
    level = mech.limiter_level(peak, shape, comp, 2.5)
    p = {"shape": shape, "level": level, "centre": 0.0, "rapp_p": 2.5}
    out = mech.apply_input("limiter", np.array([peak, -peak, 0.01]), 1.0, p)
    np.testing.assert_allclose(out[:2], [(1 - comp) * peak, -(1 - comp) * peak], rtol=1e-9)
    assert abs(out[2] - 0.01) < 1e-3  # small signals pass


def test_lowpasses_are_3db_down_at_their_corner():
    fs, fc = 10_000.0, 300.0
    t = np.arange(20_000) / fs
    x = np.sin(2 * math.pi * fc * t)
    for out, want in (
        (mech.apply_input("drive_lowpass", x, fs, {"corner_hz": fc}), 1 / math.sqrt(2)),
        (mech.apply_output("sensor_lowpass", x, x, fs, {"corner_hz": fc}), 1 / math.sqrt(2)),
    ):
        assert abs(np.std(out[5000:]) / np.std(x[5000:]) - want) < 0.01


def test_lowpasses_above_nyquist_are_the_analog_parts():
    """A corner above the record's Nyquist frequency (a fast sensor sampled slowly) keeps the analog response:
    gain and phase of H(j2πf) at a sine well inside the band, not a filter clipped below Nyquist."""
    fs, f = 2277.5, 50.0
    t = np.arange(20_000) / fs
    x = np.sin(2 * math.pi * f * t)
    for fc in (4_000.0, 16_000.0):
        w, s = 2 * math.pi * fc, 2j * math.pi * f
        for out, h in (
            (mech.apply_input("drive_lowpass", x, fs, {"corner_hz": fc}), 1 / (1 + s / w)),
            (
                mech.apply_output("sensor_lowpass", x, x, fs, {"corner_hz": fc}),
                w * w / (s * s + math.sqrt(2) * w * s + w * w),
            ),
        ):
            want = abs(h) * np.sin(2 * math.pi * f * t + np.angle(h))
            assert np.max(np.abs(out[2000:] - want[2000:])) < 2e-3  # the input taken linear between samples


def test_play_operator_and_dead_zone():
    u = np.array([0.0, 1.0, 2.0, 1.5, 1.0, 0.0, -1.0])
    np.testing.assert_allclose(mech.apply_input("backlash", u, 1.0, {"width": 0.5}), [0, 0.5, 1.5, 1.5, 1.5, 0.5, -0.5])
    np.testing.assert_allclose(
        mech.apply_input("dead_zone", u, 1.0, {"width": 0.5, "centre": 0.0}), [0, 0.5, 1.5, 1.0, 0.5, 0, -0.5]
    )


def test_quantizer_lattice_and_second_mode_limits():
    y = np.linspace(-1, 1, 101)
    q = mech.quantize(y, 0.1)
    assert np.allclose(q / 0.1, np.round(q / 0.1)) and np.max(np.abs(q - y)) <= 0.05 + 1e-12
    p = {"share": 0.0, "f1_hz": 700.0, "zeta1": 0.02, "f2_hz": 4389.0, "zeta2": 0.02}
    x = np.sin(np.arange(5000) / 30.0)
    np.testing.assert_allclose(mech.apply_output("second_mode", x, x, 10_000.0, p), x)  # no share: the same output
    slow = np.ones(3000)
    out = mech.apply_output("second_mode", slow, slow, 10_000.0, {**p, "share": 0.1})
    np.testing.assert_allclose(out[-100:], 1.0, atol=1e-6)  # both modes carry the static deflection


def test_creep_grows_by_its_rate_per_decade():
    fs = 100.0
    v = np.r_[0.0, np.ones(60_000)]  # a 1 V step held 600 s
    out = mech.apply_output("creep", np.zeros_like(v), v, fs, {"drive": v, "rate": 0.02, "gain": 1.0, "tau1_s": 0.1})
    t = np.arange(v.size) / fs
    a, b = out[np.searchsorted(t, 1.0)], out[np.searchsorted(t, 10.0)]
    assert 0.8 * 0.02 < b - a < 1.25 * 0.02  # about one rate per decade of time (log law)


def _row(mechanism, family, verdict, causes, size=0.1, cpu=10.0, seed=0):
    return {
        "case": {
            "seed": seed,
            "model": family,
            "family": family,
            "mechanism": mechanism,
            "fs": 1e4,
            "est_kind": "chirp",
            "val_kind": "steps",
        },
        "verdict": verdict,
        "causes": causes,
        "size_est": size,
        "size_val": size,
        "cpu_s": cpu,
        "params": {},
    }


def _c(effect, conf, group=()):
    return {"effect": effect, "confidence": conf, "group": list(group), "params": {}}


def test_outcomes_follow_the_rules():
    assert outcome(_row("creep", "cantilever", "discrepancy", [_c("creep", 0.9)]))["outcome"] == "right"
    o = outcome(_row("creep", "cantilever", "discrepancy", [_c("slow_drift", 0.8)]))
    assert o["outcome"] == "wrong" and o["confident_wrong"]
    grp = _c("distance_offset", 0.6, ["distance_offset", "temperature_offset"])
    assert outcome(_row("temperature", "acoustic", "discrepancy", [grp]))["outcome"] == "right"
    assert outcome(_row("creep", "cantilever", "none", []))["outcome"] == "missed"
    out = _row("gain_sag", "cantilever", "unexplained", [_c("rate_dependent_hysteresis", 0.3)])
    assert outcome(out)["outcome"] == "right"  # outside, unexplained, no confident name
    out["causes"][0]["confidence"] = 0.7
    assert outcome(out)["outcome"] == "wrong" and outcome(out)["confident_wrong"]
    assert outcome(_row(None, "user", "none", []))["outcome"] == "right"
    assert outcome(_row(None, "user", "discrepancy", [_c("sensor_offset", 0.2)]))["outcome"] == "wrong"


def test_detection_limit_and_calibration(monkeypatch):
    monkeypatch.setattr(confidence, "COEFFICIENTS", None)  # the scoring rules alone: stated = raw score
    sizes = [0.001, 0.002, 0.004, 0.01, 0.02, 0.05, 0.1]
    assert math.isclose(detection_limit(sizes, [False, False, False, True, True, True, True]), math.sqrt(0.04e-3))
    dl = detection_limit(sizes, [False, True, False, False, True, True, True])
    assert 0.002 < dl < 0.02
    assert detection_limit(sizes, [False] * 7) is None
    rows = [_row("creep", "cantilever", "discrepancy", [_c("creep", 0.85)], seed=i) for i in range(8)]
    rows += [_row("creep", "cantilever", "discrepancy", [_c("thermal_drift", 0.85)], seed=8 + i) for i in range(2)]
    cal = calibration([dict(r) for r in rows])
    assert cal["n"] == 10 and cal["bins"][0]["observed"] == pytest.approx(0.8)
    assert cal["brier"] == pytest.approx(0.8 * 0.15**2 + 0.2 * 0.85**2)
    s = score(rows)
    assert s["confident_wrong"]["k"] == 2 and s["outcomes"] == {"right": 8, "wrong": 2}


def test_ci_check_fails_when_a_rate_drops_beyond_its_sampling_error():
    stored = [_row("creep", "cantilever", "discrepancy", [_c("creep", 0.9)], seed=i, size=1.0) for i in range(6)]
    limits = {"cantilever:creep": 0.01}
    same = compare(stored, stored, limits, {"catalog:cantilever": 0.95})
    assert same["passed"] and same["groups"][0]["now"] == 1.0
    worse = [_row("creep", "cantilever", "none", [], seed=i, size=1.0) for i in range(3)] + stored[3:]
    dropped = compare(worse, stored, limits, {"catalog:cantilever": 0.95})
    assert not dropped["passed"] and dropped["groups"][0]["now"] == 0.5
    one = [_row("creep", "cantilever", "discrepancy", [_c("creep", 0.9)], seed=0, size=1.0)]
    flipped = [_row("creep", "cantilever", "none", [], seed=0, size=1.0)]
    assert not compare(flipped, one, limits, {"catalog:cantilever": 0.95})["passed"]  # one case can fail too


def test_stored_rows_read_with_the_calibration_of_now(monkeypatch):
    """A row stored before the calibration was fitted (confidence = raw score) is read with the current map, the
    causes re-ordered by it; reading again (a row written after the fit) changes nothing."""
    coef = (0.0, 2.0) + (0.0,) * (len(confidence.FEATURES) - 1)  # P = logistic(2 logit(score)) only
    monkeypatch.setattr(confidence, "COEFFICIENTS", coef)
    row = _row("creep", "cantilever", "discrepancy", [_c("thermal_drift", 0.7), _c("creep", 0.6)])
    row["causes"][1]["p_value"] = 1e-9  # features the map ignores here
    now = current(row)
    expect = [1 / (1 + ((1 - s) / s) ** 2) for s in (0.7, 0.6)]
    assert [c["effect"] for c in now["causes"]] == ["thermal_drift", "creep"]
    assert [c["confidence"] for c in now["causes"]] == pytest.approx(expect)
    assert [c["score"] for c in now["causes"]] == [0.7, 0.6] and row["causes"][0]["confidence"] == 0.7
    again = current(now)
    assert [c["confidence"] for c in again["causes"]] == pytest.approx(expect)
    flipped = (0.0, -2.0) + coef[2:]  # a map that reverses the order re-sorts the causes
    monkeypatch.setattr(confidence, "COEFFICIENTS", flipped)
    assert [c["effect"] for c in current(row)["causes"]] == ["creep", "thermal_drift"]


def test_the_case_residual_to_noise_ratio_enters_the_confidence(monkeypatch):
    """R (the final validation residual over the noise level) is a covariate of every named cause of its case: read
    from the row as stored (``residual_vs_noise``), and by the diagnosis from its verdict."""
    c = _c("creep", 0.6)
    assert confidence.features(c, 100.0)[-1] == pytest.approx(2.0)
    assert confidence.features(c, None)[-1] == 0.0 and confidence.features(c, float("nan"))[-1] == 0.0
    coef = (0.0,) * len(confidence.FEATURES) + (-1.0,)  # P = logistic(−log10 R) only
    monkeypatch.setattr(confidence, "COEFFICIENTS", coef)
    row = dict(_row("creep", "cantilever", "unexplained", [c]), residual_vs_noise=1000.0)
    assert current(row)["causes"][0]["confidence"] == pytest.approx(1 / (1 + math.exp(3.0)))


def test_the_calibration_is_fitted_on_the_causes_it_states_for():
    """A cause under a cap (a band, a transfer or the outside mark) states the cap whatever the logistic model says:
    it is no example for the model; the causes it states for are, right and wrong alike."""
    free_right, free_wrong = _c("creep", 0.9), _c("slow_drift", 0.8)
    banded, moved = dict(_c("creep", 0.9), above_nyquist=True), dict(_c("creep", 0.9), untransferable=True)
    rows = [
        _row("creep", "cantilever", "discrepancy", [free_right, free_wrong], seed=1),
        _row("creep", "cantilever", "discrepancy", [banded, moved], seed=2),
        dict(_row("creep", "cantilever", "unexplained", [_c("creep", 0.9)], seed=3), residual_vs_noise=100.0),
        dict(_row("creep", "cantilever", "unexplained", [_c("creep", 0.3)], seed=4), residual_vs_noise=1.0),
    ]
    x, y, seeds = examples(rows)
    assert list(seeds) == [1, 1, 4] and list(y) == [1.0, 0.0, 1.0]
    assert confidence.capped(banded) and confidence.capped(moved) and confidence.capped(free_right, outside=True)
    assert not confidence.capped(free_right)


def test_calibration_fit_recovers_a_known_logistic_model():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((4000, 2))
    w_true = np.array([-0.5, 1.5, -1.0])
    p = 1 / (1 + np.exp(-(w_true[0] + x @ w_true[1:])))
    y = (rng.uniform(size=p.size) < p).astype(float)
    w = fit(x, y, ridge=1e-6)
    assert np.allclose(w, w_true, atol=0.15)
    seeds = np.arange(p.size)
    ho = held_out(x, y, seeds)
    assert ho["n"] == 4000 and ho["folds"] == 10
    assert ho["brier"] == pytest.approx(float(np.mean(p * (1 - p))), abs=0.02)  # the irreducible Brier score
    assert all(abs(b["stated"] - b["observed"]) < 0.1 for b in ho["bins"] if b["n"] >= 100)


def test_the_page_renders_from_rows_and_says_when_the_run_is_partial(tmp_path):
    from benchmarks.cli.bench_diagnosis import _ranges
    from benchmarks.diagnosis_bench import page

    assert _ranges([0, 1, 2, 5, 7, 8]) == "0–2, 5, 7–8"
    rows = [_row("creep", "cantilever", "discrepancy", [_c("creep", 0.9)], seed=i, size=0.1) for i in range(4)]
    rows += [_row(None, "user", "none", [], seed=4 + i) for i in range(2)]
    scores = score(rows)
    scores["calibration_held_out"] = held_out(*examples(rows))
    meta = {"command": "c", "date": "d", "machine": "m", "seeds": _ranges(list(range(6))), "complete": False}
    text = page.render(scores, meta, tmp_path / "p.md", tmp_path / "dir").read_text()
    assert "seeds 0–5" in text and "The run is not complete" in text
    assert "| cantilever:creep | yes | 4 |" in text
    meta["complete"] = True
    assert "not complete" not in page.render(scores, meta, tmp_path / "p.md", tmp_path / "dir").read_text()
