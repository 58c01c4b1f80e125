"""Diagnosis that holds on measured records: split, ranges, bounds, sub-step, noise level, mis-sized defaults.

Default suite: the unit checks (split on a hold, amplitude option, bounds, sub-step accuracy against a 1 µs
solution, noise level against a known σ), one mis-sized default effect and one effect outside the catalog.
``slow``: two hidden effects at once (seed 0, with their parameters), the simulated 1.4 kV creep record through
the CLI and the seed sweeps behind the success rates (rates printed; docs/diagnosis.md lists the measured ones).
"""

from __future__ import annotations

import json

import discrepancy_cases_measured as C
import numpy as np
import pytest
from discrepancy_cases import hidden_case

from sysid.data.record import Record
from sysid.errors import DataError
from twins.cantilever import CantileverTwin
from twins.cantilever.substep import choose_substep
from twins.discrepancy import diagnose, ranges, splitting, unexplained


# ------------------------------------------------------------------------------------------ split
def test_default_split_moves_off_a_hold():
    fs = 100.0
    rng = np.random.default_rng(0)
    u = np.concatenate([rng.uniform(-50, 50, 500).repeat(2), np.zeros(800)])  # excited 10 s, then an 8 s hold
    rec = Record(u=u, y=u * 0.3, fs=fs)
    est, val, info = splitting.choose_split(rec, 0.6)
    assert info["moved"] and "hold" in info["note"]
    assert np.std(val.u) > splitting.MIN_EXCITATION * np.std(u)
    assert len(est) + len(val) == len(u)


def test_split_without_excitation_anywhere_asks_for_val():
    u = np.concatenate([np.zeros(100), np.full(2000, 10.0)])  # one step at the start, then a hold
    with pytest.raises(DataError, match="--val"):
        splitting.choose_split(Record(u=u, y=u, fs=10.0), 0.6)


def test_validation_record_on_a_hold_is_refused():
    est = Record(u=np.sin(np.arange(500) / 5.0), y=np.sin(np.arange(500) / 5.0), fs=10.0)
    val = Record(u=np.full(300, 0.5), y=np.full(300, 0.5), fs=10.0)
    with pytest.raises(DataError, match="no excitation"):
        diagnose(CantileverTwin(), est, val)


# ------------------------------------------------------------------------------------------ ranges
def _rec(u, fs=100.0):
    return Record(u=np.asarray(u, float), y=np.zeros(len(u)), fs=fs)


def test_amplitude_limit_follows_the_record_and_names_the_option():
    tw, notes = ranges.follow_record(CantileverTwin(), _rec(np.r_[0, 1400.0, 1000.0]), _rec(np.r_[1000.0, 1400.0]))
    assert tw.params.amp_limit_v == 1400.0 and any("amp_limit_v" in n for n in notes)
    with pytest.raises(DataError, match="amp_limit_v"):
        ranges.follow_record(CantileverTwin(), _rec(np.r_[0, 2e4]), _rec(np.r_[0, 1.0]))


def test_creep_time_constants_reach_the_record_length():
    tw, notes = ranges.follow_record(CantileverTwin(), _rec(np.zeros(60_000)), _rec(np.ones(40_000)))  # 1000 s
    assert tw.params.creep_tau_min_s * 10 ** (tw.params.creep_elements - 1) >= 1000.0


def test_at_bound_reported_and_widened_once():
    tw = CantileverTwin().with_params(f1_hz=2999.0, zeta1=0.02)
    hits = ranges.at_bounds(tw, ["f1_hz", "zeta1"])
    assert [h["param"] for h in hits] == ["f1_hz"] and hits[0]["bound"] == 3000.0 and hits[0]["side"] == "upper"
    wide, rows = ranges.widened(tw, hits)
    assert rows[0]["widened_to"] == [50.0, 30000.0]
    assert wide.with_params(f1_hz=5000.0).params.f1_hz == 5000.0  # accepted beyond the documented 3 kHz
    assert ranges.at_bounds(wide, ["f1_hz"]) == []


