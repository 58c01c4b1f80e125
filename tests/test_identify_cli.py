"""``piezotwin identify``: JSON contract, model file round trip, errors, plots; and sysid.evaluation.evaluate."""

import json

import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.cli.identify import identify
from sysid.base import load_model
from sysid.data.io import read_record, write_record
from sysid.evaluation.evaluate import evaluate
from sysid.evaluation.metrics import r2
from tests._polysys import narmax_record, narx_record

KEYS = {"identifier", "params", "n_parameters", "fit_seconds", "terms", "estimation", "validation"}


@pytest.fixture
def files(tmp_path):
    est, val = tmp_path / "est.npz", tmp_path / "val.npz"
    write_record(narx_record(1500, seed=0, noise=0.01), est)
    write_record(narx_record(800, seed=1, noise=0.01), val)
    return est, val


@pytest.mark.parametrize(
    "ident,sets",
    [
        ("narx-poly", "ny=2,nu=2,degree=2,rho_p=1e-4,criterion=err"),
        ("narmax-poly", "ny=2,nu=2,ne=3,degree=2,rho_p=1e-4,criterion=bic"),
        ("arx", "ny=2,nu=2"),
        ("armax", "ny=2,nu=2,ne=2"),
    ],
)
def test_identify_json_and_model_round_trip(files, tmp_path, capsys, ident, sets):
    est, val = files
    model_path = tmp_path / f"{ident}.json"
    code = main(
        ["identify", ident, "--est", str(est), "--val", str(val), "--set", sets, "--json", "-o", str(model_path)]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert KEYS <= set(out)
    assert out["identifier"] == ident
    for part in ("estimation", "validation"):
        for mode in ("one_step", "free_run"):
            assert set(out[part][mode]) >= {"r2", "nrmse"}
            assert out[part][mode]["nrmse"] == pytest.approx(np.sqrt(1 - out[part][mode]["r2"]), rel=1e-6)
    assert out["n_parameters"] == (len(out["terms"]) or out["n_parameters"])
    if ident.endswith("poly"):
        assert all({"term", "parameter", "err", "stderr"} <= set(t) for t in out["terms"])
        assert out["validation"]["free_run"]["r2"] > 0.99
    # the saved model loads back and predicts identically; its scores are those of the JSON
    m = load_model(model_path)
    rec = read_record(str(val))
    again = evaluate(m, rec)
    assert again["free_run"]["r2"] == pytest.approx(out["validation"]["free_run"]["r2"], rel=1e-12)
    assert again["one_step"]["r2"] == pytest.approx(out["validation"]["one_step"]["r2"], rel=1e-12)


def test_identify_exact_terms_text_output(files, capsys):
    est, _ = files
    assert main(["identify", "narx-poly", "--est", str(est), "--set", "ny=2,nu=2"]) == 0
    text = capsys.readouterr().out
    for term in ("y(k-1)*u(k-1)", "u(k-2)", "u(k-1)^2", "y(k-1)"):
        assert term in text
    assert "validation" not in text


def test_identify_several_experiments_and_plots(tmp_path, capsys):
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    write_record(narmax_record(1000, seed=1), a)
    write_record(narmax_record(1000, seed=2), b)
    code = main(
        [
            "identify",
            "narmax-poly",
            "--est",
            str(a),
            "--est",
            str(b),
            "--set",
            "ne=1",
            "--plots",
            str(tmp_path / "plots"),
            "--json",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["validation"] is None and out["estimation"]["one_step"]["r2"] > 0.95
    for f in out["plots"].values():
        assert f.endswith(".png") and (tmp_path / "plots").exists()
        with open(f, "rb") as fh:
            assert fh.read(8) == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize(
    "args,msg",
    [
        (["identify", "nosuch", "--est", "EST"], "unknown identifier"),
        (["identify", "narx-poly", "--est", "EST", "--set", "bogus=1"], "bogus"),
        (["identify", "narx-poly", "--est", "EST", "--set", "ny=two"], "ny"),
        (["identify", "narx-poly", "--est", "EST", "--set", "ny=40,nu=40"], "too few"),
        (["identify", "arx", "--est", "missing.npz"], "missing.npz"),
    ],
)
def test_identify_errors_exit_2_one_line(files, capsys, args, msg):
    est, _ = files
    args = [str(est) if a == "EST" else a for a in args]
    if "too few" in msg:
        rec = read_record(str(est))
        tmp = est.parent / "short.npz"
        write_record(rec[:60], tmp)
        args = [str(tmp) if a == str(est) else a for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and msg in err and "Traceback" not in err


def test_identify_helper_is_generic_over_registry():
    rec = narx_record(600, seed=3, noise=0.01)
    model, summary = identify("arx", rec, rec, ["ny=1,nu=2"])
    assert summary["params"]["ny"] == 1 and summary["terms"]
    assert summary["validation"]["one_step"]["r2"] == pytest.approx(r2(rec.y, model.predict(rec, 1), skip=2))


def test_report_plots_survive_a_diverging_free_run(tmp_path):
    from sysid.data.record import Record
    from sysid.polynomial.narmax import NARXPoly
    from sysid.report.plots import identification_report

    rng = np.random.default_rng(0)
    n = 400
    u = rng.uniform(-0.3, 0.3, n)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = 0.5 * y[k - 1] + u[k - 1] + 0.3 * y[k - 1] ** 2
    m = NARXPoly(ny=1, nu=1, degree=2).fit(Record(u, y, fs=1.0))
    big = Record(u + 5.0, y, fs=1.0)
    files = identification_report(m, big, tmp_path / "rep")
    assert m.diverged_at_ is not None
    assert len(files) == 5 and all((tmp_path / "rep" / f"{k}.png").exists() for k in files)
