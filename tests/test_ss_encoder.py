"""ss-encoder (SUBNET) against closed forms: a linear state-space system is learned to float32 precision, its
poles and frequency response are the true ones, and the encoder's state is the true state up to the similarity
transform that the learned (A, B, C) realise."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from sysid.base import load_model  # noqa: E402
from sysid.data.record import Record  # noqa: E402
from sysid.neural.ss_encoder import SSEncoder  # noqa: E402

A = np.array([[1.6, -0.8], [1.0, 0.0]])  # poles 0.8 ± 0.4j (|p| = 0.894)
B = np.array([1.0, 0.0])
C = np.array([0.2, 0.1])


def simulate(u: np.ndarray, x0) -> tuple[np.ndarray, np.ndarray]:
    """y(k) = C x(k), x(k+1) = A x(k) + B u(k); returns (y, states x(0) … x(N-1))."""
    x = np.asarray(x0, dtype=float)
    y, xs = np.zeros(u.size), np.zeros((u.size, 2))
    for k in range(u.size):
        xs[k] = x
        y[k] = C @ x
        x = A @ x + B * u[k]
    return y, xs


@pytest.fixture(scope="module")
def linear_fit():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(3000)
    y, _ = simulate(u, [0.0, 0.0])
    model = SSEncoder(
        nx=2,
        ny=4,
        nu=4,
        f_hidden=0,
        h_hidden=0,
        e_hidden=0,
        T=30,
        batch_size=64,
        epochs=20,
        lr=1e-2,
        device="cpu",
        seed=0,
    )
    return model.fit(Record(u=u, y=y, fs=1.0))


def learned_abc(model: SSEncoder):
    w = model.weights_
    nx = model.nx
    return w["f"]["W"][:, :nx], w["f"]["W"][:, nx:], w["h"]["W"]


def test_linear_system_learned_exactly(linear_fit):
    """Free run on a new input from a NON-zero initial state (the encoder must find it): error ~1e-6 of the
    output's SD; learned poles and frequency response (de-normalised) equal the true ones."""
    rng = np.random.default_rng(1)
    ut = rng.standard_normal(600)
    yt, _ = simulate(ut, [3.0, -2.0])
    yh = linear_fit.predict(Record(u=ut, y=yt, fs=1.0), None)
    lag = linear_fit.max_lag_
    assert lag == 4
    np.testing.assert_array_equal(yh[:lag], yt[:lag])
    assert np.sqrt(np.mean((yh - yt)[lag:] ** 2)) < 1e-4 * np.std(yt)

    Ah, Bh, Ch = learned_abc(linear_fit)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(Ah)), np.sort_complex(np.linalg.eigvals(A)), atol=1e-4)
    norm = linear_fit.normaliser_
    gain = float(norm.y_scale_) / float(norm.u_scale_)
    for w in (0.05, 0.5, 1.5, 3.0):
        z = np.exp(1j * w)
        g_true = C @ np.linalg.solve(z * np.eye(2) - A, B)
        g_hat = gain * (Ch @ np.linalg.solve(z * np.eye(2) - Ah, Bh))[0, 0]
        assert abs(g_hat - g_true) < 1e-4 * abs(g_true)


def test_encoder_state_is_true_state_up_to_similarity(linear_fit):
    """x̂(k) = ψ(past 4 samples) = M x(k) + c for every k, with M the similarity transform of the learned
    realisation: Â = M A M⁻¹, B̂ / s_u = M B and s_y Ĉ M = C (s_u, s_y: the normalisation scales)."""
    rng = np.random.default_rng(2)
    ut = rng.standard_normal(300)
    yt, xs = simulate(ut, [-1.0, 2.5])
    rec = Record(u=ut, y=yt, fs=1.0)
    ks = np.arange(4, 300, 7)
    xh = np.array([linear_fit.initial_state(rec, at=int(k)) for k in ks])
    X = np.column_stack([xs[ks], np.ones(ks.size)])
    coef, *_ = np.linalg.lstsq(X, xh, rcond=None)
    assert np.max(np.abs(X @ coef - xh)) < 1e-4 * np.max(np.abs(xh))
    M = coef[:2].T  # x̂ = M x + c
    Ah, Bh, Ch = learned_abc(linear_fit)
    np.testing.assert_allclose(Ah, M @ A @ np.linalg.inv(M), atol=1e-4)
    norm = linear_fit.normaliser_
    np.testing.assert_allclose(Bh[:, 0] / float(norm.u_scale_), M @ B, rtol=1e-3, atol=1e-5)
    np.testing.assert_allclose(Ch[0] @ M * float(norm.y_scale_), C, rtol=1e-3, atol=1e-5)


