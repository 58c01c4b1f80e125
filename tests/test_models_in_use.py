"""Identified models in use: identify -> predict -> compare from the CLI and from Python, model files
(format 2, old formats still read, bad files refused with one line), the array API."""

import json

import numpy as np
import pytest

from benchmarks.cli import main
from sysid.base import Identifier, load_model
from sysid.data.io import read_record, write_record
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError, InputError
from sysid.linear.arx import ARX
from sysid.polynomial.narmax import NARXPoly
from sysid.registry import IDENTIFIERS, get_identifier
from tests._polysys import narx_record

torch = pytest.importorskip("torch")

SETTINGS = {
    "fir": "nb=8,nk=1",
    "arx": "ny=2,nu=2",
    "armax": "ny=2,nu=2,ne=1",
    "narx-poly": "ny=2,nu=2,degree=2",
    "narmax-poly": "ny=2,nu=2,ne=1,degree=2",
    "narx-mlp": "ny=2,nu=2,hidden=6,epochs=2,device=cpu",
    "narx-mlp-sim": "ny=2,nu=2,hidden=6,epochs=1,pretrain_epochs=1,window=10,device=cpu",
    "rnn": "n_state=3,n_enc=3,enc_hidden=6,window=20,epochs=1,device=cpu",
    "bla": "nb=3,nf=2",
    "narx-poly-sim": "ny=2,nu=2,degree=2",
    "oe": "nb=2,nf=2,nk=1",
    "bj": "nb=2,nf=2,nc=1,nd=1,nk=1",
    "n4sid": "nx=2",
    "ss-encoder": "nx=2,ny=3,nu=3,f_hidden=4,h_hidden=4,e_hidden=4,T=10,epochs=1,device=cpu",
    "wh-net": "channels=2,hidden=4,nb=2,na=2,epochs=2,warmup=2,device=cpu",
    "oe-echo": "nb=3,nf=2,nk=1,echo_lag=6,echo_width=1",
    "pnlss": "nx=2,degree=2",
    "wh-bla": "nb=3,nf=2,knots=4,extra_zeros=1,warmup=2,max_nfev=20",
}


def true_free_run(u):
    """The system of tests._polysys simulated from rest (y = 0 before k = 2), written out here."""
    y = np.zeros(len(u))
    for k in range(2, len(u)):
        y[k] = 0.2 * y[k - 1] + 0.1 * y[k - 1] * u[k - 1] + 0.9 * u[k - 2] - 0.3 * u[k - 1] ** 2
    return y


def fit_percent(y, yh):
    return 100.0 * (1.0 - np.linalg.norm(y - yh) / np.linalg.norm(y - y.mean()))


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("data")
    est, val = narx_record(1200, seed=0), narx_record(600, seed=1)
    est.units, val.units = {"u": "V", "y": "um"}, {"u": "V", "y": "um"}
    write_record(est, d / "est.npz")
    write_record(val, d / "val.npz")
    with open(d / "val_u.csv", "w") as fh:  # input only, with a t column
        fh.write("t,u\n" + "".join(f"{k / val.fs!r},{float(v)!r}\n" for k, v in enumerate(val.u)))
    return d, est, val


def test_every_identifier_is_covered():
    assert set(SETTINGS) == set(IDENTIFIERS)