# ------------------------------------------------------------------------------------------ sub-step
@pytest.mark.parametrize("kind", ["staircase_1k", "steps_protocol_1k", "slow_sines_1k", "multisine_10k"])
def test_bandwidth_chosen_substep_meets_its_bound_against_a_1us_solution(kind):
    tw = CantileverTwin().noise_free()
    rng = np.random.default_rng(1)
    if kind == "staircase_1k":
        fs, u = 1000.0, np.repeat(rng.uniform(-80, 80, 6), 300)
    elif kind == "steps_protocol_1k":  # the twin's own step protocol, as the step cases of the diagnosis use it
        fs, u = 1000.0, tw.generate("steps", fs=1000.0, hold_s=1.0, level_v=80.0).u
    elif kind == "slow_sines_1k":
        t = np.arange(3000) / 1000.0
        fs, u = 1000.0, 80 * np.sin(2 * np.pi * 3 * t) + 20 * np.sin(2 * np.pi * 47 * t)
    else:
        fs, u = 10_000.0, tw.generate("thesis-multisine", duration_s=0.3, signal_seed=1).u
    h = choose_substep(tw, u, fs)
    assert h >= tw.params.max_substep_s
    fine = tw.with_params(max_substep_s=1e-6).simulate(u, fs)
    got = tw.with_params(max_substep_s=h).simulate(u, fs)
    span = tw.params.gain_um_per_v * np.ptp(u)
    assert np.max(np.abs(got - fine)) <= 1e-4 * span  # the module's error budget
    if kind == "slow_sines_1k":  # a slow record needs far fewer sub-steps than the default 50 per sample
        assert tw.with_params(max_substep_s=h).substeps(fs) <= 5


def test_substep_is_rechosen_for_an_adopted_configuration():
    """The step chosen from the starting twin misses its bound once an asymmetry is added (1.5× on the step
    protocol); the diagnosis re-chooses it for every configuration it adopts."""
    tw = CantileverTwin().noise_free()
    u = tw.generate("steps", fs=1000.0, hold_s=1.0, level_v=80.0).u
    rec = Record(u=u, y=np.zeros(u.size), fs=1000.0)
    start, _ = ranges.follow_record(tw, rec, rec)
    asym = start.with_effects(set(start.effects) | {"asymmetric_hysteresis"}).with_params(asym_factor=1.2)
    new = ranges.substep_for(asym, rec, rec)
    assert new.params.max_substep_s < start.params.max_substep_s
    assert ranges.substep_for(start, rec, rec).params.max_substep_s == start.params.max_substep_s
    fine = asym.with_params(max_substep_s=1e-6).simulate(u, rec.fs)
    budget = 1e-4 * asym.params.gain_um_per_v * np.ptp(u)
    assert np.max(np.abs(asym.simulate(u, rec.fs) - fine)) > budget
    assert np.max(np.abs(new.simulate(u, rec.fs) - fine)) <= budget


# ------------------------------------------------------------------------------------------ noise
def test_noise_level_from_holds_matches_the_known_sigma():
    rng = np.random.default_rng(2)
    u = np.repeat(rng.uniform(-1, 1, 20), 500)
    y = 3.0 * u + 0.01 * rng.standard_normal(u.size)
    nl = unexplained.noise_level(u, y, 1000.0)
    assert nl["sigma2"] == pytest.approx(1e-4, rel=0.2)


def test_noise_level_of_a_coarsely_quantised_reading_is_not_the_rounding_of_its_grid():
    """The diagnosis benchmark's cases 47, 142 and 227: readings on a grid 5–13× coarser than their noise. More than
    half their second differences were 0 or the rounding of grid values (1e-16 of the span), and their MAD gave
    σ² ~ 1e-30: the residual of a model with the right quantiser was then 1e26–1e29 × "the noise" and the verdict
    `unexplained`. The level now lies between the noise's power and the quantiser's q²/12 + σ²."""
    from benchmarks.diagnosis_bench.cases import draw_case
    from benchmarks.diagnosis_bench.truth import make_records

    for seed in (47, 142, 227):
        case = draw_case(seed)
        assert case.mechanism == "quantization"
        b = make_records(case)
        nl = unexplained.records_noise(b["est"], b["val"])
        noise = float(np.var(np.concatenate(b["noise"])))
        q2 = b["params"]["step"] ** 2 / 12.0
        assert 0.3 * noise <= nl["sigma2"] <= 2.0 * (q2 + noise), (seed, nl)