def test_horizons_and_save_load(linear_fit, tmp_path):
    """k-step prediction of a linear model from exact states equals the measurement; a horizon as long as the
    record is the free run; .pt and .json files predict identically."""
    rng = np.random.default_rng(3)
    ut = rng.standard_normal(200)
    yt, _ = simulate(ut, [0.5, 0.5])
    rec = Record(u=ut, y=yt, fs=1.0)
    for k in (1, 5):
        yk = linear_fit.predict(rec, k)
        assert np.sqrt(np.mean((yk - yt)[4:] ** 2)) < 1e-4 * np.std(yt)
    np.testing.assert_allclose(linear_fit.predict(rec, 500), linear_fit.predict(rec, None), rtol=0, atol=1e-12)
    for suffix in (".pt", ".json"):
        path = linear_fit.save(tmp_path / f"m{suffix}")
        np.testing.assert_array_equal(load_model(path).predict(rec, None), linear_fit.predict(rec, None))


def test_nonlinear_default_network_beats_linear_on_a_static_nonlinearity():
    """Wiener system y = tanh(2 x1) after the linear dynamics: the default f/h networks (64 tanh) fit it better
    than the same model with linear f/h, within a few epochs (quick)."""
    rng = np.random.default_rng(4)
    u = rng.standard_normal(2000)
    x, _ = simulate(u, [0.0, 0.0])
    y = np.tanh(2.0 * x)
    ut = rng.standard_normal(400)
    xt, _ = simulate(ut, [0.0, 0.0])
    yt = np.tanh(2.0 * xt)
    common = dict(nx=2, ny=4, nu=4, T=20, batch_size=64, epochs=8, lr=1e-2, device="cpu", seed=0, e_hidden=0)
    rms = {}
    for name, hidden in (("linear", 0), ("mlp", 64)):
        m = SSEncoder(f_hidden=hidden, h_hidden=hidden, **common).fit(Record(u=u, y=y, fs=1.0))
        rms[name] = np.sqrt(np.mean((m.predict(Record(u=ut, y=yt, fs=1.0), None) - yt)[4:] ** 2))
    assert rms["mlp"] < 0.5 * rms["linear"]


def test_cosine_decay_to_lr_is_the_constant_step_and_decays_otherwise():
    """A cosine from lr down to lr_min = lr is the constant step: the same weights bit for bit; a decay to 0 trains
    the first epoch at lr exactly as the constant step does and differs from the second epoch on."""
    rng = np.random.default_rng(3)
    u = rng.standard_normal(600)
    y, _ = simulate(u, [0.0, 0.0])
    common = dict(
        nx=2,
        ny=4,
        nu=4,
        f_hidden=8,
        h_hidden=0,
        e_hidden=0,
        T=20,
        batch_size=32,
        epochs=4,
        lr=1e-2,
        device="cpu",
        seed=0,
        val_fraction=0.0,
    )
    rec = Record(u=u, y=y, fs=1.0)
    const = SSEncoder(**common).fit(rec)
    same = SSEncoder(lr_min=1e-2, **common).fit(rec)
    for part in const.weights_:
        np.testing.assert_array_equal(const.weights_[part]["W"], same.weights_[part]["W"])
    decayed = SSEncoder(lr_min=0.0, **common).fit(rec)
    assert decayed.loss_history_[0] == const.loss_history_[0]  # the first epoch runs at lr in both
    assert decayed.loss_history_ != const.loss_history_


def test_bad_options_are_refused():
    from sysid.errors import ConfigError, DataError

    with pytest.raises(ConfigError):
        SSEncoder(ny=0, nu=0).fit(Record(u=np.arange(100.0), y=np.arange(100.0) ** 2, fs=1.0))
    with pytest.raises(ConfigError):
        SSEncoder(f_hidden="x").fit(Record(u=np.arange(100.0), y=np.arange(100.0) ** 2, fs=1.0))
    m = SSEncoder.from_assignments({"f_hidden": "64-32", "h_hidden": "0", "e_hidden": "0"})
    m._check_params(check_device=False)
    assert (m.f_hidden, m.h_hidden, m.e_hidden) == ([64, 32], [], [])
    with pytest.raises(ConfigError, match="lr_min"):
        SSEncoder(lr=1e-3, lr_min=1e-2, device="cpu").fit(Record(u=np.arange(100.0), y=np.arange(100.0) ** 2, fs=1.0))
    with pytest.raises(DataError):
        SSEncoder(T=500, device="cpu").fit(Record(u=np.sin(np.arange(100.0)), y=np.cos(np.arange(100.0)), fs=1.0))


def test_default_quick_run_scores_ss_encoder_on_its_quick_datasets_only(monkeypatch):
    """The quick check's budget has room for simulation-error training on Silverbox only: the default quick run
    lists ss-encoder × cascaded tanks as skipped with the reason (an explicit --identifiers still runs it)."""
    import sysid.registry
    from benchmarks import scoring

    assert scoring.QUICK_ONLY_DATASETS["ss-encoder"]["datasets"] == ["silverbox"]
    monkeypatch.setattr(sysid.registry, "available_identifiers", lambda: ["ss-encoder"])
    run = scoring.score(None, ["cascaded-tanks"], quick=True, sysidentpy=False)
    assert run.rows == []
    reason = scoring.QUICK_ONLY_DATASETS["ss-encoder"]["why"]
    assert {"identifier": "ss-encoder", "dataset": "cascaded-tanks", "reason": reason} in run.skipped
