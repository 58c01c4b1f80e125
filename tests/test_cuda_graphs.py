"""CUDA graphs of ss-encoder's training (sysid.neural.cuda_graphs): the replayed steps are the eager steps.

On a machine with CUDA: a Wiener system (linear dynamics, then tanh) is fitted three ways from the same seed — on
the CPU, on the GPU eagerly, on the GPU with graphs — with a section count that leaves a shorter last batch (run
eagerly between replays), gradient clipping and a cosine step-size schedule (the step size a tensor that the
schedule rewrites between replays). The three training curves agree to float32 rounding, so the graph replays the
step it captured with the current weights, step size and data. Without CUDA only the CPU-side checks run.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sysid.data.record import Record  # noqa: E402
from sysid.errors import ConfigError  # noqa: E402
from sysid.neural.ss_encoder import SSEncoder  # noqa: E402

needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")


def _wiener(n: int, seed: int) -> Record:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    x = np.zeros(2)
    y = np.zeros(n)
    for k in range(n):  # poles 0.8 ± 0.4j, then a static tanh
        y[k] = np.tanh(2.0 * (0.2 * x[0] + 0.1 * x[1]))
        x = np.array([1.6 * x[0] - 0.8 * x[1] + u[k], x[0]])
    return Record(u=u, y=y, fs=1.0)


def _fit(device: str, graphs: bool) -> SSEncoder:
    # 1500 samples, 20 % held out, lag 4, T 20: 1176 sections = 18 full batches of 64 and one of 24
    opts = dict(nx=2, ny=4, nu=4, f_hidden=16, h_hidden=16, e_hidden=0, T=20, batch_size=64, epochs=4)
    model = SSEncoder(**opts, lr=2e-2, lr_min=1e-4, clip=1.0, seed=0, device=device, cuda_graphs=graphs)
    return model.fit(_wiener(1500, 1))


def test_the_cpu_ignores_cuda_graphs_and_bad_values_are_refused():
    model = _fit("cpu", True)
    assert model.cuda_graphs_ is False and model.device_used_ == "cpu"
    with pytest.raises(ConfigError, match="cuda_graphs"):
        SSEncoder(cuda_graphs="yes", device="cpu").fit(_wiener(300, 0))


@needs_cuda
def test_graph_replays_train_the_eager_model():
    cpu, eager, graphed = _fit("cpu", False), _fit("cuda", False), _fit("cuda", True)
    assert graphed.cuda_graphs_ and not eager.cuda_graphs_
    assert len(graphed.loss_history_) == len(eager.loss_history_) == 4
    np.testing.assert_allclose(graphed.loss_history_, eager.loss_history_, rtol=1e-3)
    np.testing.assert_allclose(graphed.val_history_, eager.val_history_, rtol=1e-3)
    np.testing.assert_allclose(graphed.val_history_, cpu.val_history_, rtol=1e-3)
    assert graphed.val_history_[-1] < 0.5 * graphed.val_history_[0]  # it trained
    for part in graphed.weights_:
        np.testing.assert_allclose(graphed.weights_[part]["W"], eager.weights_[part]["W"], rtol=1e-2, atol=1e-4)
