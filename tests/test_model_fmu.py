"""Identified models as FMUs: per-sample stepper == free run bit for bit; exported ARX, narx-poly, a NARX network,
a PNLSS and a Wiener–Hammerstein model validate with fmpy and their FMPy simulation equals the model's own free run
(1e-9 relative)."""

import json
import zipfile

import numpy as np
import pytest

from sysid.errors import ConfigError
from sysid.linear.arx import ARMAX, ARX
from sysid.neural.narx_mlp import NARXMLP
from sysid.nonlinear.pnlss import PNLSS
from sysid.nonlinear.wiener_hammerstein import WienerHammerstein
from sysid.polynomial.narmax import NARMAXPoly, NARXPoly
from sysid.stepper import make_stepper
from tests._polysys import narx_record

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy.validation import validate_fmu  # noqa: E402

from twins.fmu.check import fmu_simulate  # noqa: E402


@pytest.fixture(scope="module")
def est():
    r = narx_record(1500, seed=0, noise=0.01)
    return r.replace(fs=2000.0, units={"u": "V", "y": "um"})


def _models(est):
    return {
        "arx": ARX(ny=3, nu=3).fit(est),
        "armax": ARMAX(ny=2, nu=2, ne=1).fit(est),
        "narx-poly": NARXPoly(degree=2).fit(est),
        "narmax-poly": NARMAXPoly(ne=1).fit(est),
        "narx-mlp": NARXMLP(ny=3, nu=3, hidden=[8, 8], epochs=3, device="cpu", linear=True, seed=1).fit(est),
        "pnlss": PNLSS(nx=2, degree=2, max_nfev=20, starts=1).fit(est),
        "wh-bla": WienerHammerstein(nb=3, nf=2, knots=4, extra_zeros=1, warmup=2, max_nfev=20).fit(est),
    }


def test_stepper_is_the_free_run_bit_for_bit(est):
    u = narx_record(2000, seed=5).u
    for name, m in _models(est).items():
        s = make_stepper(m)
        out = np.array([s.step(v) for v in u])
        assert np.array_equal(out, m.predict(u)), name
        s.reset()
        assert np.array_equal(np.array([s.step(v) for v in u[:50]]), out[:50]), name


def test_stepper_refuses_rnn():
    from sysid.neural.rnn import RNNStateSpace

    with pytest.raises(ConfigError, match="supported: arx"):
        make_stepper(RNNStateSpace())


@pytest.mark.parametrize("name", ["arx", "narx-poly", "narx-mlp", "pnlss", "wh-bla"])
def test_exported_model_fmu_validates_and_equals_free_run(name, est, tmp_path, capsys):
    from benchmarks.cli import main

    m = _models(est)[name]
    model_file = m.save(tmp_path / f"{name}.npz")
    fmu = tmp_path / "fmus" / f"{name}.fmu"
    assert main(["export-fmu", "--model", str(model_file), "-o", str(fmu), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["validation_problems"] == [] and out["fs"] == 2000.0
    assert validate_fmu(str(fmu)) == []
    with zipfile.ZipFile(fmu) as z:
        md = z.read("modelDescription.xml").decode()
    assert 'stepSize="0.0005"' in md and 'name="u"' in md and 'name="y"' in md
    u = narx_record(3000, seed=7).u
    y_fmu = fmu_simulate(fmu, u, 2000.0)
    ref = m.predict(u)
    np.testing.assert_allclose(y_fmu, ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(ref)))
    if name == "arx":  # the step check shared with the twins' slave: a discrete-time model takes exactly 1/fs
        import fmpy

        log = []
        with pytest.raises(Exception, match="fmi2DoStep failed"):
            fmpy.simulate_fmu(
                str(fmu),
                stop_time=0.01,
                output_interval=1e-3,
                debug_logging=True,
                logger=lambda c, i, s, cat, msg: log.append(msg.decode() if isinstance(msg, bytes) else str(msg)),
            )
        assert "must be 1/fs = 0.0005 s" in "\n".join(log)


def test_export_refuses_model_without_stepper_and_bad_choice(est, tmp_path, capsys):
    from benchmarks.cli import main

    assert main(["export-fmu"]) == 2
    assert "give a twin name or --model" in capsys.readouterr().err
