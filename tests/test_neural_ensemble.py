"""Ensembles of the NARX-MLP identifiers (``ensemble=k``).

An ensemble of k networks (member i trained as a single model of seed ``seed·k + i``) predicts the members' mean
at every step; in free run and k steps ahead the MEAN is what is fed back. The members are merged into one wide
network (block-diagonal hidden layers, output weights / k), so the reference here is written independently:
the members are trained again as single models, and plain numpy loops average their outputs step by step.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sysid.base import load_model  # noqa: E402
from sysid.errors import ConfigError, DataError  # noqa: E402
from sysid.neural.core import ACT_CODE, count_mlp_parameters, merge_ensemble, mlp_forward_np  # noqa: E402
from sysid.neural.narx_mlp import NARXMLP, NARXMLPSim  # noqa: E402
from sysid.neural.records import normalised_pairs  # noqa: E402
from tests.neural_systems import bouc_wen_record, multisine_input  # noqa: E402

FS = 1000.0


@pytest.fixture(scope="module")
def plant():
    est = bouc_wen_record(multisine_input(1500, FS, 100.0, seed=1), FS, f0=100.0, noise=0.005, seed=3)
    est2 = bouc_wen_record(multisine_input(900, FS, 100.0, seed=4), FS, f0=100.0, noise=0.005, seed=5)
    val = bouc_wen_record(multisine_input(300, FS, 100.0, seed=2), FS, f0=100.0)
    return est, est2, val


def _mean_net(members, sizes, code, linear):
    def f(x):
        return np.mean([mlp_forward_np(w, sizes, code, x, linear) for w in members], axis=0)

    return f


def _regressor(y, u, t, ny, nu, nk):
    return np.concatenate([y[t - np.arange(1, ny + 1)].reshape(-1), u[t - np.arange(nk, nk + nu)].reshape(-1)])


def _reference_predictions(model, members, val, horizon):
    """Normalised-unit reference by plain loops: the mean of the members' outputs, fed back for free run / k steps."""
    ((un, yn),) = normalised_pairs([val], model.normaliser_)
    sizes = [model.sizes_[0], *model.hidden, model.sizes_[-1]]
    net = _mean_net([m.weights_ for m in members], sizes, ACT_CODE[model.activation], model.linear)
    lag, n = model.max_lag_, len(val)
    out = yn.copy()
    if horizon is None:
        for t in range(lag, n):
            out[t] = net(_regressor(out, un, t, model.ny, model.nu, model.nk)[None, :])[0]
    else:
        for t in range(lag, n):
            s = max(lag, t - horizon + 1)  # the prediction ŷ(t | t-horizon) starts from measurements before s
            work = yn.copy()
            for tt in range(s, t + 1):
                work[tt] = net(_regressor(work, un, tt, model.ny, model.nu, model.nk)[None, :])[0]
            out[t] = work[t]
    y = model.normaliser_.inverse_y(out)
    y[:lag] = val.y.reshape(-1, 1)[:lag]
    return y[:, 0]


CASES = [
    ("mlp-relu-linear", NARXMLP, dict(epochs=2, linear=True, activation="relu"), False),
    ("mlp-tanh-plain-tail", NARXMLP, dict(epochs=2, activation="tanh", select_tail=0.2), False),
    ("mlp-sigmoid-linear-two-records", NARXMLP, dict(epochs=2, linear=True, activation="sigmoid", nk=2), True),
    (
        "sim-relu-linear-tail",
        NARXMLPSim,
        dict(epochs=1, pretrain_epochs=1, window=10, linear=True, select_tail=0.2),
        False,
    ),
]


@pytest.mark.parametrize("name,cls,kw,two", CASES, ids=[c[0] for c in CASES])
def test_merged_network_is_the_mean_of_its_members(plant, name, cls, kw, two):
    est, est2, val = plant
    data = [est, est2] if two else est
    k, seed = 3, 2
    common = dict(ny=3, nu=2, hidden=[6, 5], device="cpu", **kw)
    ens = cls(seed=seed, ensemble=k, **common).fit(data)
    members = [cls(seed=seed * k + i, **common).fit(data) for i in range(k)]
    n_in = ens.sizes_[0]
    assert ens.sizes_ == [n_in, k * 6, k * 5, 1]
    assert ens.member_seeds() == [6, 7, 8]
    # the members differ (otherwise averaging would prove nothing)
    assert not np.allclose(members[0].weights_, members[1].weights_)
    per_member = count_mlp_parameters(n_in, [6, 5], 1, False)
    assert ens.n_parameters_ == k * per_member + (n_in if kw.get("linear") else 0)
    assert ens.n_parameters_ < ens.weights_.size  # the zero blocks are not counted
    assert ens.describe()["structure"]["ensemble"] == k
    if kw.get("select_tail"):
        assert len(ens.selected_epoch_) == k and ens.selected_epoch_ == [m.selected_epoch_ for m in members]
    scale = float(np.std(val.y))
    for horizon in (1, 4, None):
        got = ens.predict(val, horizon=horizon)
        ref = _reference_predictions(ens, members, val, horizon)
        assert np.isfinite(got).all()
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * scale, err_msg=f"horizon={horizon}")
    # and the mean really differs from a single member (the test above is not vacuous)
    assert np.max(np.abs(ens.predict(val, horizon=None) - members[0].predict(val, horizon=None))) > 1e-6 * scale


