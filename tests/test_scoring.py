"""Scoring, the accuracy floors and their check (``piezotwin score --quick --check``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from _toy_models import ToyARX
from benchmarks import scoring
from benchmarks.cli import main
from benchmarks.datasets import load_dataset


def _row(ident, dataset, test, rmse, status="ok", refs=None):
    return {"identifier": ident, "dataset": dataset, "test": test, "status": status, "units": "V",
            "free_run": {"rmse": rmse, "nrmse": rmse, "r2": 1 - rmse ** 2}, "one_step": {"rmse": rmse / 10},
            "references": refs or {}}


def test_check_names_every_pair_above_its_ceiling():
    base = {"format": scoring.BASELINES_FORMAT, "rules": [], "modes": {"quick": {
        "narx-poly": {"silverbox": {"multisine": {"max_rmse": 5e-3, "measured": 4e-3},
                                    "arrow": {"max_rmse": 5e-3, "measured": 4e-3}}},
        "arx": {"cascaded-tanks": {"test": {"max_rmse": 1.2, "measured": 1.0}}}}}}
    run = {"mode": "quick", "rows": [_row("narx-poly", "silverbox", "multisine", 4.5e-3),
                                     _row("narx-poly", "silverbox", "arrow", 6e-3),
                                     _row("arx", "cascaded-tanks", "test", float("nan"), status="diverged")]}
    fails = scoring.check(run, base)
    assert len(fails) == 2
    assert any("narx-poly on silverbox/arrow" in f and "0.006 " in f for f in fails)
    assert not any("silverbox/multisine" in f for f in fails)
    assert any("arx on cascaded-tanks/test" in f and "diverged" in f for f in fails)
    # the same run in full mode has no floors: nothing to fail
    assert scoring.check({**run, "mode": "full"}, base) == []


def test_rules_beat_linear_and_published():
    base = {"format": scoring.BASELINES_FORMAT, "modes": {}, "rules": [
        {"rule": "beats_linear", "linear": "arx", "datasets": ["wiener-hammerstein"]},
        {"rule": "beats_value", "identifier": "narmax-poly", "dataset": "silverbox",
         "tests": {"multisine": 7.73e-3, "arrow": 4.15e-3}, "what": "SysIdentPy's published number"}]}
    bla = {"linear_baseline": {"value": 44.4e-3, "model": "BLA"}}
    rows = [_row("arx", "wiener-hammerstein", "test", 56e-3, refs=bla),
            _row("narx-poly", "wiener-hammerstein", "test", 17e-3, refs=bla),
            _row("narmax-poly", "wiener-hammerstein", "test", 50e-3, refs=bla),  # beats ARX, not the BLA
            _row("narmax-poly", "silverbox", "multisine", 3e-3),
            _row("narmax-poly", "silverbox", "arrow", 4.2e-3)]  # does not beat 4.15 mV
    fails = scoring.check({"mode": "quick", "rows": rows}, base)
    assert len(fails) == 2
    assert any("narmax-poly on wiener-hammerstein/test" in f and "BLA" in f for f in fails)
    assert any("narmax-poly on silverbox/arrow" in f and "SysIdentPy" in f for f in fails)
    # an explicit, documented exemption removes exactly that pair
    base["rules"][0]["exemptions"] = [{"identifier": "narmax-poly", "dataset": "wiener-hammerstein", "why": "test"}]
    assert len(scoring.check({"mode": "quick", "rows": rows}, base)) == 1


def test_scores_match_an_independent_computation():
    ds = load_dataset("cascaded-tanks")
    rows, preds = scoring.score_pair("toy-arx", ds, factory=lambda n: ToyARX, params={"ny": 2, "nu": 2})
    (r,) = rows
    model = ToyARX(2, 2).fit(ds.est)
    y = ds.tests["test"].y
    yfr = model.predict(ds.tests["test"], horizon=None)
    skip = max(ds.init_samples, 2)
    assert r["skip"] == 4
    e = y[skip:] - yfr[skip:]
    assert r["free_run"]["rmse"] == pytest.approx(np.sqrt(np.mean(e ** 2)), rel=1e-12)
    assert r["free_run"]["r2"] == pytest.approx(1 - np.sum(e ** 2) / np.sum((y[skip:] - y[skip:].mean()) ** 2), rel=1e-12)
    assert np.array_equal(preds["test"], yfr)
    assert r["n_parameters"] == 5 and r["references"]["linear_baseline"]["value"] == 0.75


def test_normalised_wrapper_is_exact_for_an_affine_invariant_model():
    """ARX with an intercept is invariant to affine scaling of u and y: fitting on normalised data and mapping
    back must give the same free run as fitting on the raw data."""
    ds = load_dataset("cascaded-tanks")
    raw = ToyARX(2, 2).fit(ds.est).predict(ds.tests["test"], horizon=None)
    wrapped = scoring.Normalised(ToyARX(2, 2)).fit(ds.est)
    assert wrapped.max_lag_ == 2 and wrapped.n_parameters_ == 5
    np.testing.assert_allclose(wrapped.predict(ds.tests["test"], horizon=None), raw, rtol=1e-9, atol=1e-9)


def test_make_floors_adds_margin_and_keeps_rules():
    run = {"mode": "quick", "rows": [_row("arx", "cascaded-tanks", "test", 1.0), _row("x", "d", "t", float("nan"), status="diverged")]}
    prev = {"format": scoring.BASELINES_FORMAT, "modes": {"full": {"a": {}}}, "rules": [{"rule": "beats_linear", "datasets": []}]}
    new = scoring.make_floors(run, margin=0.1, previous=prev)
    assert new["modes"]["quick"] == {"arx": {"cascaded-tanks": {"test": {"max_rmse": 1.1, "measured": 1.0, "units": "V",
                                                                          "r2_measured": 0.0}}}}
    assert new["modes"]["full"] == {"a": {}} and new["rules"] == prev["rules"]


# ------------------------------------------------------------------------------------- the real floors
def _available(ident: str) -> bool:
    from sysid.registry import available_identifiers

    return ident in available_identifiers()


def test_baselines_file_is_consistent():
    base = scoring.load_baselines()
    assert base["format"] == scoring.BASELINES_FORMAT
    for mode, floors in base["modes"].items():
        for ident, dsets in floors.items():
            for dname, tests in dsets.items():
                for test, f in tests.items():
                    # a floor is a measured value plus a margin, never below what was measured
                    assert f["max_rmse"] >= f["measured"] > 0, (mode, ident, dname, test)
    kinds = {r["rule"] for r in base["rules"]}
    assert {"beats_linear", "beats_value"} <= kinds


def _degraded(offset: float):
    from sysid.registry import get_identifier

    def factory(name):
        cls = get_identifier(name)

        class Degraded(cls):
            """The real identifier with a deliberate error: a constant offset on every prediction."""

            def predict(self, record, horizon=1):
                y = super().predict(record, horizon=horizon)
                return y + offset * np.std(record.y)

        return Degraded

    return factory


def test_degraded_identifier_fails_the_check():
    if not _available("narx-poly"):
        pytest.skip("narx-poly not built in this checkout")
    floors = scoring.load_baselines()["modes"].get("quick", {})
    if "cascaded-tanks" not in floors.get("narx-poly", {}):
        pytest.skip("no quick floor for narx-poly on cascaded-tanks yet")
    good = scoring.score(["narx-poly"], ["cascaded-tanks"], quick=True, sysidentpy=False)
    assert scoring.check(good) == []
    bad = scoring.score(["narx-poly"], ["cascaded-tanks"], quick=True, sysidentpy=False, factory=_degraded(0.5))
    fails = scoring.check(bad)
    assert fails and all("narx-poly on cascaded-tanks/test" in f for f in fails)


def test_score_cli_check_exit_codes(tmp_path, capsys):
    if not _available("narx-poly"):
        pytest.skip("narx-poly not built in this checkout")
    args = ["score", "--quick", "--identifiers", "narx-poly", "--datasets", "cascaded-tanks", "--no-sysidentpy"]
    assert main(args + ["--check", "--report", str(tmp_path / "rep")]) == 0
    assert (tmp_path / "rep" / "score.md").read_text().count("narx-poly") == 1
    impossible = {"format": scoring.BASELINES_FORMAT, "rules": [],
                  "modes": {"quick": {"narx-poly": {"cascaded-tanks": {"test": {"max_rmse": 1e-9, "measured": 1e-9}}}}}}
    path = tmp_path / "b.json"
    path.write_text(json.dumps(impossible))
    capsys.readouterr()
    assert main(args + ["--check", "--baselines", str(path), "--json"]) == 1
    err = capsys.readouterr().err
    assert "narx-poly on cascaded-tanks/test" in err
    assert main(["score", "--identifiers", "nosuch"]) == 2


@pytest.mark.slow
def test_quick_check_passes_on_this_build():
    """What CI runs: `piezotwin score --quick --check` (about 1 CPU-minute)."""
    assert main(["score", "--quick", "--check", "--no-sysidentpy", "--json"]) == 0
