"""Neural identifiers: structure against the dissertation, training, prediction modes, persistence, determinism."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sysid.base import load_model  # noqa: E402
from sysid.data.record import Record  # noqa: E402
from sysid.errors import ConfigError, DataError, DivergenceWarning  # noqa: E402
from sysid.evaluation.metrics import r2  # noqa: E402
from sysid.neural.core import count_mlp_parameters, free_run_mlp, k_step_mlp, mlp_forward_np  # noqa: E402
from sysid.neural.narx_mlp import NARXMLP, NARXMLPSim  # noqa: E402
from sysid.neural.rnn import RNNStateSpace  # noqa: E402
from tests.neural_systems import bouc_wen_record, multisine_input  # noqa: E402

FS = 1000.0


@pytest.fixture(scope="module")
def plant():
    """Bouc–Wen hysteretic oscillator: multisine estimation, another multisine realisation for validation."""
    est = bouc_wen_record(multisine_input(6000, FS, 100.0, seed=1), FS, f0=100.0, noise=0.005, seed=3)
    val = bouc_wen_record(multisine_input(2000, FS, 100.0, seed=2), FS, f0=100.0)
    return est, val


# ------------------------------------------------------------------ structure (published numbers)
@pytest.mark.parametrize(
    "layers,width,expected",
    [
        (3, 25, 1851),
        (3, 50, 6201),
        (3, 100, 22401),
        (4, 25, 2501),
        (4, 50, 8751),
        (4, 100, 32501),
        (5, 25, 3151),
        (5, 50, 11301),
        (5, 100, 42601),
    ],
)
def test_parameter_count_matches_table_4_2(layers, width, expected):
    # Table 4.2: ny = nu = 10 (20 regressors, eq. 2-14), one output
    assert count_mlp_parameters(20, [width] * layers, 1) == expected


def test_fitted_parameter_count_and_regressor(plant):
    est, _ = plant
    m = NARXMLP(ny=10, nu=10, hidden=[25] * 4, epochs=1).fit(est)
    assert m.n_parameters_ == 2501 == m.weights_.size
    assert m.max_lag_ == 10 and m.sizes_ == [20, 25, 25, 25, 25, 1]


def test_config_from_set_strings():
    m = NARXMLP.from_assignments({"hidden": "75-75", "activation": "sigmoid", "ny": "512", "nu": "512", "epochs": "75"})
    assert m.hidden == [75, 75] and m.activation == "sigmoid" and m.ny == 512 and m.epochs == 75
    with pytest.raises(ConfigError):
        NARXMLP(activation="softplus").fit(Record(u=np.zeros(50), y=np.zeros(50), fs=1.0))
    with pytest.raises(ConfigError):
        NARXMLP(ny=2000)._check_params()
    with pytest.raises(ConfigError):
        NARXMLP(device="tpu")._check_params()


# ------------------------------------------------------------------ prediction kernels
def test_kernels_agree_with_direct_recursion():
    rng = np.random.default_rng(0)
    sizes = [5, 7, 6, 1]  # ny = 3, nu = 2
    flat = rng.normal(0, 0.4, count_mlp_parameters(5, [7, 6], 1))
    un = rng.normal(size=(60, 1))
    yn = rng.normal(size=(60, 1))
    for code in (0, 1, 2):
        fr, div = free_run_mlp(flat, sizes, code, yn, un, 3, 2, 1e6)
        assert div == -1
        ref = yn.copy()
        for t in range(3, 60):
            x = np.r_[ref[t - 1, 0], ref[t - 2, 0], ref[t - 3, 0], un[t - 1, 0], un[t - 2, 0]][None]
            ref[t] = mlp_forward_np(flat, sizes, code, x)[0]
        np.testing.assert_allclose(fr, ref, rtol=1e-12, atol=1e-12)
        # k-step at every sample: compare with a direct restart of the recursion for each target
        k = 4
        ks = k_step_mlp(flat, sizes, code, yn, un, 3, 2, k, 1e6)
        for t in range(3, 60):
            start = max(t - k + 1, 3)
            sim = yn.copy()
            for tt in range(start, t + 1):
                x = np.r_[sim[tt - 1, 0], sim[tt - 2, 0], sim[tt - 3, 0], un[tt - 1, 0], un[tt - 2, 0]][None]
                sim[tt] = mlp_forward_np(flat, sizes, code, x)[0]
            assert ks[t, 0] == pytest.approx(sim[t, 0], rel=1e-12, abs=1e-12)


def test_divergence_gives_nan_and_warning():
    sizes = [1, 1]
    flat = np.array([3.0, 0.0])  # y(t) = 3 y(t-1): unstable
    m = NARXMLP(ny=1, nu=0, hidden=[], epochs=0)
    m._check_params = lambda: None  # allow the linear (no hidden layer) test network
    rec = Record(u=np.sin(np.arange(200.0)), y=np.r_[1.0, np.zeros(199)], fs=1.0)  # nu = 0: u unused
    m.fit(rec)
    m.weights_, m.sizes_ = flat, sizes
    with pytest.warns(DivergenceWarning):
        yh = m.predict(rec, None)
    assert (
        m.diverged_at_ is not None and np.isnan(yh[m.diverged_at_ :]).all() and np.isfinite(yh[: m.diverged_at_]).all()
    )


# ------------------------------------------------------------------ training and persistence
@pytest.mark.parametrize(
    "cls,kw",
    [
        (NARXMLP, dict(ny=4, nu=4, hidden=[16, 16], activation="tanh", lr=1e-3, epochs=40)),
        (NARXMLPSim, dict(ny=4, nu=4, hidden=[16, 16], activation="tanh", epochs=3, pretrain_epochs=30, window=20)),
        (RNNStateSpace, dict(n_state=16, n_enc=8, enc_hidden=[32], window=40, batch_size=16, epochs=40, lr=5e-3)),
    ],
)
def test_learns_saves_loads_identically(plant, tmp_path, cls, kw):
    est, val = plant
    m = cls(seed=1, device="cpu", **kw).fit(est)
    preds = {h: m.predict(val, h) for h in (1, 5, None)}
    # 5-step-ahead must beat persistence ŷ(t) = y(t-5) clearly (a model that learnt nothing does not)
    persist = np.r_[val.y[:5], val.y[:-5]]
    r2_persist = r2(val.y, persist, m.max_lag_)
    r2_5 = r2(val.y, preds[5], m.max_lag_)
    assert r2_5 > max(0.8, r2_persist + 0.2), (r2_5, r2_persist)
    np.testing.assert_array_equal(preds[1][: m.max_lag_], val.y[: m.max_lag_])  # copied initial conditions
    for suffix in (".pt", ".json"):
        path = m.save(tmp_path / f"model{suffix}")
        m2 = load_model(path)
        assert type(m2) is cls and m2.get_params() == m.get_params() and m2.n_parameters_ == m.n_parameters_
        for h, p in preds.items():
            np.testing.assert_array_equal(m2.predict(val, h), p)


def test_deterministic_on_cpu_for_a_seed(plant):
    est, val = plant
    kw = dict(ny=3, nu=3, hidden=[8, 8], epochs=2, lr=1e-3, device="cpu")
    a = NARXMLP(seed=7, **kw).fit(est)
    b = NARXMLP(seed=7, **kw).fit(est)
    c = NARXMLP(seed=8, **kw).fit(est)
    np.testing.assert_array_equal(a.weights_, b.weights_)
    assert a.loss_history_ == b.loss_history_
    assert not np.array_equal(a.weights_, c.weights_)
    s1 = NARXMLPSim(
        seed=2, epochs=1, pretrain_epochs=1, window=10, **{k: v for k, v in kw.items() if k != "epochs"}
    ).fit(est)
    s2 = NARXMLPSim(
        seed=2, epochs=1, pretrain_epochs=1, window=10, **{k: v for k, v in kw.items() if k != "epochs"}
    ).fit(est)
    np.testing.assert_array_equal(s1.weights_, s2.weights_)
    r1 = RNNStateSpace(n_state=4, n_enc=4, enc_hidden=[8], window=20, epochs=1, seed=3, device="cpu").fit(est)
    r2_ = RNNStateSpace(n_state=4, n_enc=4, enc_hidden=[8], window=20, epochs=1, seed=3, device="cpu").fit(est)
    for k in r1.state_dict_:
        np.testing.assert_array_equal(r1.state_dict_[k], r2_.state_dict_[k])


def test_several_records_and_bad_input(plant):
    est, val = plant
    a, b = est.split(fraction=0.5)
    m = NARXMLP(ny=3, nu=3, hidden=[8], epochs=1, device="cpu").fit([a, b])
    assert m.predict(val, None).shape == val.y.shape
    with pytest.raises(DataError):
        m.predict(val[:3], None)
    with pytest.raises(ConfigError):
        m.predict(val, 0)
    with pytest.raises(ConfigError):
        NARXMLP().predict(val)
    with pytest.raises(DataError):
        m.fit(Record(u=np.zeros(10), y=None, fs=1.0))


def test_rnn_k_step_matches_free_run_from_each_start(plant):
    est, val = plant
    m = RNNStateSpace(n_state=6, n_enc=5, enc_hidden=[8], window=20, epochs=1, device="cpu").fit(est)
    short = val[:200]
    k = 7
    ks = m.predict(short, k)
    for t in (m.max_lag_ + 10, 120, 199):
        start = t - k + 1
        sub = short[start - m.max_lag_ : t + 1]  # free run from the start encodes exactly at `start`
        fr = m.predict(sub, None)
        assert ks[t] == pytest.approx(fr[-1], rel=1e-10, abs=1e-12)


@pytest.mark.parametrize("activation", ["relu", "tanh", "sigmoid"])
def test_hand_written_backprop_equals_autograd(activation):
    from sysid.neural.core import FlatMLP

    g = torch.Generator().manual_seed(0)
    net = FlatMLP(6, [5, 4], 2, activation, g, torch.device("cpu"), torch.float64)
    x = torch.randn(9, 6, dtype=torch.float64, generator=g)
    y = torch.randn(9, 2, dtype=torch.float64, generator=g)
    loss = net.mse_grad_(x, y)
    manual = net.flat.grad.clone()
    net.flat.grad.zero_()
    ref = ((net(x) - y) ** 2).mean()
    ref.backward()
    assert float(loss) == pytest.approx(float(ref.detach()), rel=1e-14)
    np.testing.assert_allclose(manual.numpy(), net.flat.grad.numpy(), rtol=1e-12, atol=1e-14)
    assert net.check_grad_storage()


@pytest.mark.parametrize(
    "name,opts",
    [
        ("narx-mlp", "ny=3,nu=3,hidden=8-8,epochs=2,device=cpu"),
        ("narx-mlp-sim", "ny=3,nu=3,hidden=8,epochs=1,pretrain_epochs=1,window=10,device=cpu"),
        ("rnn", "n_state=4,n_enc=4,enc_hidden=8,window=20,epochs=1,device=cpu"),
    ],
)
def test_identify_cli_same_json_as_polynomial_models(tmp_path, plant, capsys, name, opts):
    import json

    from benchmarks.cli import main
    from sysid.data.io import write_record

    est, val = plant
    write_record(est, tmp_path / "est.npz")
    write_record(val, tmp_path / "val.npz")
    model_file = tmp_path / "m.pt"
    code = main(
        [
            "identify",
            name,
            "--est",
            str(tmp_path / "est.npz"),
            "--val",
            str(tmp_path / "val.npz"),
            "--set",
            opts,
            "--json",
            "-o",
            str(model_file),
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("identifier", "params", "n_parameters", "fit_seconds", "terms", "estimation", "validation"):
        assert key in out
    assert out["identifier"] == name and out["terms"] == []
    for part in ("estimation", "validation"):
        assert set(out[part]) >= {"one_step", "free_run"} and set(out[part]["one_step"]) >= {"r2", "nrmse"}
    m = load_model(model_file)
    assert m.n_parameters_ == out["n_parameters"]
    assert main(["identify", name, "--est", str(tmp_path / "est.npz"), "--set", "nosuch=1"]) == 2


def test_model_trained_for_cuda_loads_and_predicts_on_cpu(plant, tmp_path):
    est, val = plant
    m = NARXMLP(ny=2, nu=2, hidden=[4], epochs=1, device="cpu").fit(est)
    ref = m.predict(val, None)
    m.device = "cuda"  # as saved by a GPU run; prediction never needs the training device
    for suffix in (".pt", ".json"):
        m2 = load_model(m.save(tmp_path / f"gpu{suffix}"))
        assert m2.device == "cuda"
        np.testing.assert_array_equal(m2.predict(val, None), ref)


def test_input_delay_nk_kernels_and_fit(plant):
    rng = np.random.default_rng(1)
    sizes = [5, 6, 1]  # ny = 2, nu = 3, nk = 4: u(t-4), u(t-5), u(t-6)
    flat = rng.normal(0, 0.4, count_mlp_parameters(5, [6], 1))
    un = rng.normal(size=(50, 1))
    yn = rng.normal(size=(50, 1))
    fr, _ = free_run_mlp(flat, sizes, 1, yn, un, 2, 3, 1e6, nk=4)
    ref = yn.copy()
    for t in range(6, 50):
        x = np.r_[ref[t - 1, 0], ref[t - 2, 0], un[t - 4, 0], un[t - 5, 0], un[t - 6, 0]][None]
        ref[t] = mlp_forward_np(flat, sizes, 1, x)[0]
    np.testing.assert_allclose(fr, ref, rtol=1e-12, atol=1e-12)
    ks = k_step_mlp(flat, sizes, 1, yn, un, 2, 3, 60, 1e6, nk=4)  # k beyond the record: a free run from the start
    np.testing.assert_allclose(ks, ref, rtol=1e-12, atol=1e-12)
    est, val = plant
    m = NARXMLP(ny=2, nu=3, nk=4, hidden=[6], epochs=1, device="cpu").fit(est)
    assert m.max_lag_ == 6 and m.n_parameters_ == count_mlp_parameters(5, [6], 1)
    assert m.predict(val, None).shape == val.y.shape and np.isfinite(m.predict(val, 3)).all()


def test_sim_warm_start_is_the_one_step_model_and_tail_selection(plant):
    """pretrain = NARXMLP's epochs/lr/batch and seed: with 0 simulation epochs the weights equal the one-step
    model's exactly. select_tail: the kept weights are the best free-run R² on the held-out estimation tail."""
    est, _ = plant
    est = est[:2000]
    kw = dict(ny=4, nu=4, hidden=[8], activation="tanh", seed=3, device="cpu")
    osa = NARXMLP(**kw, epochs=3, lr=1e-3, batch_size=64).fit(est)
    warm = NARXMLPSim(**kw, epochs=0, pretrain_epochs=3, pretrain_lr=1e-3, pretrain_batch_size=64, batch_size=4).fit(
        est
    )
    np.testing.assert_array_equal(warm.weights_, osa.weights_)
    sim = NARXMLPSim(**kw, epochs=4, lr=3e-3, window=20, pretrain_epochs=3, pretrain_lr=1e-3, select_tail=0.25).fit(est)
    assert 0 <= sim.selected_epoch_ <= 4
    tail = est[1500 - sim.max_lag_ :]  # the held-out 500 samples with their initial conditions
    assert r2(tail.y, sim.predict(tail, None), sim.max_lag_) == pytest.approx(sim.selection_r2_, abs=1e-9)
    with pytest.raises(ConfigError, match="select_tail"):
        NARXMLPSim(**kw, select_tail=0.7).fit(est)
    with pytest.raises(ConfigError, match="pretrain_batch_size"):
        NARXMLPSim(**kw, pretrain_batch_size=0).fit(est)


@pytest.mark.parametrize("cls", [NARXMLP, RNNStateSpace])
def test_unidentifiable_data_refused_like_the_polynomial_models(cls):
    """The identifiers share one data check: a constant input or output, or too few samples, is refused."""
    from sysid.errors import DataError

    t = np.arange(300.0)
    with pytest.raises(DataError, match="input u is constant"):
        cls(epochs=1).fit(Record(u=np.ones(300), y=np.sin(t), fs=1.0, source="flat.npz"))
    with pytest.raises(DataError, match="output y is constant"):
        cls(epochs=1).fit(Record(u=np.sin(t), y=np.zeros(300), fs=1.0, source="flat.npz"))
    with pytest.raises(DataError, match="too few"):
        cls(epochs=1).fit(Record(u=np.sin(t[:5]), y=np.cos(t[:5]), fs=1.0, source="short.npz"))