@pytest.mark.heavy
@pytest.mark.parametrize("ident", list(SETTINGS))
def test_identify_predict_compare_cli(ident, data, tmp_path, capsys):
    d, est, val = data
    model = tmp_path / f"{ident}.npz"
    assert (
        main(["identify", ident, "--est", str(d / "est.npz"), "--set", SETTINGS[ident], "-o", str(model), "--json"])
        == 0
    )
    capsys.readouterr()
    m = load_model(model)
    assert m.name == ident and m.fs_ == 1.0
    assert m.estimation_["units"] == {"u": "V", "y": "um"} and m.estimation_["n_samples"] == 1200
    for horizon, h in (("1", 1), ("3", 3), ("inf", None)):
        out = tmp_path / f"pred{horizon}.npz"
        assert (
            main(["predict", str(model), "--data", str(d / "val.npz"), "--horizon", horizon, "--json", "-o", str(out)])
            == 0
        )
        res = json.loads(capsys.readouterr().out)
        yh = m.predict(val, h)
        assert np.array_equal(read_record(out).y, yh)  # the record written is the model's prediction
        L = m.max_lag_
        assert res["skip"] == L
        assert res["metrics"]["fit_percent"] == pytest.approx(fit_percent(val.y[L:], yh[L:]), rel=1e-9)
        rmse = np.sqrt(np.mean((val.y[L:] - yh[L:]) ** 2))
        assert res["metrics"]["rmse"] == pytest.approx(rmse, rel=1e-9)
    # input-only CSV: free run from zero initial conditions, the same as the Python API without y
    assert main(["predict", str(model), "--data", str(d / "val_u.csv"), "--json", "-o", str(tmp_path / "p.csv")]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["horizon"] == "inf" and res["initial_conditions"] == "zero" and res["metrics"] is None
    np.testing.assert_allclose(read_record(tmp_path / "p.csv").y, m.predict(val.u), rtol=0, atol=0)
    # compare: two models on the same samples
    other = tmp_path / "arx.json"
    assert main(["identify", "arx", "--est", str(d / "est.npz"), "--set", "ny=2,nu=2", "-o", str(other)]) == 0
    capsys.readouterr()
    assert (
        main(
            [
                "compare",
                str(model),
                str(other),
                "--data",
                str(d / "val.npz"),
                "--json",
                "--report",
                str(tmp_path / "rep"),
            ]
        )
        == 0
    )
    res = json.loads(capsys.readouterr().out)
    skip = max(m.max_lag_, 2)
    assert [r["skip"] for r in res["models"]] == [skip, skip]
    yf = m.predict(val, None)
    assert res["models"][0]["metrics"]["r2"] == pytest.approx(
        1 - np.sum((val.y[skip:] - yf[skip:]) ** 2) / np.sum((val.y[skip:] - val.y[skip:].mean()) ** 2), rel=1e-9
    )
    assert (tmp_path / "rep" / "compare.png").stat().st_size > 10_000


def test_input_only_free_run_is_the_true_system(data, tmp_path, capsys):
    """Noise-free data of a polynomial NARX: the identified model run from the input alone reproduces the
    system simulated from rest (closed-form recursion in this test)."""
    d, est, val = data
    model = tmp_path / "m.npz"
    assert main(["identify", "narx-poly", "--est", str(d / "est.npz"), "--set", "criterion=err", "-o", str(model)]) == 0
    assert main(["predict", str(model), "--data", str(d / "val_u.csv"), "-o", str(tmp_path / "p.npz")]) == 0
    text = capsys.readouterr().out
    assert "free run" in text and "zero initial conditions" in text
    np.testing.assert_allclose(read_record(tmp_path / "p.npz").y, true_free_run(val.u), atol=1e-9)
    # with y: the fit is printed (noise-free data, true structure: 100 %)
    assert main(["predict", str(model), "--data", str(d / "val.npz"), "--horizon", "inf"]) == 0
    assert "fit 100.000 %" in capsys.readouterr().out


@pytest.mark.parametrize("ident", list(SETTINGS))
def test_python_api_on_arrays(ident, data, tmp_path):
    _, est, val = data
    cls = get_identifier(ident)
    a = cls.from_assignments(dict(kv.split("=") for kv in SETTINGS[ident].split(",")))
    m = a.fit(est.u, est.y, fs=est.fs)
    assert m is a
    assert m.estimation_["fs"] == 1.0
    free = m.predict(val.u)  # free run from the input alone
    assert free.shape == val.u.shape and np.all(free[: m.max_lag_] == 0.0)
    assert np.array_equal(free, m.predict(Record(val.u, None, fs=1.0)))
    assert np.array_equal(m.predict(val.u, val.y), m.predict(val, 1))  # with y: one step by default
    assert np.array_equal(m.predict(val.u, val.y, horizon=None), m.predict(val, None))
    assert m.score(val.u, val.y) == pytest.approx(m.score(val, horizon=None), rel=0, abs=0)
    with pytest.raises(ConfigError, match="needs the measured output y"):
        m.predict(val.u, horizon=2)
    for suffix in (".npz", ".json", ".model"):
        m2 = cls.load(m.save(tmp_path / f"m{suffix}"))
        assert np.array_equal(m2.predict(val.u), free)
        assert np.array_equal(m2.predict(val, 3), m.predict(val, 3))
        assert m2.estimation_ == m.estimation_
    with pytest.raises(DataError, match=f"holds a {ident} model, not"):
        (ARX if ident != "arx" else NARXPoly).load(tmp_path / "m.npz")


def test_fit_on_arrays_equals_fit_on_record(data):
    _, est, val = data
    a = NARXPoly().fit(est.u, est.y, fs=est.fs)
    b = NARXPoly().fit(est)
    assert np.array_equal(a.predict(val, None), b.predict(val, None))
    assert a.estimation_["sha256"] == b.estimation_["sha256"]
    c = NARXPoly().fit(est.u, est.y + 1e-12, fs=est.fs)
    assert c.estimation_["sha256"] != a.estimation_["sha256"]


def test_model_file_is_plain_json_and_npz(data, tmp_path):
    _, est, _ = data
    m = ARX(orders="given").fit(est)  # the options an ARX() had before it chose its own orders
    p = m.save(tmp_path / "m.npz")
    with np.load(p, allow_pickle=False) as z:
        head = json.loads(str(z["header"]))
    assert head["format"] == "piezotwin-model" and head["version"] == 2 and head["identifier"] == "arx"
    assert head["params"] == {"ny": 2, "nu": 2, "nk": 1, "intercept": False, "orders": "given", "max_order": 100}
    assert head["estimation"]["fs"] == 1.0 and len(head["estimation"]["sha256"]) == 64
    assert head["checksum"].startswith("sha256:")


def test_rate_mismatch_is_refused(data, tmp_path, capsys):
    d, est, _ = data
    model = tmp_path / "m.npz"
    ARX().fit(est).save(model)
    assert main(["predict", str(model), "--data", str(d / "val_u.csv"), "--fs", "1"]) == 0
    capsys.readouterr()
    write_record(narx_record(300, seed=4).replace(fs=2.0), tmp_path / "fast.npz")
    assert main(["predict", str(model), "--data", str(tmp_path / "fast.npz")]) == 2
    err = capsys.readouterr().err
    assert "identified at 1 Hz" in err and len(err.strip().splitlines()) == 1


def test_old_formats_still_read(data, tmp_path):
    """Version-1 JSON (earlier releases) and torch .pt files load and predict as the model."""
    _, est, val = data
    m = NARXPoly().fit(est)
    v1 = {"format": "piezotwin-model/1", "identifier": m.name, "params": m.get_params(), "state": m._state()}
    p = tmp_path / "old.json"
    from sysid.data.jsonio import json_default

    p.write_text(json.dumps(v1, default=json_default))
    assert np.array_equal(load_model(p).predict(val, None), m.predict(val, None))
    from sysid.neural.narx_mlp import NARXMLP

    n = NARXMLP(ny=2, nu=2, hidden=[4], epochs=1, device="cpu").fit(est)
    assert np.array_equal(load_model(n.save(tmp_path / "n.pt")).predict(val, None), n.predict(val, None))


def _bad_files(tmp_path, est):
    good = ARX().fit(est).save(tmp_path / "arx.npz")
    raw = good.read_bytes()
    trunc = tmp_path / "truncated.npz"
    trunc.write_bytes(raw[: len(raw) // 2])
    # another identifier's file, renamed and edited to claim to be a narx-poly model
    edited = tmp_path / "narx.npz"
    with np.load(good, allow_pickle=False) as z:
        entries = {k: z[k] for k in z.files}
    head = json.loads(str(entries["header"]))
    assert head["identifier"] == "arx"
    head["identifier"] = "narx-poly"
    entries["header"] = np.array(json.dumps(head))
    np.savez(edited, **entries)
    js = ARX().fit(est).save(tmp_path / "arx.json")
    edited_json = tmp_path / "armax.json"
    edited_json.write_text(js.read_text().replace('"identifier": "arx"', '"identifier": "armax"'))
    legacy = tmp_path / "legacy.json"  # an old (unchecksummed) arx file edited to say narx-mlp
    m = ARX().fit(est)
    legacy.write_text(
        json.dumps(
            {
                "format": "piezotwin-model/1",
                "identifier": "narx-mlp",
                "params": {},
                "state": json.loads(json.dumps(m._state(), default=float)),
            }
        )
    )
    trunc_json = tmp_path / "truncated.json"
    trunc_json.write_text(js.read_text()[: len(js.read_text()) // 2])
    foreign = tmp_path / "settings.json"
    foreign.write_text(json.dumps({"name": "not a model", "values": [1, 2, 3]}))
    return {
        trunc: "truncated",
        trunc_json: "truncated",
        edited: "checksum",
        edited_json: "checksum",
        legacy: "not a valid narx-mlp model",
        foreign: "not a piezotwin model file",
    }


def test_bad_model_files_exit_2_with_one_line(data, tmp_path, capsys):
    d, est, _ = data
    for path, words in _bad_files(tmp_path, est).items():
        with pytest.raises(InputError, match=words):
            load_model(path)
        for argv in (
            ["predict", str(path), "--data", str(d / "val.npz")],
            ["compare", str(path), "--data", str(d / "val.npz")],
        ):
            assert main(argv) == 2, path
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1 and str(path) in err and words in err, err


def test_identifier_base_load_is_generic(data, tmp_path):
    _, est, _ = data
    p = ARX().fit(est).save(tmp_path / "m.npz")
    assert isinstance(Identifier.load(p), ARX)


def test_horizon_parsing():
    from sysid.report.compare import parse_horizon

    assert parse_horizon("inf") is None and parse_horizon("1") == 1 and parse_horizon("25") == 25
    for bad in ("0", "-3", "x", "1.5"):
        with pytest.raises(ConfigError):
            parse_horizon(bad)
