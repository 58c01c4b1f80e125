"""A nonlinear identifier run with defaults is held against the default linear model (arx) on the same hold-out:
a warning with both R² when it loses, and ``auto=true`` keeps the better one (library and CLI)."""

import json

import pytest

from benchmarks.cli import main
from sysid.data.io import write_record
from sysid.identify import free_run_r2, identify
from sysid.registry import get_identifier
from tests._modal import modal_records
from tests._polysys import narx_record


@pytest.fixture(scope="module")
def modal():
    return modal_records(n=4096)


def test_nonlinear_default_that_loses_says_so_with_both_r2(modal):
    est, val = modal
    model, s = identify("narx-poly", est, val, {})
    ref = s["linear_reference"]
    assert s["identifier"] == "narx-poly" and model.name == "narx-poly" and ref["better"] == "arx"
    # both numbers are the free-run R² of the two models on the same validation samples
    lin = get_identifier("arx")().fit(est)
    assert [ref["model_r2"], ref["r2"]] == pytest.approx(free_run_r2([model, lin], val), abs=1e-12)
    assert ref["r2"] > ref["model_r2"] + 0.1
    w = [x for x in s["warnings"] if "worse than the default linear model arx" in x]
    assert len(w) == 1 and f"{ref['model_r2']:.4f}" in w[0] and f"{ref['r2']:.4f}" in w[0]


def test_auto_keeps_the_linear_model_when_it_simulates_better(modal):
    est, val = modal
    model, s = identify("narx-poly", est, val, {"auto": "true"})
    assert model.name == "arx" and s["identifier"] == "arx"
    assert s["fallback"]["requested"] == "narx-poly" and s["fallback"]["kept"] == "arx"
    assert s["validation"]["free_run"]["r2"] > 0.99
    # without a validation record the comparison runs on the last 30 % of the estimation data
    model2, s2 = identify("narx-poly", est, None, {"auto": "true"})
    assert model2.name == "arx" and s2["linear_reference"]["holdout"].startswith("last 30%")


def test_a_nonlinear_model_that_wins_is_kept_without_warning():
    est, val = narx_record(1500, seed=0, noise=0.01), narx_record(800, seed=1, noise=0.01)
    model, s = identify("narx-poly", est, val, {"auto": "true"})
    assert model.name == "narx-poly" and s["linear_reference"]["better"] == "narx-poly" and "fallback" not in s
    assert not any("default linear model" in w for w in s["warnings"])
    # options given (not the defaults) and no auto: no comparison
    _, s3 = identify("narx-poly", est, val, {"ny": "2"})
    assert "linear_reference" not in s3


def test_identify_cli_auto_writes_the_kept_model(modal, tmp_path, capsys):
    est, val = modal
    write_record(est, tmp_path / "est.npz")
    write_record(val, tmp_path / "val.npz")
    args = ["identify", "narx-poly", "--est", str(tmp_path / "est.npz"), "--val", str(tmp_path / "val.npz")]
    assert main([*args, "--set", "auto=true", "--json", "-o", str(tmp_path / "m.json")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["identifier"] == "arx" and out["fallback"]["requested"] == "narx-poly"
    assert json.loads((tmp_path / "m.json").read_text())["identifier"] == "arx"
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "linear reference arx" in text and "worse than the default linear model arx" in text
    assert main([*args, "--set", "auto=maybe"]) == 2
    assert "auto: expected a boolean" in capsys.readouterr().err
    assert main(["identify", "arx", "--est", str(tmp_path / "est.npz"), "--set", "auto=true"]) == 2
    err = capsys.readouterr().err
    assert "arx is linear" in err and "orders=auto" in err and len(err.strip().splitlines()) == 1


def test_a_comparison_that_cannot_be_made_is_reported_not_raised(monkeypatch):
    """When the linear reference cannot be fitted (here: the registry refuses it), the nonlinear model is still
    returned, with the reason under linear_reference and no fallback."""
    import sysid.identify as ident

    monkeypatch.setattr(ident, "LINEAR_DEFAULT", "nosuch")
    est, val = narx_record(600, seed=0, noise=0.01), narx_record(300, seed=1, noise=0.01)
    model, s = ident.identify("narx-poly", est, val, {"auto": "true"})
    assert model.name == "narx-poly" and "fallback" not in s
    assert s["linear_reference"]["identifier"] == "nosuch" and "unknown identifier" in s["linear_reference"]["error"]
