"""One vocabulary of identifier options: lags ``ny``, ``nu`` and delay ``nk`` in every
identifier that has them, ``linear`` for the linear bypass; the older spellings (``n_y``, ``n_u``,
``linear_order``) work as deprecated aliases, through one table (sysid.config.ALIASES)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from benchmarks.cli import main
from sysid.config import ALIASES, resolve_aliases
from sysid.data.io import write_record
from sysid.data.record import Record
from sysid.errors import ConfigError
from sysid.registry import IDENTIFIERS, get_identifier

LAG_NAMES = {"ny", "nu", "n_y", "n_u"}
FAST = {
    "narx-mlp": "epochs=1,hidden=4",
    "narx-mlp-sim": "epochs=1,pretrain_epochs=1,hidden=4,window=10",
    "rnn": "epochs=1,n_state=2,enc_hidden=4,window=10",
    "ss-encoder": "epochs=1,T=10,f_hidden=4,h_hidden=4,e_hidden=4",
    "wh-net": "epochs=1,channels=2,hidden=4,nb=2,na=2",
}


def _available() -> list[str]:
    out = []
    for name in IDENTIFIERS:
        try:
            out.append((name, get_identifier(name)))
        except ConfigError:
            pass
    return out


def _with_lags():
    return [(n, c) for n, c in _available() if LAG_NAMES & set(c._param_names())]


@pytest.fixture(scope="module")
def est_file(tmp_path_factory):
    rng = np.random.default_rng(0)
    u = rng.standard_normal(300)
    y = np.zeros_like(u)
    for k in range(2, u.size):  # a second-order plant: ny = nu = 2 is the right structure
        y[k] = 1.2 * y[k - 1] - 0.5 * y[k - 2] + 0.4 * u[k - 1] + 0.2 * u[k - 2] + 0.1 * u[k - 1] ** 2
    path = tmp_path_factory.mktemp("vocab") / "est.npz"
    write_record(Record(u=u, y=y, fs=100.0), path)
    return path


def test_every_identifier_with_lags_spells_them_ny_nu():
    found = _with_lags()
    assert {"arx", "armax", "narx-poly", "narmax-poly", "narx-mlp", "narx-mlp-sim"} <= {n for n, _ in found}
    for name, cls in found:
        params = set(cls._param_names())
        assert {"ny", "nu"} <= params and not params & set(ALIASES), (name, params)
        if "nk" not in params:
            assert name not in ("arx", "armax", "narx-poly", "narmax-poly", "narx-mlp", "narx-mlp-sim")


@pytest.mark.parametrize("name", [n for n, _ in _with_lags()])
def test_set_ny_nu_works_for_every_identifier_with_lags(name, est_file, capsys):
    extra = FAST.get(name)
    argv = ["identify", name, "--est", str(est_file), "--set", "ny=2,nu=2", "--json", "-q"]
    if extra:
        argv += ["--set", extra]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    params = out.get("params") or out.get("model", {}).get("params") or {}
    assert params.get("ny") == 2 and params.get("nu") == 2, out.keys()


def test_deprecated_lag_names_still_work_and_say_so():
    cls = get_identifier("narx-mlp")
    with pytest.warns(DeprecationWarning, match="n_y -> ny"):
        m = cls(n_y=3, n_u=4)
    assert (m.ny, m.nu) == (3, 4)
    with pytest.warns(DeprecationWarning):
        m = cls.from_assignments({"n_y": "5", "nu": "6"})
    assert (m.ny, m.nu) == (5, 6)
    with pytest.warns(DeprecationWarning):
        m.set_params(n_u=7)
    assert m.nu == 7 and m.get_params()["nu"] == 7 and "n_u" not in m.get_params()
    rnn = get_identifier("rnn")
    with pytest.warns(DeprecationWarning, match="linear_order -> linear"):
        r = rnn.from_assignments({"linear_order": "3"})
    assert r.linear == 3 and r.linear_order == 3


def test_both_spellings_at_once_are_refused():
    with pytest.raises(ConfigError, match="same option"):
        get_identifier("narx-mlp")(n_y=2, ny=3)
    with pytest.raises(ConfigError, match="same option"):
        resolve_aliases({"linear_order": 1, "linear": 2}, ["linear"], "rnn")


def test_an_alias_is_not_applied_where_the_old_name_is_a_real_option():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert resolve_aliases({"n_y": 1}, ["n_y", "ny"]) == {"n_y": 1}  # both valid: left alone, no warning
        assert resolve_aliases({"n_y": 1}, ["degree"]) == {"n_y": 1}  # not an option here: the caller refuses it


def test_old_model_files_with_old_names_load(tmp_path, est_file):
    from sysid.base import load_model
    from sysid.data.io import read_record

    rec = read_record(est_file)
    model = get_identifier("narx-mlp")(ny=2, nu=2, epochs=1, hidden=[4]).fit(rec)
    from sysid.data.jsonio import json_default

    # a model file as written before the rename: the first (JSON, unchecksummed) format with the old names
    params = model.get_params()
    params["n_y"], params["n_u"] = params.pop("ny"), params.pop("nu")
    payload = {"format": "piezotwin-model/1", "identifier": model.name, "params": params, "state": model._state()}
    path = tmp_path / "m.json"
    path.write_text(json.dumps(payload, default=json_default))
    with pytest.warns(DeprecationWarning):
        back = load_model(path)
    np.testing.assert_array_equal(back.predict(rec, horizon=None), model.predict(rec, horizon=None))


def test_search_grid_and_set_accept_old_names():
    from sysid.search import SweepSpec, parse_grid

    with pytest.warns(DeprecationWarning):
        grid = parse_grid("n_y=2,3;hidden=4", "narx-mlp")
    assert grid == {"ny": ["2", "3"], "hidden": ["4"]}
    with pytest.warns(DeprecationWarning):
        spec = SweepSpec(identifier="narx-mlp", grid={"hidden": ["4"]}, fixed={"n_u": "2"})
    assert spec.fixed == {"nu": "2"}
