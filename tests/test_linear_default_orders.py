"""ARX and ARMAX run without orders choose them and report the choice; explicit orders behave as before."""

import json

import numpy as np
import pytest
from scipy.signal import lfilter

from benchmarks.cli import main
from sysid.base import load_model
from sysid.data.io import write_record
from sysid.data.record import Record
from sysid.evaluation.evaluate import evaluate
from sysid.linear.arx import ARMAX, ARX


def _sixth_order(n=8000, seed=4):
    """Lightly damped 6th-order system that ARX(2, 2), the old default, cannot simulate."""
    rng = np.random.default_rng(seed)
    poles = [0.98 * np.exp(1j * w) for w in (0.2, 0.6, 1.3)]
    a = np.real(np.poly(poles + [np.conj(p) for p in poles]))
    u = rng.standard_normal(n)
    y = lfilter([0, 1.0, 0.3], a, u) + 0.05 * rng.standard_normal(n)
    return Record(u[:6000], y[:6000], fs=1.0), Record(u[6000:], y[6000:], fs=1.0)


def _lstsq_arx(rec, ny, nu, nk=1):
    """Closed-form ARX: ordinary least squares on the lagged columns."""
    L = max(ny, nk + nu - 1)
    y, u = rec.y.reshape(-1), rec.u.reshape(-1)
    cols = [y[L - i : len(y) - i] for i in range(1, ny + 1)] + [u[L - j : len(u) - j] for j in range(nk, nk + nu)]
    return np.linalg.lstsq(np.column_stack(cols), y[L:], rcond=None)[0]


def test_arx_without_orders_chooses_and_reports():
    est, val = _sixth_order()
    m = ARX().fit(est)
    assert m.chosen_orders_ == {"ny": m.ny, "nu": m.nu} and m.ny >= 6
    d = m.describe()
    assert d["chosen_orders"] == m.chosen_orders_ and any(r["chosen"] for r in d["order_selection"])
    old = ARX(orders="given").fit(est)  # what ARX() did before: ny = nu = 2
    assert evaluate(m, val)["free_run"]["r2"] > 0.95 > evaluate(old, val)["free_run"]["r2"] + 0.1
    # a refit chooses again
    assert m.fit(est).chosen_orders_ == d["chosen_orders"]


@pytest.mark.parametrize(
    "kw,orders", [({"ny": 3, "nu": 3}, (3, 3)), ({"ny": 5}, (5, 2)), ({"nu": 4}, (2, 4)), ({"orders": "given"}, (2, 2))]
)
def test_arx_explicit_orders_as_before(kw, orders):
    est, _ = _sixth_order()
    m = ARX(**kw).fit(est)
    assert (m.ny, m.nu) == orders and m.chosen_orders_ == {} and "chosen_orders" not in m.describe()
    np.testing.assert_allclose(m.theta_[0], _lstsq_arx(est, *orders), rtol=1e-9, atol=1e-12)


def test_set_orders_are_integers():
    m = ARX.from_assignments({"ny": "3", "nu": "4"})
    assert (m.ny, m.nu) == (3.0, 4.0)
    est, _ = _sixth_order()
    m.fit(est)
    assert (m.ny, m.nu) == (3, 4) and isinstance(m.ny, int)


def test_armax_without_orders_takes_the_arx_order_and_two_noise_lags():
    est, _ = _sixth_order()
    m = ARMAX(max_order=12).fit(est)
    n = ARX(max_order=12).fit(est).chosen_orders_["ny"]
    assert m.chosen_orders_ == {"ny": n, "nu": n, "ne": 2}
    given = ARMAX(ny=2, nu=2, ne=2).fit(est)
    assert given.chosen_orders_ == {} and len(given.theta_[0]) == 6
    np.testing.assert_array_equal(given.theta_[0], ARMAX(orders="given").fit(est).theta_[0])


def test_saved_model_keeps_chosen_orders_and_old_files_load(tmp_path):
    est, val = _sixth_order()
    m = ARX().fit(est)
    m2 = load_model(m.save(tmp_path / "auto.json"))
    assert m2.chosen_orders_ == m.chosen_orders_ and (m2.ny, m2.nu) == (m.ny, m.nu)
    np.testing.assert_array_equal(m2.predict(val, None), m.predict(val, None))
    # a file written before the orders were chosen: its options are ny = nu = 2, orders = "given"
    old = ARX(ny=2, nu=2, orders="given").fit(est)
    path = old.save(tmp_path / "old.json")
    head = json.loads(path.read_text())
    assert head["params"]["orders"] == "given" and "chosen_orders" not in json.dumps(head)
    o2 = load_model(path)
    assert o2.chosen_orders_ == {}
    np.testing.assert_array_equal(o2.predict(val, 3), old.predict(val, 3))


def test_identify_cli_reports_the_chosen_orders(tmp_path, capsys):
    est, val = _sixth_order()
    write_record(est, tmp_path / "est.npz")
    write_record(val, tmp_path / "val.npz")
    assert (
        main(["identify", "arx", "--est", str(tmp_path / "est.npz"), "--val", str(tmp_path / "val.npz"), "--json"]) == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["chosen_orders"]["ny"] == out["params"]["ny"] >= 6
    assert main(["identify", "arx", "--est", str(tmp_path / "est.npz")]) == 0
    text = capsys.readouterr().out
    assert f"orders chosen automatically (none given): ny={out['params']['ny']}, nu={out['params']['nu']}" in text
    assert main(["identify", "arx", "--est", str(tmp_path / "est.npz"), "--set", "ny=2,nu=2", "--json"]) == 0
    assert "chosen_orders" not in json.loads(capsys.readouterr().out)
