"""Linear bypass of the neural identifiers (NARX-MLP ``linear=True``, RNN ``linear=k``).

The bypass starts at the least-squares ARX of the same lags with an intercept, and the network's output at zero,
so an untrained model must predict exactly what :class:`sysid.linear.ARX` (closed-form least squares on the raw
data, ``intercept=True``) predicts — one step, k steps and in free run. The compiled free run, the k-step
recursion and the hand-written gradient are checked against plain numpy loops and autograd.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sysid.base import load_model  # noqa: E402
from sysid.errors import ConfigError  # noqa: E402
from sysid.linear.arx import ARX  # noqa: E402
from sysid.neural.core import (  # noqa: E402
    FlatMLP,
    count_mlp_parameters,
    free_run_mlp,
    k_step_mlp,
    least_squares_linear,
    mlp_forward_np,
)
from sysid.neural.narx_mlp import NARXMLP, NARXMLPSim  # noqa: E402
from sysid.neural.rnn import RNNStateSpace  # noqa: E402
from tests.neural_systems import bouc_wen_record, multisine_input  # noqa: E402

FS = 1000.0


@pytest.fixture(scope="module")
def plant():
    est = bouc_wen_record(multisine_input(3000, FS, 100.0, seed=1), FS, f0=100.0, noise=0.005, seed=3)
    val = bouc_wen_record(multisine_input(800, FS, 100.0, seed=2), FS, f0=100.0)
    return est, val


def _reference_net(flat, sizes, code, x, linear):
    """The flat layout written out by hand: per layer W (out × in, row-major) then b; L (n_out × n_in) last."""
    act = {0: lambda v: np.maximum(v, 0.0), 1: np.tanh, 2: lambda v: 1.0 / (1.0 + np.exp(-v))}[code]
    o, a = 0, np.asarray(x, dtype=float)
    for i in range(len(sizes) - 1):
        n_in, n_out = sizes[i], sizes[i + 1]
        W = np.array([[flat[o + j * n_in + m] for m in range(n_in)] for j in range(n_out)])
        o += n_in * n_out
        a = W @ a + flat[o : o + n_out]
        o += n_out
        if i < len(sizes) - 2:
            a = act(a)
    if linear:
        a = a + flat[o : o + sizes[0] * sizes[-1]].reshape(sizes[-1], sizes[0]) @ x
    return a


# ------------------------------------------------------------------ untrained = least-squares ARX
@pytest.mark.parametrize(
    "cls,kw",
    [
        (NARXMLP, dict(epochs=0)),
        (NARXMLPSim, dict(epochs=0, pretrain_epochs=0)),
    ],
)
def test_untrained_bypass_is_the_least_squares_arx(plant, cls, kw):
    est, val = plant
    arx = ARX(ny=3, nu=2, intercept=True).fit(est)
    m = cls(ny=3, nu=2, hidden=[8, 8], linear=True, device="cpu", **kw).fit(est)
    scale = np.std(val.y)
    for h in (1, 4, None):
        a, b = arx.predict(val, h), m.predict(val, h)
        # the weights are trained (and stored) in float32: agreement to ~1e-7 of the signal, not bit-exact
        np.testing.assert_allclose(b, a, rtol=0, atol=2e-5 * scale, err_msg=f"horizon {h}")
    # and the least-squares solve itself: L, c reproduce numpy's lstsq on the normalised regressor
    (un, yn) = (m.normaliser_.transform_u(est.u)[:, None], m.normaliser_.transform_y(est.y)[:, None])
    L, c = least_squares_linear([(un, yn)], 3, 2)
    t = np.arange(3, len(est))
    X = np.column_stack([yn[t - 1, 0], yn[t - 2, 0], yn[t - 3, 0], un[t - 1, 0], un[t - 2, 0], np.ones(t.size)])
    ref = np.linalg.lstsq(X, yn[t, 0], rcond=None)[0]
    np.testing.assert_allclose(np.r_[L[0], c], ref, rtol=1e-9, atol=1e-11)


def test_bypass_stays_fixed_in_training_and_counts_parameters(plant):
    est, _ = plant
    m0 = NARXMLP(ny=3, nu=2, hidden=[8], linear=True, epochs=0, device="cpu").fit(est)
    m = NARXMLP(ny=3, nu=2, hidden=[8], linear=True, epochs=2, lr=1e-3, device="cpu").fit(est)
    n_mlp = count_mlp_parameters(5, [8], 1)
    assert m.n_parameters_ == m.weights_.size == n_mlp + 5 == count_mlp_parameters(5, [8], 1, linear=True)
    np.testing.assert_array_equal(m.weights_[n_mlp:], m0.weights_[n_mlp:])  # L: the least-squares ARX, untouched
    assert not np.array_equal(m.weights_[:n_mlp], m0.weights_[:n_mlp])  # the network did train
    s = NARXMLPSim(ny=3, nu=2, hidden=[8], linear=True, epochs=1, pretrain_epochs=1, window=10, device="cpu").fit(est)
    np.testing.assert_array_equal(s.weights_[n_mlp:], m0.weights_[n_mlp:])
    assert m.describe()["structure"]["linear"] is True
    with pytest.raises(ConfigError, match="linear"):
        NARXMLP(linear="yes")._check_params()


# ------------------------------------------------------------------ kernels
@pytest.mark.parametrize("code", [0, 1, 2])
def test_free_run_and_k_step_kernels_with_bypass_equal_a_numpy_loop(code):
    rng = np.random.default_rng(4)
    sizes = [5, 6, 4, 1]  # ny = 2, nu = 3
    flat = rng.normal(0, 0.3, count_mlp_parameters(5, [6, 4], 1, linear=True))
    flat[-5:] = [0.5, -0.2, 0.3, 0.1, -0.1]  # a stable linear part
    un = rng.normal(size=(70, 1))
    yn = rng.normal(size=(70, 1))
    fr, div = free_run_mlp(flat, sizes, code, yn, un, 2, 3, 1e6, linear=True)
    assert div == -1
    ref = yn.copy()
    for t in range(3, 70):
        x = np.r_[ref[t - 1, 0], ref[t - 2, 0], un[t - 1, 0], un[t - 2, 0], un[t - 3, 0]]
        ref[t] = _reference_net(flat, sizes, code, x, True)
    np.testing.assert_allclose(fr, ref, rtol=1e-12, atol=1e-12)
    # without the flag the same buffer's network part alone is used: a different answer
    assert not np.allclose(free_run_mlp(flat[:-5], sizes, code, yn, un, 2, 3, 1e6)[0][3:], fr[3:])
    # batched forward and k-step (k beyond the record = a free run from the start)
    X = rng.normal(size=(7, 5))
    np.testing.assert_allclose(
        mlp_forward_np(flat, sizes, code, X, linear=True),
        np.array([_reference_net(flat, sizes, code, x, True) for x in X]),
        rtol=1e-12,
        atol=1e-12,
    )
    np.testing.assert_allclose(
        k_step_mlp(flat, sizes, code, yn, un, 2, 3, 100, 1e6, linear=True), ref, rtol=1e-12, atol=1e-12
    )
    ks = k_step_mlp(flat, sizes, code, yn, un, 2, 3, 3, 1e6, linear=True)
    for t in (3, 10, 69):
        sim = yn.copy()
        for tt in range(max(t - 2, 3), t + 1):
            x = np.r_[sim[tt - 1, 0], sim[tt - 2, 0], un[tt - 1, 0], un[tt - 2, 0], un[tt - 3, 0]]
            sim[tt] = _reference_net(flat, sizes, code, x, True)
        assert ks[t, 0] == pytest.approx(sim[t, 0], rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("activation", ["relu", "tanh", "sigmoid"])
def test_hand_written_gradient_with_bypass_equals_autograd(activation):
    g = torch.Generator().manual_seed(1)
    net = FlatMLP(6, [5, 4], 2, activation, g, torch.device("cpu"), torch.float64, linear=True)
    with torch.no_grad():
        net.flat.normal_(0.0, 0.5, generator=g)
    x = torch.randn(9, 6, dtype=torch.float64, generator=g)
    y = torch.randn(9, 2, dtype=torch.float64, generator=g)
    loss = net.mse_grad_(x, y)
    manual = net.flat.grad.clone()
    net.flat.grad.zero_()
    ref = ((net(x) - y) ** 2).mean()
    ref.backward()
    assert float(loss) == pytest.approx(float(ref.detach()), rel=1e-14)
    np.testing.assert_allclose(manual.numpy(), net.flat.grad.numpy(), rtol=1e-12, atol=1e-14)
    assert np.abs(manual.numpy()[-12:]).max() > 0  # the bypass's own gradient (delta^T x) is in there
    assert net.check_grad_storage()
    np.testing.assert_allclose(
        net(x).detach().numpy(),
        mlp_forward_np(
            net.weights_np(), net.sizes, {"relu": 0, "tanh": 1, "sigmoid": 2}[activation], x.numpy(), linear=True
        ),
        rtol=1e-12,
        atol=1e-12,
    )
    # frozen bypass: zero gradient for L, the rest unchanged
    net.freeze_linear()
    net.mse_grad_(x, y)
    np.testing.assert_array_equal(net.flat.grad.numpy()[-12:], 0.0)
    np.testing.assert_allclose(net.flat.grad.numpy()[:-12], manual.numpy()[:-12], rtol=1e-12, atol=1e-14)


# ------------------------------------------------------------------ recurrent model
def test_rnn_linear_path_untrained_is_the_arx_simulation(plant):
    est, val = plant
    k, n_enc = 3, 5
    arx = ARX(ny=k, nu=k, intercept=True).fit(est)
    m = RNNStateSpace(n_state=4, n_enc=n_enc, enc_hidden=[8], epochs=0, linear=k, device="cpu").fit(est)
    scale = np.std(val.y)
    np.testing.assert_allclose(m.predict(val, 1)[n_enc:], arx.predict(val, 1)[n_enc:], rtol=0, atol=2e-5 * scale)
    # free run: the RNN starts from the measured y(0..n_enc-1); the ARX simulation started at the same sample
    shift = n_enc - k
    np.testing.assert_allclose(
        m.predict(val, None)[n_enc:], arx.predict(val[shift:], None)[k:], rtol=0, atol=2e-5 * scale
    )
    # k-step at every sample: the ARX k-step prediction
    np.testing.assert_allclose(
        m.predict(val, 4)[n_enc + 4 :], arx.predict(val, 4)[n_enc + 4 :], rtol=0, atol=2e-5 * scale
    )


def test_rnn_linear_path_equals_a_numpy_recursion():
    from sysid.neural.rnn import _Net

    torch.manual_seed(0)
    k, n_enc, nu, ny = 3, 4, 1, 1
    net = _Net(n_enc * (nu + ny), [6], 5, nu, ny, "gru", linear=k, n_enc=n_enc).double()
    rng = np.random.default_rng(2)
    with torch.no_grad():
        net.arx.weight.copy_(torch.tensor([[0.6, -0.3, 0.1, 0.8, -0.4, 0.2]], dtype=torch.float64))
        net.arx.bias.fill_(0.05)
    x0 = rng.normal(size=(2, n_enc * (nu + ny)))
    useq = rng.normal(size=(2, 9, nu))
    got = net.linear_path(torch.from_numpy(x0), torch.from_numpy(useq)).detach().numpy()
    a, b = np.array([0.6, -0.3, 0.1]), np.array([0.8, -0.4, 0.2])
    for s in range(2):
        # time axis: index n_enc = t0; y(t0-i) = x0[i-1], u(t0-i) = x0[n_enc + i - 1]; u(t0+j-1) = useq[j]
        y = np.zeros(n_enc + 9)
        u = np.zeros(n_enc + 9)
        for i in range(1, n_enc + 1):
            y[n_enc - i] = x0[s, i - 1]
            u[n_enc - i] = x0[s, n_enc + i - 1]
        u[n_enc - 1 : n_enc + 8] = useq[s, :, 0]
        for t in range(n_enc, n_enc + 9):
            y[t] = a @ y[t - 1 : t - 4 : -1] + b @ u[t - 1 : t - 4 : -1] + 0.05
        np.testing.assert_allclose(got[s, :, 0], y[n_enc:], rtol=1e-12, atol=1e-12)


def test_rnn_linear_path_fixed_in_training_saved_and_loaded(plant, tmp_path):
    est, val = plant
    kw = dict(n_state=6, n_enc=5, enc_hidden=[8], window=20, batch_size=8, linear=3, device="cpu", seed=2)
    m0 = RNNStateSpace(epochs=0, **kw).fit(est)
    m = RNNStateSpace(epochs=2, **kw).fit(est)
    for key in ("arx.weight", "arx.bias"):
        np.testing.assert_array_equal(m.state_dict_[key], m0.state_dict_[key])
    assert not np.array_equal(m.state_dict_["readout.weight"], m0.state_dict_["readout.weight"])
    assert m.n_parameters_ == RNNStateSpace(epochs=0, **{**kw, "linear": 0}).fit(est).n_parameters_ + 7
    assert m.describe()["structure"]["linear_order"] == 3
    preds = {h: m.predict(val, h) for h in (1, 6, None)}
    for suffix in (".pt", ".json"):
        m2 = load_model(m.save(tmp_path / f"rnn{suffix}"))
        assert m2.linear == 3
        for h, p in preds.items():
            np.testing.assert_array_equal(m2.predict(val, h), p)
    with pytest.raises(ConfigError, match="linear"):
        RNNStateSpace(n_enc=4, linear=5)._check_params()


def test_narx_mlp_bypass_saved_and_loaded(plant, tmp_path):
    est, val = plant
    m = NARXMLP(ny=3, nu=2, hidden=[8], linear=True, epochs=1, device="cpu").fit(est)
    preds = {h: m.predict(val, h) for h in (1, 5, None)}
    for suffix in (".pt", ".json"):
        m2 = load_model(m.save(tmp_path / f"mlp{suffix}"))
        assert m2.linear is True and m2.n_parameters_ == m.n_parameters_
        for h, p in preds.items():
            np.testing.assert_array_equal(m2.predict(val, h), p)


def test_rnn_linear_path_filter_equals_the_loop():
    """The compiled filter that prediction takes for long float64 sequences gives the per-step recursion's values."""
    from sysid.neural.rnn import FILTER_MIN_STEPS, _Net

    torch.manual_seed(1)
    k, n_enc = 3, 4
    net = _Net(n_enc * 2, [6], 5, 1, 1, "gru", linear=k, n_enc=n_enc).double()
    with torch.no_grad():
        net.arx.weight.copy_(torch.tensor([[0.6, -0.3, 0.1, 0.8, -0.4, 0.2]], dtype=torch.float64))
        net.arx.bias.fill_(0.05)
    rng = np.random.default_rng(3)
    x0 = torch.from_numpy(rng.normal(size=(3, n_enc * 2)))
    useq = torch.from_numpy(rng.normal(size=(3, 4 * FILTER_MIN_STEPS, 1)))
    loop = net.linear_path(x0, useq).detach()  # gradients enabled: the per-step loop
    with torch.no_grad():
        fast = net.linear_path(x0, useq)
    np.testing.assert_allclose(fast.numpy(), loop.numpy(), rtol=1e-12, atol=1e-12)