# ------------------------------------------------------------------------------------------ whole diagnoses
@pytest.mark.heavy
def test_missized_default_creep_is_named_with_its_rate():
    start, est, val, true, field = C.missized_case("creep", 0)
    out = diagnose(start, est, val, max_rounds=1)
    top = out["causes"][0]
    assert top["effect"] == "creep" and top["kind"] == "mis-sized default", out["causes"]
    assert abs(top["params"][field] - true) <= 0.15 * true
    assert "× the configured" in top["evidence"] and out["verdict"] == "discrepancy"


@pytest.mark.heavy
def test_dead_zone_outside_the_catalog_is_unexplained():
    start, est, val, _ = C.outside_case("dead_zone", 0)
    out = diagnose(start, est, val, max_rounds=1)
    assert out["verdict"] == "unexplained"
    assert out["residual_vs_noise"]["unexplained_fraction"] > 0.9
    assert "outside the model class" in out["residual_vs_noise"]["text"]


@pytest.mark.slow  # ≈ 27 s CPU: 8200 samples whose 400 V jumps need 118 sub-steps per sample
def test_creep_stack_record_loads_and_is_diagnosed_from_the_cli(tmp_path, capsys):
    from benchmarks.cli import main

    rec = C.creep_stack_record(0)
    path = tmp_path / "stack.csv"
    np.savetxt(
        path, np.column_stack([np.arange(len(rec)) / rec.fs, rec.u, rec.y]), delimiter=",", header="t,u,y", comments=""
    )
    assert main(["diagnose", "cantilever", "--data", str(path), "--max-rounds", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert any("amp_limit_v" in n for n in out["ranges"])
    named = [c["effect"] for c in out["causes"]]
    assert out["verdict"] == "unexplained" or (out["verdict"] == "discrepancy" and named[0] == "creep"), out["causes"]


def _named(out):
    return {c["effect"] for c in out["causes"]} | {g for c in out["causes"] for g in c.get("group", [])}


def _recheck(stage_twin, truth):
    """The final re-check of mis-sized defaults on a short broadband record of ``truth`` (with its noise), with one
    added cause beside a sensor named mis-sized at 3× its configured bandwidth."""
    from types import SimpleNamespace

    from twins.discrepancy import rounds
    from twins.discrepancy.options import DiagnoseOptions
    from twins.discrepancy.trials import make_stage

    fs, rng = 10_000.0, np.random.default_rng(3)
    u = np.repeat(rng.uniform(-60, 60, 400), 5)
    est, val = (Record(u=x, y=truth.simulate(x, fs), fs=fs) for x in (u[:1200], u[1200:]))
    opts = DiagnoseOptions()
    prior = CantileverTwin().noise_free()
    loop = SimpleNamespace(inp=SimpleNamespace(est=est, val=val), cal=SimpleNamespace(prior=prior), opts=opts)
    causes = [
        {"effect": "input_delay", "round": 1, "params": {}},
        {
            "effect": "sensor_lowpass",
            "kind": "mis-sized default",
            "round": 2,
            "params": {"sensor_bandwidth_hz": 15000.0},
        },
    ]
    ext = rounds.Extension(make_stage(stage_twin, est, val, opts), causes, [])
    rounds._recheck_defaults(loop, ext)
    return ext


def test_mis_sized_default_back_at_its_size_is_withdrawn_after_the_revisit():
    truth = CantileverTwin(seed=4)
    tw = truth.noise_free()
    ext = _recheck(tw.with_params(sensor_bandwidth_hz=5100.0), truth)  # refitted to 2 % of the configured size
    assert [c["effect"] for c in ext.causes] == ["input_delay"] and "within 5 %" in ext.rounds[-1]["note"]
    assert ext.rounds[-1]["withdrawn"] == "sensor_lowpass" and ext.stage.twin.params.sensor_bandwidth_hz == 5100.0
    ext = _recheck(tw.with_params(sensor_bandwidth_hz=6000.0), truth)  # the configured size fits better: put back
    assert [c["effect"] for c in ext.causes] == ["input_delay"] and "not significantly worse" in ext.rounds[-1]["note"]
    assert ext.stage.twin.params.sensor_bandwidth_hz == 5000.0
    ext = _recheck(tw.with_params(sensor_bandwidth_hz=15000.0), truth.with_params(sensor_bandwidth_hz=15000.0))
    sensor = ext.causes[1]  # the data do have the 3× bandwidth: kept, reported as refitted
    assert sensor["effect"] == "sensor_lowpass" and sensor["ratio_to_configured"]["sensor_bandwidth_hz"] == 3.0


@pytest.mark.slow  # ≈ 100 s: three rounds of the whole catalog on steps; the toy two-effect test runs by default
def test_two_hidden_effects_creep_and_thermal_drift():
    """Creep + thermal drift on steps (seed 0), both named with their parameters within 15 %: before the revisit
    and the core refit of the estimation leader, an asymmetric hysteresis mimicking the pair took creep's place."""
    pair = ("creep", "thermal_drift")
    start, est, val, true = C.pair_case(pair, 0)
    out = diagnose(start, est, val, max_rounds=3)
    assert set(pair) <= _named(out) and out["verdict"] == "discrepancy", out["causes"]
    creep = next(c for c in out["causes"] if c["effect"] == "creep")
    drift = next(c for c in out["causes"] if c["effect"] == "thermal_drift")
    assert abs(creep["params"]["creep_per_decade"] - true["creep_per_decade"]) <= 0.15 * true["creep_per_decade"]
    for f in ("thermal_drift_um", "thermal_tau_s"):
        assert abs(drift["params"][f] - true[f]) <= 0.15 * true[f], drift


# ------------------------------------------------------------------------------------------ slow sweeps
def _rate(results):
    return sum(results), len(results)


@pytest.mark.slow
@pytest.mark.parametrize("effect", sorted(C.MISSIZED))
def test_missized_defaults_over_seeds(effect):
    ok = []
    for seed in range(3):
        start, est, val, true, field = C.missized_case(effect, seed)
        out = diagnose(start, est, val, max_rounds=1)
        top = out["causes"][0] if out["causes"] else {}
        ok.append(top.get("effect") == effect and abs(top["params"][field] - true) <= 0.15 * true)
    print(f"mis-sized {effect}: {_rate(ok)}")
    assert sum(ok) == 3


# every pair's 10-seed rate is measured (docs/diagnosis.md): creep + thermal drift 9/10, saturation + delay 10/10,
# amplifier compression + wall echo 9/10
_PAIR_PARAMS = sorted(C.PAIRS) + sorted(C.ACOUSTIC_PAIRS)


@pytest.mark.slow
@pytest.mark.parametrize("pair", _PAIR_PARAMS)
def test_two_hidden_effects_over_seeds(pair):
    ok = []
    for seed in range(10):
        start, est, val, _ = C.pair_case(pair, seed)
        out = diagnose(start, est, val, max_rounds=3)
        ok.append(set(pair) <= _named(out))
    print(f"pair {pair}: {_rate(ok)}")
    assert sum(ok) >= 9


@pytest.mark.slow
@pytest.mark.parametrize("kind", C.OUTSIDE)
def test_outside_the_catalog_over_seeds(kind):
    ok = []
    for seed in range(10):
        start, est, val, _ = C.outside_case(kind, seed)
        ok.append(diagnose(start, est, val, max_rounds=1)["verdict"] == "unexplained")
    print(f"outside {kind}: {_rate(ok)}")
    assert sum(ok) >= 9


@pytest.mark.slow
def test_noise_only_over_20_seeds():
    ok = []
    for seed in range(20):
        start, est, val, _, _ = hidden_case("cantilever", None, seed)
        ok.append(diagnose(start, est, val, max_rounds=1)["verdict"] == "none")
    print(f"noise only: {_rate(ok)}")
    assert sum(ok) >= 19
