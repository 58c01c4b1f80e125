"""Delay estimate, order selection and practitioner warnings of the linear identifiers; identify CLI keys."""

import json

import numpy as np
import pytest
from scipy.signal import lfilter

from benchmarks.cli.identify import identify
from sysid.data.io import write_record
from sysid.data.record import Record
from sysid.evaluation.advice import closed_loop_correlation, practitioner_warnings
from sysid.linear.arx import ARX
from sysid.linear.order import delay_estimate, order_table, plot_order_table

F = [1.0, -1.5, 0.7]
B = [1.0, 0.5]


def _sys(n=3000, nk=1, seed=0, sigma=0.1):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = lfilter(np.r_[np.zeros(nk), B], F, u) + sigma * rng.standard_normal(n)
    return Record(u, y, fs=100.0)


@pytest.mark.parametrize("nk", [0, 1, 4, 17])
def test_delay_estimate_known_delay(nk):
    assert delay_estimate(_sys(nk=nk, seed=nk)) == [nk]


def test_delay_estimate_two_inputs_and_coloured_input():
    rng = np.random.default_rng(1)
    u = lfilter([1.0], [1.0, -0.7], rng.standard_normal((4000, 2)), axis=0)
    y = lfilter([0, 0, 1.0], [1, -0.5], u[:, 0]) + lfilter(np.r_[np.zeros(6), 0.7], [1, -0.3], u[:, 1])
    y = y + 0.05 * rng.standard_normal(4000)
    assert delay_estimate(Record(u, y, fs=1.0)) == [2, 6]


def test_order_table_aic_bic_and_validation(tmp_path):
    est, val = _sys(seed=1), _sys(seed=2)
    rows = order_table("oe", est, val, grid=(1, 2, 3, 4), options={"nk": 1})
    assert [r["order"] for r in rows] == [1, 2, 3, 4]
    bic = [r["bic"] for r in rows]
    assert int(np.argmin(bic)) == 1  # the true order (nb = nf = 2) has the lowest BIC
    assert rows[1]["val_r2"] > 0.99 > rows[0]["val_r2"]
    assert plot_order_table(rows, tmp_path / "o.png").stat().st_size > 0


def test_arx_auto_orders_improve_a_model_arx_2_2_cannot_fit():
    """A lightly damped 6th-order system: ARX(2,2) free-runs badly; orders="auto" picks a larger order that
    simulates well on fresh data."""
    rng = np.random.default_rng(4)
    poles = [0.98 * np.exp(1j * w) for w in (0.2, 0.6, 1.3)]
    a = np.real(np.poly(poles + [np.conj(p) for p in poles]))
    u = rng.standard_normal(8000)
    y = lfilter([0, 1.0, 0.3], a, u) + 0.05 * rng.standard_normal(8000)
    est, val = Record(u[:6000], y[:6000], fs=1.0), Record(u[6000:], y[6000:], fs=1.0)
    from sysid.evaluation.evaluate import evaluate

    r2_fixed = evaluate(ARX(orders="given").fit(est), val)["free_run"]["r2"]
    auto = ARX(orders="auto").fit(est)
    r2_auto = evaluate(auto, val)["free_run"]["r2"]
    assert auto.chosen_orders_["ny"] >= 6
    assert r2_auto > 0.95 and r2_auto > r2_fixed + 0.1


def _closed_loop(n=5000, seed=0):
    """Integrating plant y(t) = y(t−1) + 0.1 u(t−1) + e under proportional feedback u = 2 (r − y)."""
    rng = np.random.default_rng(seed)
    r = np.repeat(rng.standard_normal(n // 50), 50)
    e = 0.05 * rng.standard_normal(n)
    y, u = np.zeros(n), np.zeros(n)
    for t in range(1, n):
        y[t] = y[t - 1] + 0.1 * u[t - 1] + e[t]
        u[t] = 2.0 * (r[t] - y[t])
    return Record(u, y, fs=1.0)


def test_integrator_and_closed_loop_warning():
    rec = _closed_loop()
    m = ARX(ny=1, nu=1).fit(rec)
    w = practitioner_warnings(m, rec)
    assert len(w) == 1 and "unit circle" in w[0] and "closed-loop" in w[0]


def test_open_loop_has_no_closed_loop_correlation():
    for seed in range(5):
        c = closed_loop_correlation(_sys(seed=seed, n=5000))
        assert abs(c["rho"]) < c["threshold"]


def test_one_step_versus_free_run_warning():
    """An ARX(2,2) fitted to a high-order lightly damped system: one-step R² near 1, free run much worse."""
    summary = {"estimation": {"one_step": {"r2": 0.99995}, "free_run": {"r2": 0.44}}}
    w = practitioner_warnings(object(), _sys(), None, summary)
    assert len(w) == 1 and "0.99995" in w[0] and "0.44" in w[0]
    ok = {"estimation": {"one_step": {"r2": 0.995}, "free_run": {"r2": 0.99}}}
    assert practitioner_warnings(object(), _sys(), None, ok) == []


def test_identify_json_parameters_warnings_and_range(tmp_path, capsys):
    from benchmarks.cli import main

    est = _sys(seed=3)
    val = Record(2.0 * est.u, 2.0 * est.y, fs=100.0)
    write_record(est, tmp_path / "est.npz")
    write_record(val, tmp_path / "val.npz")
    rc = main(
        [
            "identify",
            "oe",
            "--est",
            str(tmp_path / "est.npz"),
            "--val",
            str(tmp_path / "val.npz"),
            "--set",
            "nb=2,nf=2,nk=1",
            "--json",
        ]
    )
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    names = [p["name"] for p in out["parameters"]]
    assert names == ["b1", "b2", "f1", "f2"]
    vals = {p["name"]: p for p in out["parameters"]}
    assert abs(vals["f1"]["value"] - F[1]) < 4 * vals["f1"]["std"]
    assert any("beyond the estimation range" in w for w in out["warnings"])
    rc = main(["identify", "n4sid", "--est", str(tmp_path / "est.npz")])
    text = capsys.readouterr().out
    assert rc == 0 and "nx = 2" in text


def test_identify_reports_chosen_orders():
    _, s = identify("oe", _sys(seed=5), None, {})
    assert s["chosen_orders"] == {"nk": [1], "nb": [2], "nf": [2]}


def test_orders_command_table_json_and_bad_grid(tmp_path, capsys):
    from benchmarks.cli import main

    write_record(_sys(seed=6, nk=2), tmp_path / "est.npz")
    write_record(_sys(seed=7, nk=2), tmp_path / "val.npz")
    rc = main(
        [
            "orders",
            "oe",
            "--est",
            str(tmp_path / "est.npz"),
            "--val",
            str(tmp_path / "val.npz"),
            "--grid",
            "1-2-3",
            "--json",
            "--plot",
            str(tmp_path / "o.png"),
        ]
    )
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["delay"] == [2] and [r["order"] for r in out["rows"]] == [1, 2, 3]
    assert out["best"]["bic"] == 2 and (tmp_path / "o.png").exists()
    assert main(["orders", "oe", "--est", str(tmp_path / "est.npz"), "--grid", "0-x"]) == 2
