"""wh-net (dynoNet-style block network) against its definitions: the IIR layer's gradients are the finite
differences of its forward pass, a linear system is learned to its coefficients, a Wiener–Hammerstein system with
known blocks is reproduced in free run to its noise level, and a saved model predicts identically."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

torch = pytest.importorskip("torch")

from sysid.base import load_model  # noqa: E402
from sysid.data.record import Record  # noqa: E402
from sysid.errors import ConfigError  # noqa: E402
from sysid.neural.blocknet import BlockNet  # noqa: E402
from sysid.neural.iir import LinearDynamic, MIMOFilter, filter_np, iir_filter  # noqa: E402
from sysid.neural.training import train_records  # noqa: E402
from sysid.neural.wh_net import WHNet  # noqa: E402

B_TRUE = np.array([0.3, 0.2])
A_TRUE = np.array([-1.5, 0.7])  # poles 0.75 ± 0.37j


def test_iir_gradients_match_finite_differences():
    """gradcheck (float64 finite differences of the lfilter forward) of ∂/∂u, ∂/∂b, ∂/∂a of one SISO filter and of
    a MIMO layer with an input delay."""
    gen = torch.Generator().manual_seed(0)
    u = torch.randn(2, 40, dtype=torch.float64, generator=gen, requires_grad=True)
    b = torch.randn(3, dtype=torch.float64, generator=gen, requires_grad=True)
    a = torch.tensor([-0.9, 0.3], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(iir_filter, (u, b, a))
    layer = LinearDynamic(2, 3, nb=3, na=2, nk=1, generator=gen)
    x = torch.randn(2, 25, 2, dtype=torch.float64, generator=gen, requires_grad=True)
    assert torch.autograd.gradcheck(MIMOFilter.apply, (x, layer.b, layer.a))
    assert torch.autograd.gradcheck(layer, (x,))  # with the delay, the input gradient only
    y = layer(x).detach().numpy()
    np.testing.assert_allclose(
        y, filter_np(x.detach().numpy(), layer.b.detach().numpy(), layer.a.detach().numpy(), 1), rtol=0, atol=1e-13
    )


def test_linear_system_learned_exactly():
    """y = B/A u (from rest): a single IIR layer trained on the free-run error finds b and a to 1e-4."""
    rng = np.random.default_rng(0)
    u = rng.standard_normal(1000)
    y = lfilter(B_TRUE, np.r_[1.0, A_TRUE], u)
    layer = LinearDynamic(1, 1, nb=2, na=2, generator=torch.Generator().manual_seed(0))
    res = train_records(layer, [(u[:, None], y[:, None])], warmup=0, epochs=300, lr=0.1, lr_min=1e-4)
    assert res.stopped == "epochs"
    np.testing.assert_allclose(layer.b.detach().numpy().ravel(), B_TRUE, atol=1e-4)
    np.testing.assert_allclose(layer.a.detach().numpy().ravel(), A_TRUE, atol=1e-4)


def test_linear_system_learned_exactly_from_sections():
    """The same system from mini-batches of 8 sections of 200 samples, each simulated from rest with its first 40
    samples (the transient of the zero state: the poles decay as 0.84^t, 0.1 % left at t = 40) out of the loss:
    the coefficients to 1e-3 (measured 4e-5), and the seed fixes the draw of sections (same seed, same weights)."""
    rng = np.random.default_rng(0)
    u = rng.standard_normal(2000)
    y = lfilter(B_TRUE, np.r_[1.0, A_TRUE], u)

    def fit(seed):
        layer = LinearDynamic(1, 1, nb=2, na=2, generator=torch.Generator().manual_seed(0))
        res = train_records(
            layer,
            [(u[:, None], y[:, None])],
            warmup=40,
            epochs=150,
            lr=0.05,
            lr_min=1e-4,
            val_fraction=0.1,
            window=200,
            batch=8,
            seed=seed,
        )
        return layer, res

    layer, res = fit(0)
    assert res.epochs_run == 150 and res.restarts == 0
    np.testing.assert_allclose(layer.b.detach().numpy().ravel(), B_TRUE, atol=1e-3)
    np.testing.assert_allclose(layer.a.detach().numpy().ravel(), A_TRUE, atol=1e-3)
    again, _ = fit(0)
    np.testing.assert_array_equal(again.a.detach().numpy(), layer.a.detach().numpy())
    other, _ = fit(1)
    assert not np.array_equal(other.a.detach().numpy(), layer.a.detach().numpy())


def _wh_system(u: np.ndarray) -> np.ndarray:
    z = lfilter([0.0, 0.4, 0.2], [1.0, -1.2, 0.5], u)
    w = np.tanh(1.5 * z) + 0.1 * z
    return lfilter([0.5, 0.3], [1.0, -0.6], w)


def _wh_fit(epochs: int) -> tuple[WHNet, float]:
    rng = np.random.default_rng(1)
    u = rng.standard_normal(2000)
    y = _wh_system(u)
    noise = 0.01 * np.std(y)
    model = WHNet(
        channels=3,
        hidden=12,
        nb=3,
        na=2,
        epochs=epochs,
        lr=3e-2,
        lr_min=1e-4,
        val_fraction=0.2,
        warmup=10,
        seed=0,
        device="cpu",
    )
    model.fit(Record(u=u, y=y + noise * rng.standard_normal(u.size), fs=1.0))
    return model, noise


def _free_run_rmse(model: WHNet) -> float:
    ut = np.random.default_rng(2).standard_normal(1000)
    yt = _wh_system(ut)
    yh = model.predict(Record(u=ut, y=yt, fs=1.0), None)
    np.testing.assert_array_equal(yh[:10], yt[:10])
    return float(np.sqrt(np.mean((yh - yt)[10:] ** 2)))


@pytest.fixture(scope="module")
def wh_fit():
    return _wh_fit(400)  # ≈ 2.5 s CPU


def test_wiener_hammerstein_system_learned_in_a_few_seconds(wh_fit):
    """Known blocks (2nd-order G1, saturating F, 1st-order G2), 1 % output noise, 400 epochs: the free run of a new
    input is within 6 noise levels of the noise-free output (the slow test trains to the noise level)."""
    model, noise = wh_fit
    assert _free_run_rmse(model) < 6 * noise


@pytest.mark.slow  # ≈ 15 s CPU
def test_wiener_hammerstein_system_reproduced_to_the_noise_level():
    """The same system trained 2000 epochs: free-run RMSE within 2 noise levels of the noise-free output
    (measured 1.56×)."""
    model, noise = _wh_fit(2000)
    assert _free_run_rmse(model) < 2 * noise


def test_every_horizon_is_the_free_run_and_save_load_round_trips(wh_fit, tmp_path):
    """Output-error model: one-step and k-step predictions equal the free run; .pt and .json files predict
    bit-identically; max_lag_ is the warm-up."""
    model, _ = wh_fit
    rng = np.random.default_rng(3)
    ut = rng.standard_normal(300)
    rec = Record(u=ut, y=_wh_system(ut), fs=1.0)
    free = model.predict(rec, None)
    assert model.max_lag_ == 10
    np.testing.assert_array_equal(model.predict(rec, 1), free)
    np.testing.assert_array_equal(model.predict(rec, 7), free)
    for suffix in (".pt", ".json"):
        loaded = load_model(model.save(tmp_path / f"m{suffix}"))
        np.testing.assert_array_equal(loaded.predict(rec, None), free)
        assert loaded.n_parameters_ == model.n_parameters_


def test_linear_path_and_blocks_have_the_stated_shapes():
    """G1 → F → G2 (+ G0) maps (B, T, n_in) to (B, T, n_out); the linear path adds one layer of parameters."""
    gen = torch.Generator().manual_seed(0)
    plain = BlockNet(2, 1, 3, 3, [5], 4, 3, 2, 2, generator=gen)
    both = BlockNet(2, 1, 3, 3, [5], 4, 3, 2, 2, linear=True, generator=gen)
    u = torch.randn(1, 50, 2, dtype=torch.float64)
    assert plain(u).shape == (1, 50, 1) and both(u).shape == (1, 50, 1)
    extra = sum(p.numel() for p in both.parameters()) - sum(p.numel() for p in plain.parameters())
    assert extra == 2 * (4 + 3)


def test_bad_options_are_refused():
    rec = Record(u=np.sin(np.arange(200.0)), y=np.cos(np.arange(200.0)), fs=1.0)
    for bad in (
        {"channels": 0},
        {"hidden": "x"},
        {"na": -1},
        {"lr": 0},
        {"lr": 1e-3, "lr_min": 1e-2},
        {"val_fraction": 0.9},
        {"activation": "cube"},
        {"window": 50},
        {"window": 100, "batch": 0},
    ):
        with pytest.raises(ConfigError):
            WHNet(epochs=1, device="cpu", **bad).fit(rec)
    m = WHNet.from_assignments({"hidden": "16-8", "linear": "true"})
    m._check_params(check_device=False)
    assert m.hidden == [16, 8] and m.linear is True
