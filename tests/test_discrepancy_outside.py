"""Acoustic effects injected by code outside the twin (``tests/discrepancy_outside.py``: a tanh limiter, a cubic
soft clip and a hard clip of the drive, an in-phase copy of the drive, a delayed copy of the output; the bare
twin's simulation with 1 % output noise) are named by the catalog's effect families, and never as another
effect; noise alone gives ``none``. ``slow``: one diagnosis is 20–50 s; ``DISCREPANCY_SEEDS`` (default 0,1,2)
sets the seeds, and the rates are asserted at ≥ 90 % (all of three seeds) and printed as JSON. Default suite: the
echo's fit from a filter switch at its bound (the cause of the two misses of 8/10, seeds 3 and 5).
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from discrepancy_outside import expected_effect, outside_case

from twins.discrepancy import diagnose

SEEDS = [int(s) for s in os.environ.get("DISCREPANCY_SEEDS", "0,1,2").split(",")]


def _run(kind: str, seed: int) -> dict:
    start, est, val, truth = outside_case(kind, seed)
    out = diagnose(start, est, val, max_rounds=1)
    top = out["causes"][0] if out["causes"] else {}
    want = expected_effect(kind)
    named = {c["effect"] for c in out["causes"]}
    ok = (top.get("effect") == want and named <= {want, "unexplained"}) if want else out["verdict"] == "none"
    return {
        "seed": seed,
        "ok": bool(ok),
        "top": top.get("effect"),
        "causes": sorted(named),
        "params": top.get("params"),
        "truth": truth,
        "nrmse_before": out["baseline"]["nrmse_val"],
        "nrmse_after": out["extended"]["nrmse_val"],
    }


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["tanh", "cubic", "clip"])
def test_compression_of_another_shape_is_named_compression(kind):
    res = [_run(kind, s) for s in SEEDS]
    print(json.dumps({"kind": kind, "results": res}, default=str))
    assert sum(r["ok"] for r in res) >= 0.9 * len(res), res
    assert not any("wall_echo" in r["causes"] for r in res), res


@pytest.mark.slow
def test_in_phase_crosstalk_is_named_crosstalk():
    res = [_run("inphase", s) for s in SEEDS]
    print(json.dumps({"kind": "inphase", "results": res}, default=str))
    assert sum(r["ok"] for r in res) >= 0.9 * len(res), res


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["echo", "echo_lp"])
def test_echo_as_delayed_copy_is_named_and_explained(kind):
    """Named wall_echo, and the validation NRMSE after the extension within 1.5× the injected 1 % noise; the copy
    as it is, and through a low-pass (a lossy wall)."""
    res = [_run(kind, s) for s in SEEDS]
    print(json.dumps({"kind": kind, "results": res}, default=str))
    assert sum(r["ok"] and r["nrmse_after"] < 0.015 for r in res) >= 0.9 * len(res), res


@pytest.mark.slow
def test_noise_only_on_the_bare_twin_is_none():
    res = [_run("none", s) for s in SEEDS]
    assert all(r["ok"] for r in res), res


def test_least_squares_from_a_switch_at_its_bound_keeps_the_echo():
    """The echo's low-pass cutoff 0 means "no filter", 10⁻³ Hz "no echo": least squares started at 0 is moved
    inside the bounds, lands where the echo is filtered away and stopped there (seeds 3 and 5 named a geometry
    effect). Started from the injected echo's own delay and size with no filter, the fit keeps the echo: the
    validation NRMSE within 1.5× the injected 1 % noise (2.5 s)."""
    from twins.acoustic.channel import wall_path_length
    from twins.discrepancy.evidence import sound_speed
    from twins.discrepancy.options import DiagnoseOptions
    from twins.discrepancy.prediction import deterministic
    from twins.discrepancy.trials import run_trial

    start, est, val, truth = outside_case("echo", 3)
    base = deterministic(start)
    L, c = base.params.distance_m, sound_speed(base)
    extra = c * float(truth["echo_delay_s"])  # √(L² + 4w²) − L = c·τ
    w = float(np.sqrt((L + extra) ** 2 - L * L) / 2)
    assert abs(wall_path_length(L, w) - L - extra) < 1e-9
    x0 = {
        "wall_distance_m": w,
        "wall_reflection": 1.0,
        "wall_coupling": float(truth["echo_amplitude"]),
        "wall_echo_cutoff_hz": 0.0,
        "wall_echo_path": "copy",
    }
    tr = run_trial(base, "wall_echo", est, val, [], {}, DiagnoseOptions(), refit_core=False, start=x0)
    assert tr.nrmse_val < 0.015, (tr.nrmse_val, tr.effect_params)
    assert tr.effect_params["wall_echo_cutoff_hz"] == 0.0 or tr.effect_params["wall_echo_cutoff_hz"] > 1e5