@pytest.mark.parametrize("act", ["relu", "tanh", "sigmoid"])
@pytest.mark.parametrize("hidden", [[], [4], [4, 3, 5]])
@pytest.mark.parametrize("linear", [False, True])
def test_merge_ensemble_random_weights(act, hidden, linear):
    rng = np.random.default_rng(0)
    sizes = [7, *hidden, 2]
    n_w = count_mlp_parameters(7, hidden, 2, linear)
    members = [rng.normal(size=n_w) for _ in range(4)]
    if linear:  # the bypass L is shared, as in the identifiers (fixed least squares)
        for m in members[1:]:
            m[-14:] = members[0][-14:]
    flat, msizes = merge_ensemble(members, sizes, linear)
    assert msizes == [7, *[4 * h for h in hidden], 2]
    assert flat.size == count_mlp_parameters(7, msizes[1:-1], 2, linear)
    x = rng.normal(size=(50, 7))
    code = ACT_CODE[act]
    ref = np.mean([mlp_forward_np(w, sizes, code, x, linear) for w in members], axis=0)
    np.testing.assert_allclose(mlp_forward_np(flat, msizes, code, x, linear), ref, rtol=0, atol=1e-12)


def test_ensemble_one_is_the_single_network(plant):
    est, _, val = plant
    common = dict(ny=3, nu=2, hidden=[6, 5], device="cpu", epochs=2, linear=True, seed=4)
    a = NARXMLP(**common).fit(est)
    b = NARXMLP(ensemble=1, **common).fit(est)
    assert b.sizes_ == [a.sizes_[0], 6, 5, 1]
    np.testing.assert_array_equal(a.weights_, b.weights_)
    assert a.n_parameters_ == b.n_parameters_ == count_mlp_parameters(a.sizes_[0], [6, 5], 1, True)
    np.testing.assert_array_equal(a.predict(val, horizon=None), b.predict(val, horizon=None))
    # member i of an ensemble is the single network of seed seed·k + i: its first-layer block is that net's
    ens = NARXMLP(**{**common, "ensemble": 2}).fit(est)
    single = NARXMLP(**{**common, "seed": 4 * 2 + 1}).fit(est)
    n_in = ens.sizes_[0]
    W1 = ens.weights_[: n_in * 12].reshape(12, n_in)
    np.testing.assert_array_equal(W1[6:], single.weights_[: n_in * 6].reshape(6, n_in))


@pytest.mark.parametrize("suffix", [".json", ".pt"])
def test_ensemble_saved_and_loaded(plant, tmp_path, suffix):
    est, _, val = plant
    m = NARXMLPSim(
        ny=3, nu=2, hidden=[6], device="cpu", epochs=1, pretrain_epochs=1, window=10, linear=True, ensemble=3, seed=1
    ).fit(est)
    m2 = load_model(m.save(tmp_path / f"ens{suffix}"))
    assert m2.ensemble == 3 and m2.sizes_ == m.sizes_ and m2.n_parameters_ == m.n_parameters_
    np.testing.assert_array_equal(m2.weights_, m.weights_)
    for h in (1, 3, None):
        np.testing.assert_array_equal(m2.predict(val, horizon=h), m.predict(val, horizon=h))


def test_saved_sizes_must_match_ensemble(plant, tmp_path):
    est, _, _ = plant
    m = NARXMLP(ny=3, nu=2, hidden=[6], device="cpu", epochs=1, ensemble=2).fit(est)
    state = m._state()
    bad = NARXMLP(ny=3, nu=2, hidden=[6], device="cpu", ensemble=3)
    with pytest.raises(DataError, match="ensemble=3"):
        bad._load_state(state)


@pytest.mark.parametrize("cls", [NARXMLP, NARXMLPSim])
@pytest.mark.parametrize("value", [0, -1, 65, 1.5, True, "3", None])
def test_bad_ensemble_values(plant, cls, value):
    est, _, _ = plant
    with pytest.raises(ConfigError) as err:
        cls(ny=2, nu=2, hidden=[4], device="cpu", epochs=1, ensemble=value).fit(est)
    msg = str(err.value)
    assert "ensemble" in msg and "\n" not in msg
