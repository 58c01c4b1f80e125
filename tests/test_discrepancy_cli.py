"""``piezotwin diagnose``: JSON contract, report folder, bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from sysid.data.io import write_record

cantilever = pytest.importorskip("twins.cantilever")


@pytest.fixture(scope="module")
def delayed_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("diag")
    truth = cantilever.CantileverTwin.from_options(effect=["input_delay:delay=4e-4"], seed=1)
    est = truth.generate("thesis-multisine", duration_s=0.5, signal_seed=2)
    val = cantilever.CantileverTwin(truth.params, truth.effects, 2).generate(
        "thesis-sines", freqs_hz="10-100", min_duration_s=0.1
    )
    write_record(est, d / "est.npz")
    write_record(val, d / "val.npz")
    return d


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "benchmarks.cli", "diagnose", *args], capture_output=True, text=True)


def test_cli_json_and_report(delayed_files):
    d = delayed_files
    r = _cli(
        "cantilever",
        "--data",
        str(d / "est.npz"),
        "--val",
        str(d / "val.npz"),
        "--candidates",
        "input_delay,saturation",
        "--max-rounds",
        "1",
        "--json",
        "--report",
        str(d / "rep"),
    )
    assert r.returncode == 0, r.stderr
    # one progress line per finished round on stderr, with --json too (stdout stays the JSON document alone)
    rounds = [ln for ln in r.stderr.splitlines() if ln.startswith("[diagnose] round 1: ")]
    assert len(rounds) == 1 and "trials, leader input_delay" in rounds[0], r.stderr
    out = json.loads(r.stdout)
    assert out["verdict"] == "discrepancy"
    assert list(out["causes"][0])[:4] == ["effect", "confidence", "evidence", "params"]
    assert out["causes"][0]["effect"] == "input_delay"
    assert abs(out["causes"][0]["params"]["input_delay_s"] - 4e-4) < 4e-5
    for part in ("baseline", "extended"):
        assert set(out[part]) == {"effects", "r2_val", "nrmse_val", "tests"}
        assert len(out[part]["tests"]["tests"]) == 5
    assert "input_delay" in out["extended"]["effects"] and "input_delay" not in out["baseline"]["effects"]
    assert set(out["gain"]) == {"nrmse_ratio", "r2_delta"} and out["gain"]["nrmse_ratio"] < 0.5
    for f in ("residuals.png", "spectra.png", "correlation_tests.png", "hysteresis.png", "index.html"):
        assert (d / "rep" / f).stat().st_size > 1000, f


def test_cli_bad_input(delayed_files, tmp_path):
    d = delayed_files
    r = _cli("cantilever", "--data", str(d / "est.npz"), "--candidates", "no_such_effect")
    assert r.returncode == 2 and "unknown effect" in r.stderr and "Traceback" not in r.stderr
    r = _cli("cantilever", "--data", str(tmp_path / "missing.npz"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    r = _cli("cantilever", "--data", str(d / "est.npz"), "--validation-start", "rest", "--max-rounds", "0")
    assert r.returncode == 2 and "validation_start 'rest'" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_cli_refuses_a_skip_that_leaves_nothing_to_score(delayed_files):
    """A skip past the record's end is refused with one line (it ended in numpy's gradient error before)."""
    d = delayed_files
    r = _cli("cantilever", "--data", str(d / "est.npz"), "--skip", "999999999", "--max-rounds", "0", "--no-calibrate")
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert "skip=999999999 leaves 0 of the" in r.stderr and len(r.stderr.strip().splitlines()) == 1
