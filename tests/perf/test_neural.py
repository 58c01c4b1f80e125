"""Speed of the neural identifiers: one epoch and the full 100-epoch training of the dissertation's
4 × 25 ReLU NARX-MLP (lags 10) on 80 000 samples — the goal is ≤ 60 s for the 100 epochs on 2 CPU cores —
and the free-run simulation (compiled recursion against a PyTorch eager loop as reference).

Run: ``make bench`` or
``python -m pytest tests/perf/test_neural.py --benchmark-enable -p no:cacheprovider -o addopts=""``.
The device is chosen as in the library (CUDA when present, else CPU); ``extra_info["device"]`` records it.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sysid.data.record import Record  # noqa: E402
from sysid.neural.core import free_run_mlp  # noqa: E402
from sysid.neural.device import select_device  # noqa: E402
from sysid.neural.narx_mlp import NARXMLP, NARXMLPSim  # noqa: E402
from sysid.neural.rnn import RNNStateSpace  # noqa: E402

N = 80_000  # thesis-multisine: 8 s at 10 kHz


@pytest.fixture(scope="module")
def rec80k():
    """A nonlinear ARX-like system driven by noise (the content does not change the cost)."""
    rng = np.random.default_rng(0)
    u = rng.standard_normal(N + 10)
    y = np.zeros_like(u)
    for t in range(2, u.size):
        y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + 0.4 * np.tanh(u[t - 1]) + 0.1 * u[t - 2] ** 2
    return Record(u=u, y=y, fs=10_000.0)


@pytest.fixture(scope="module")
def fitted(rec80k):
    return NARXMLP(epochs=1, seed=0).fit(rec80k)


def test_narx_mlp_one_epoch_80k(benchmark, rec80k):
    """One epoch: 625 mini-batches of 128 pairs (plus normalising and building Φ once)."""
    benchmark.extra_info.update({"items": N, "device": str(select_device("auto"))})
    m = benchmark.pedantic(lambda: NARXMLP(epochs=1, seed=0).fit(rec80k), rounds=3, iterations=1)
    assert m.n_parameters_ == 2501 and len(m.loss_history_) == 1


def test_narx_mlp_100_epochs_80k(benchmark, rec80k):
    """The full training of Table 4.1 (100 epochs, 62 500 RMSprop steps); goal ≤ 60 s."""
    benchmark.extra_info.update({"items": N * 100, "target_s": 60.0, "device": str(select_device("auto"))})
    m = benchmark.pedantic(lambda: NARXMLP(epochs=100, seed=0).fit(rec80k), rounds=1, iterations=1)
    assert len(m.loss_history_) == 100 and m.loss_history_[-1] < m.loss_history_[0]
    assert benchmark.stats.stats.max < 60.0


def test_narx_mlp_sim_one_epoch_80k(benchmark, rec80k):
    """Simulation-error training: one epoch of 1600 windows of 50 steps, 32 windows per batch."""
    benchmark.extra_info.update({"items": N, "device": str(select_device("auto"))})
    benchmark.pedantic(lambda: NARXMLPSim(epochs=1, pretrain_epochs=0, seed=0).fit(rec80k), rounds=1, iterations=1)


def test_free_run_compiled_80k(benchmark, fitted, rec80k):
    """Free run of the 4 × 25 net over 80 000 samples: numba-compiled recursion in float64."""
    benchmark.extra_info.update({"items": N, "reference": "test_free_run_torch_eager_reference"})
    fitted.predict(rec80k[:100], None)  # compile outside the timing (cached on disk afterwards)
    y = benchmark.pedantic(lambda: fitted.predict(rec80k, None), rounds=3, iterations=1)
    assert np.isfinite(y).all()


def test_free_run_torch_eager_reference(benchmark, fitted, rec80k):
    """Reference: the same recursion as a PyTorch loop (one small forward per sample), 8 000 of the 80 000
    samples (×10 for the full length)."""
    sizes = fitted.sizes_
    w = torch.as_tensor(fitted.weights_)
    layers, o = [], 0
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers.append((w[o : o + a * b].view(b, a), w[o + a * b : o + a * b + b]))
        o += a * b + b
    un = torch.as_tensor(fitted.normaliser_.transform_u(rec80k.u[:8000]))
    yn = torch.as_tensor(fitted.normaliser_.transform_y(rec80k.y[:8000]))

    def loop():
        y = yn.clone()
        with torch.no_grad():
            for t in range(10, y.shape[0]):
                x = torch.cat([y[t - 10 : t].flip(0), un[t - 10 : t].flip(0)])
                for i, (W, b) in enumerate(layers):
                    x = W @ x + b
                    if i < len(layers) - 1:
                        x = torch.relu(x)
                y[t] = x[0]
        return y

    benchmark.extra_info.update({"items": 8000})
    y = benchmark.pedantic(loop, rounds=1, iterations=1)
    ours, _ = free_run_mlp(fitted.weights_, sizes, 0, yn.numpy()[:, None], un.numpy()[:, None], 10, 10, 1e3)
    np.testing.assert_allclose(y.numpy(), ours[:, 0], rtol=1e-9, atol=1e-9)


def test_rnn_free_run_80k(benchmark, rec80k):
    m = RNNStateSpace(epochs=1, seed=0).fit(rec80k[:5000])
    benchmark.extra_info.update({"items": N})
    y = benchmark.pedantic(lambda: m.predict(rec80k, None), rounds=3, iterations=1)
    assert np.isfinite(y).all()


@pytest.fixture(scope="module")
def rnn_linear():
    """The rnn's ARX path (4 lags, float64) and an 80 000-step free run's inputs."""
    from sysid.neural.rnn import _Net

    torch.manual_seed(0)
    net = _Net(8 * 2, [8], 4, 1, 1, "gru", linear=4, n_enc=8).double()
    with torch.no_grad():
        net.arx.weight.copy_(torch.tensor([[1.2, -0.5, 0.1, -0.05, 0.4, 0.1, 0.0, 0.0]], dtype=torch.float64))
    rng = np.random.default_rng(0)
    return net, torch.from_numpy(rng.normal(size=(1, 16))), torch.from_numpy(rng.normal(size=(1, N, 1)))


def test_rnn_linear_path_loop_reference(benchmark, rnn_linear):
    """Reference: the per-step recursion (what training runs, with gradients)."""
    net, x0, useq = rnn_linear
    benchmark.extra_info.update({"items": N})
    with torch.enable_grad():
        benchmark.pedantic(lambda: net.linear_path(x0, useq).detach(), rounds=1, iterations=1)


def test_rnn_linear_path_filter(benchmark, rnn_linear):
    """Prediction's filter path (scipy.signal.lfilter): the same values as the loop."""
    net, x0, useq = rnn_linear
    benchmark.extra_info.update({"items": N, "reference": "test_rnn_linear_path_loop_reference"})
    with torch.no_grad():
        fast = benchmark.pedantic(lambda: net.linear_path(x0, useq), rounds=5, iterations=1, warmup_rounds=1)
    loop = net.linear_path(x0, useq).detach()
    np.testing.assert_allclose(fast.numpy(), loop.numpy(), rtol=1e-9, atol=1e-9)
