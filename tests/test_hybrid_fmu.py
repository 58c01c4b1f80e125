"""The hybrid twin (physics twin + fitted remainder) as an FMU, like any twin: the multi-input stepper of a
polynomial model equals its free run bit for bit; the hybrid's per-sample stepper equals its ``simulate``; a
saved hybrid twin exported by ``piezotwin export-fmu --hybrid`` validates with fmpy and its FMPy simulation equals
the hybrid twin's Python simulation (1e-9 relative) on an input the fit never saw; bad input is one line, exit 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from test_hybrid import _path_records

from sysid.data.record import Record
from sysid.errors import ConfigError
from sysid.linear.arx import ARX
from sysid.polynomial.narmax import NARXPoly
from sysid.stepper import make_stepper
from twins.hybrid import DEFAULT_CANDIDATES, HybridTwin


def _miso_record(n: int = 1500, seed: int = 0) -> Record:
    """Two inputs, one output: y = 0.5 y[k−1] + u1[k−1] − 0.3 u2[k] + 0.2 u1[k−1]·u2[k−1] (+ 1 % noise)."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 2))
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = 0.5 * y[k - 1] + u[k - 1, 0] - 0.3 * u[k, 1] + 0.2 * u[k - 1, 0] * u[k - 1, 1]
    return Record(u=u, y=y + 0.01 * rng.standard_normal(n), fs=1000.0)


def test_multi_input_polynomial_stepper_is_the_free_run_bit_for_bit():
    est, u = _miso_record(), _miso_record(800, seed=3).u
    for m in (ARX(ny=2, nu=2, nk=0, orders="given").fit(est), NARXPoly(ny=2, nu=2, nk=0, degree=2).fit(est)):
        s = make_stepper(m)
        out = np.array([s.step(row) for row in u])
        assert np.array_equal(out, m.predict(Record(u=u, y=None, fs=1000.0), horizon=None).reshape(-1)), m.name


def test_model_fmu_refuses_a_multi_input_model(tmp_path):
    from twins.fmu.model_export import export_model_fmu

    m = ARX(ny=1, nu=1, nk=0, orders="given").fit(_miso_record(300))
    with pytest.raises(ConfigError, match="one input u"):
        export_model_fmu(m, tmp_path / "m.fmu")


@pytest.fixture(scope="module")
def hybrids():
    tw, est, val, _ = _path_records()
    return {ident: HybridTwin(tw, [(ident, settings)]).fit(est) for ident, settings in DEFAULT_CANDIDATES}, val


@pytest.mark.parametrize("ident", [c[0] for c in DEFAULT_CANDIDATES])
def test_hybrid_stepper_is_its_simulation(hybrids, ident):
    hy, val = hybrids[0][ident], hybrids[1]
    st = hy.make_stepper(hy.fs_)
    y = np.array([st.step(v) for v in val.u])
    assert np.array_equal(y, hy.simulate(val.u, val.fs))
    st.reset()
    assert np.array_equal(np.array([st.step(v) for v in val.u[:60]]), y[:60])
    with pytest.raises(ConfigError, match="discrete-time at 1000 Hz"):
        hy.make_stepper(2000.0)


fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")


def test_saved_hybrid_exports_as_an_fmu_that_equals_its_simulation(hybrids, tmp_path, capsys):
    from fmpy.validation import validate_fmu

    from benchmarks.cli import main
    from twins.fmu.check import fmu_simulate

    hy, val = hybrids[0]["narx-poly"], hybrids[1]  # the nonlinear remainder: the longer path through the stepper
    saved = hy.save(tmp_path / "hybrid.json")
    fmu = tmp_path / "fmus" / "hybrid.fmu"
    assert main(["export-fmu", "--hybrid", str(saved), "-o", str(fmu), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["validation_problems"] == [] and out["fs"] == 1000.0 and out["identifier"] == "narx-poly"
    assert validate_fmu(str(fmu)) == []
    back = HybridTwin.load(saved)
    ref = back.simulate(val.u, val.fs)
    y_fmu = fmu_simulate(fmu, val.u, val.fs)
    np.testing.assert_allclose(y_fmu, ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(ref)))
    # the remainder is there: the FMU is the hybrid, not the physics twin alone
    assert np.max(np.abs(ref - hy.physics.simulate(val.u, val.fs))) > 100 * 1e-9 * np.max(np.abs(ref))


def test_export_hybrid_bad_input(hybrids, tmp_path, capsys):
    from benchmarks.cli import main

    saved = hybrids[0]["arx"].save(tmp_path / "h.json")
    (tmp_path / "x.json").write_text(json.dumps({"format": "something-else"}))
    for args, msg in (
        (["--hybrid", str(tmp_path / "x.json")], "not a piezotwin hybrid twin file"),
        (["cantilever", "--hybrid", str(saved)], "one of the three"),
        (["--hybrid", str(saved), "--fs", "2000", "-o", str(tmp_path / "h.fmu")], "at 1000"),
        (["--hybrid", str(saved), "-o", str(tmp_path / "h.zip")], "must end in .fmu"),
    ):
        assert main(["export-fmu", *args]) == 2, args
        err = capsys.readouterr().err
        assert msg in err and "Traceback" not in err and len(err.strip().splitlines()) == 1, (args, err)
    # one run as a user's shell sees it: a separate process, exit status 2, one line
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks.cli", "export-fmu", "--hybrid", str(tmp_path / "x.json")],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
