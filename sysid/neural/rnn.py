"""Recurrent state-space model (registry id ``rnn``): the recurrent network the dissertation names as the way on.

Model (discrete time, normalised units)::

    h(t0)   = E([y(t0-1) … y(t0-n_enc), u(t0-1) … u(t0-n_enc)])      encoder: MLP, tanh output
    h(t+1)  = GRU(u(t), h(t))            (or an LSTM cell; its cell state also comes from the encoder)
    ŷ(t+1)  = C h(t+1) + d  [+ ŷ_lin(t+1)]

With ``linear`` = k > 0 a linear path is added: ŷ_lin is the free-run simulation of an ARX model of
orders (k, k) with intercept, ŷ_lin(t) = Σ_i A_i ŷ_lin(t-i) + Σ_i B_i u(t-i) + c, started from the measured
y(t0-1) … y(t0-k) of the encoder window. It is the least-squares ARX of the estimation data, kept fixed, and
the readout (C, d) starts at zero, so training starts from the ARX model's simulation and the recurrent network
learns the nonlinear correction (a linear model refined by a network: BLA-initialised networks, Schoukens & Ljung
2019; the linear skip of SUBNET, Beintema et al.).

The encoder estimates the initial state from ``n_enc`` past measured samples (the same regressor as a NARX
with ny = nu = n_enc, eq. 2-14); afterwards the model runs on the input alone, so every prediction is a
simulation. Training (:func:`sysid.neural.training.train_simulation`, the loop ``ss-encoder`` uses too) minimises
the free-run (simulation) MSE over windows of ``window`` samples started at random positions (multiple shooting,
ceil(rows / window) windows drawn with replacement per epoch, many as one batch), with Adam and gradient-norm
clipping. The network is called as every section-trained model is, ``net(ypast, upast, useq)``.

``predict(record, None)`` encodes the state from the first ``n_enc`` samples and simulates the rest;
``predict(record, k)`` encodes at every ``t − k`` and simulates k steps (all windows as one batch).
Prediction runs on the CPU in float64 from the saved weights, so it is identical after save/load.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from sysid.base import as_record_list
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError, DivergenceWarning
from sysid.neural.core import least_squares_linear
from sysid.neural.device import configure_threads, train_dtype
from sysid.neural.persist import saved_array
from sysid.neural.records import MAX_LAG, check_channels, check_predict_input, normalised_pairs
from sysid.neural.sequence import SequenceIdentifier
from sysid.neural.training import train_simulation

__all__ = ["RNNStateSpace"]

CELLS = ("gru", "lstm")


#: float64 sequences at least this long take the filter path of _Net.linear_path when no gradient is needed
#: (prediction; training and its float32 hold-out checks keep the loop, so trained models do not change)
FILTER_MIN_STEPS = 64


class _Net(torch.nn.Module):
    def __init__(
        self,
        n_enc_in: int,
        enc_hidden: Sequence[int],
        n_state: int,
        nu: int,
        ny: int,
        cell: str,
        linear: int = 0,
        n_enc: int = 0,
    ):
        super().__init__()
        self.cell = cell
        self.n_state = n_state
        self.nu, self.ny, self.k, self.n_enc = nu, ny, int(linear), int(n_enc)

        n_init = n_state * (2 if cell == "lstm" else 1)
        layers: list[torch.nn.Module] = []
        a = n_enc_in
        for w in enc_hidden:
            layers += [torch.nn.Linear(a, w), torch.nn.Tanh()]
            a = w
        layers += [torch.nn.Linear(a, n_init), torch.nn.Tanh()]
        self.encoder = torch.nn.Sequential(*layers)
        rnn_cls = torch.nn.GRU if cell == "gru" else torch.nn.LSTM
        self.rnn = rnn_cls(nu, n_state, batch_first=True)
        self.readout = torch.nn.Linear(n_state, ny)
        # ARX path on [y(t-1) … y(t-k), u(t-1) … u(t-k)] (lag-major, as the NARX regressor of eq. 2-14)
        self.arx = torch.nn.Linear(self.k * (ny + nu), ny) if self.k else None

    def forward(self, ypast: torch.Tensor, upast: torch.Tensor, useq: torch.Tensor) -> torch.Tensor:
        """``ypast`` (B, n_enc, ny), ``upast`` (B, n_enc, nu) the samples before t0 (oldest first), ``useq``
        (B, T, nu) the inputs u(t0) … u(t0+T-1) → ŷ(t0) … ŷ(t0+T-1) (B, T, ny), as
        :class:`sysid.neural.subnet.SubnetModel` is called. ŷ(t) reads u up to t-1: the recurrence runs on
        u(t0-1) … u(t0+T-2)."""
        B = ypast.shape[0]
        x0 = torch.cat([ypast.flip(1).reshape(B, -1), upast.flip(1).reshape(B, -1)], dim=1)  # lag-major, eq. 2-14
        return self.simulate(x0, torch.cat([upast[:, -1:], useq[:, :-1]], dim=1))

    def simulate(self, x0: torch.Tensor, useq: torch.Tensor) -> torch.Tensor:
        """``x0`` (B, n_enc_in) past regressor, ``useq`` (B, T, nu) inputs u(t0-1) … u(t0+T-2) → ŷ (B, T, ny)."""
        z = self.encoder(x0)
        if self.cell == "lstm":
            h0 = (z[:, : self.n_state].unsqueeze(0).contiguous(), z[:, self.n_state :].unsqueeze(0).contiguous())
        else:
            h0 = z.unsqueeze(0).contiguous()
        out, _ = self.rnn(useq, h0)
        y = self.readout(out)
        return y if self.arx is None else y + self.linear_path(x0, useq)

    def arx_layer(self) -> torch.nn.Linear:
        """The ARX path, present when the network was built with ``linear`` > 0."""
        if self.arx is None:
            raise ValueError("the network has no ARX path (built with linear=0)")
        return self.arx

    def linear_path(self, x0: torch.Tensor, useq: torch.Tensor) -> torch.Tensor:
        """Free-run simulation of the ARX path over the window: ŷ_lin (B, T, ny) for targets t0 … t0+T-1."""
        k, ny, nu = self.k, self.ny, self.nu
        B, T = useq.shape[0], useq.shape[1]
        nyr = self.n_enc * ny
        # u(t0-k) … u(t0-2) from the encoder window (lags k … 2), then u(t0-1) … u(t0+T-2)
        upast = x0[:, nyr : nyr + k * nu].reshape(B, k, nu).flip(1)[:, : k - 1]
        ufull = torch.cat([upast, useq], dim=1)  # ufull[:, m] = u(t0-k+m)
        win = ufull.unfold(1, k, 1)[:, :T]  # (B, T, nu, k): u(t0+j-k) … u(t0+j-1)
        ureg = win.flip(-1).permute(0, 1, 3, 2).reshape(B, T, k * nu)  # lag-major u(t0+j-1) … u(t0+j-k)
        arx = self.arx_layer()
        W = arx.weight
        v = torch.matmul(ureg, W[:, k * ny :].t()) + arx.bias  # input part and intercept, all steps at once
        Ay = W[:, : k * ny]
        hist = x0[:, : k * ny]  # measured y(t0-1) … y(t0-k)
        if ny == 1 and T >= FILTER_MIN_STEPS and v.dtype == torch.float64 and not torch.is_grad_enabled():
            return self._linear_path_filter(v, hist, Ay)
        outs = []
        for j in range(T):
            yl = torch.addmm(v[:, j], hist, Ay.t())
            outs.append(yl)
            hist = torch.cat([yl, hist[:, : (k - 1) * ny]], dim=1) if k > 1 else yl
        return torch.stack(outs, dim=1)

    @staticmethod
    def _linear_path_filter(v: torch.Tensor, hist: torch.Tensor, Ay: torch.Tensor) -> torch.Tensor:
        """The recursion of :meth:`linear_path` for one output without gradients: ŷ(j) = v(j) + Σ_i a_i ŷ(j − i)
        is the IIR filter 1/(1 − Σ a_i q^−i) of v, started from the measured outputs (scipy.signal.lfilter,
        one compiled pass per sequence instead of one tensor operation per step: 3.7 s → 0.01 s for the
        170 000-sample free run of cantilever-thesis). Equal to the loop to rounding (tests/test_neural_linear.py)."""
        from scipy.signal import lfilter, lfiltic

        a = np.r_[1.0, -Ay.detach().cpu().double().numpy()[0]]
        vv = v.detach().cpu().double().numpy()[:, :, 0]
        past = hist.detach().cpu().double().numpy()
        out = np.stack([lfilter([1.0], a, vv[i], zi=lfiltic([1.0], a, past[i]))[0] for i in range(vv.shape[0])])
        return torch.from_numpy(out[:, :, None]).to(dtype=v.dtype, device=v.device)

    @torch.no_grad()
    def init_linear(self, L: np.ndarray, c: np.ndarray) -> None:
        """ARX path at (L, c) (from :func:`least_squares_linear`), readout at zero: ŷ = the ARX simulation."""
        arx = self.arx_layer()
        arx.weight.copy_(torch.as_tensor(L, dtype=arx.weight.dtype))
        arx.bias.copy_(torch.as_tensor(c, dtype=arx.bias.dtype))
        self.readout.weight.zero_()
        self.readout.bias.zero_()


class RNNStateSpace(SequenceIdentifier):
    """GRU/LSTM state-space model with a learned initial-state encoder, trained on simulation error.

    Parameters
    ----------
    n_state : int
        Dimension of the recurrent state h.
    n_enc : int
        Past samples of y and u given to the encoder (the model's ``max_lag_``).
    enc_hidden : list of int
        Hidden widths of the encoder MLP (tanh).
    cell : str
        ``gru`` or ``lstm``.
    window, batch_size, epochs, lr : int, int, int, float
        Simulated window length T, windows per batch, epochs (each draws rows/T windows) and Adam step size.
    clip : float
        Gradient-norm clipping (0: off).
    linear : int
        Order k (0 … n_enc) of the linear ARX path added to the output, started at the least-squares ARX(k, k)
        with intercept and kept fixed in training (the recurrent network learns the residual of its simulation);
        0 (default): no linear path. The same option name as the NARX-MLP's bypass; the older name
        ``linear_order`` is accepted as a deprecated alias (:data:`sysid.config.ALIASES`).
    seed, device, dtype :
        As for the NARX-MLP (``dtype``: training precision, ``float32`` or ``float64``).
    """

    name = "rnn"
    _fitted_attr = "state_dict_"

    def __init__(
        self,
        n_state: int = 32,
        n_enc: int = 20,
        enc_hidden: Sequence[int] = (64,),
        cell: str = "gru",
        window: int = 100,
        batch_size: int = 32,
        epochs: int = 30,
        lr: float = 3e-3,
        clip: float = 1.0,
        seed: int = 0,
        device: str = "auto",
        linear: int = 0,
        dtype: str = "float32",
    ):
        self.dtype = dtype
        self.linear = linear
        self.n_state = n_state
        self.n_enc = n_enc
        self.enc_hidden = list(enc_hidden) if isinstance(enc_hidden, (list, tuple)) else enc_hidden
        self.cell = cell
        self.window = window
        self.batch_size = batch_size
        self.epochs = epochs
        self.lr = lr
        self.clip = clip
        self.seed = seed
        self.device = device

    # ------------------------------------------------------------------ checks
    def _check_params(self, check_device: bool = True) -> None:
        self._check_int("n_state", 1, 4096)
        self._check_int("n_enc", 1, MAX_LAG)
        self._check_int("window", 1, 100_000)
        self._check_int("batch_size", 1, 1_000_000)
        self._check_int("epochs", 0, 1_000_000)
        self._check_int("linear", 0, int(self.n_enc))
        eh = self.enc_hidden
        if not isinstance(eh, (list, tuple)) or not all(
            isinstance(w, (int, np.integer)) and not isinstance(w, bool) and w >= 1 for w in eh
        ):
            raise ConfigError(f"{self.name}: enc_hidden={eh!r} must be a list of widths, e.g. enc_hidden=64 or 64-64")
        self.enc_hidden = [int(w) for w in eh]
        if self.cell not in CELLS:
            raise ConfigError(f"{self.name}: cell={self.cell!r} not one of: {', '.join(CELLS)}")
        self._check_step_size("lr")
        self._check_clip()
        train_dtype(getattr(self, "dtype", "float32"), self.name)
        self._check_seed_device(check_device)

    def _build(self, nu: int, ny: int) -> _Net:
        return _Net(
            self.n_enc * (nu + ny),
            self.enc_hidden,
            int(self.n_state),
            nu,
            ny,
            self.cell,
            int(self.linear),
            int(self.n_enc),
        )

    # ------------------------------------------------------------------ fit
    def fit(self, data: Record | Sequence[Record]) -> RNNStateSpace:
        self._check_params()
        recs = as_record_list(data)
        lag, T = int(self.n_enc), int(self.window)
        nu, ny = check_channels(recs, lag, self.name)
        device, gen, pairs = self._start_fit(recs)
        dtype = train_dtype(getattr(self, "dtype", "float32"), self.name)
        if not any(u.shape[0] >= lag + T for u, _ in pairs):
            raise DataError(f"{self.name}: no record has {T + lag} samples for one window; lower window or n_enc")
        net = self._build(nu, ny)
        if self.linear:
            # the ARX path is the least-squares ARX, kept fixed; the recurrent network learns the residual of its
            # simulation. Training it with Adam as well was measured worse (quick data, free-run RMSE: cascaded
            # tanks 2.1 V trained vs 0.65 V fixed; piezo 3.5 vs 1.09 um): Adam's steps of about lr per weight
            # move the poles of a finely sampled ARX that far.
            net.init_linear(*least_squares_linear(pairs, int(self.linear), int(self.linear)))
            net.arx_layer().requires_grad_(False)
        net = net.to(device=device, dtype=dtype)
        n_rows = sum(max(0, u.shape[0] - lag) for u, _ in pairs)  # targets with a full encoder window
        res = train_simulation(
            net,
            pairs,
            lag,
            T,
            int(self.epochs),
            int(self.batch_size),
            float(self.lr),
            clip=float(self.clip),
            generator=gen,
            device=device,
            dtype=dtype,
            draws=max(1, math.ceil(n_rows / T)),
            desc=self.name,
        )
        self.state_dict_ = {k: v.detach().to("cpu", torch.float64).numpy().copy() for k, v in net.state_dict().items()}
        self.n_parameters_ = int(sum(v.size for v in self.state_dict_.values()))
        self._end_fit(res, nu, ny, lag, device)
        self._net64: _Net | None = None
        return self

    # ------------------------------------------------------------------ predict
    def _cpu_net(self) -> _Net:
        net: _Net | None = getattr(self, "_net64", None)
        if net is None:
            net = self._build(self.n_inputs_, self.n_outputs_).to(torch.float64)
            net.load_state_dict({k: torch.as_tensor(v, dtype=torch.float64) for k, v in self.state_dict_.items()})
            net.eval()
            self._net64 = net
        return net

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """Free run (``None``) or k-step-ahead at every sample (``horizon=k``; 1 = one step). Shaped like y."""
        self._check_fitted()
        check_predict_input(self, record, horizon)
        lag = self.max_lag_
        n = len(record)
        configure_threads()
        ((un, yn),) = normalised_pairs([record], self.normaliser_)
        net = self._cpu_net()
        self.diverged_at_ = None
        yhat = yn.copy()
        with torch.no_grad():
            if horizon is None or horizon >= n - lag:
                yhat[lag:] = net(
                    torch.from_numpy(yn[None, :lag]), torch.from_numpy(un[None, :lag]), torch.from_numpy(un[None, lag:])
                ).numpy()[0]
            else:
                k = int(horizon)
                targets = np.arange(lag, n)
                t0 = np.maximum(targets - k + 1, lag)  # window start (first simulated target) per target
                steps = targets - t0 + 1  # ≤ k; shorter only at the record start
                chunk = max(1, 4_000_000 // max(1, k * int(self.n_state)))
                for a in range(0, targets.size, chunk):
                    sl = slice(a, a + chunk)
                    tt0 = t0[sl]
                    past = tt0[:, None] + np.arange(-lag, 0)[None, :]
                    idx = np.clip(tt0[:, None] + np.arange(k)[None, :], 0, n - 1)
                    # (B, k, nu) inputs u(t0) …; steps past a short window are simply not read
                    out = net(torch.from_numpy(yn[past]), torch.from_numpy(un[past]), torch.from_numpy(un[idx])).numpy()
                    yhat[targets[sl]] = out[np.arange(out.shape[0]), steps[sl] - 1]
        bad = ~np.isfinite(yhat).all(axis=1)
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            self.diverged_at_ = first
            if horizon is None:
                yhat[first:] = np.nan
            warnings.warn(f"{self.name}: non-finite predictions from sample {first}", DivergenceWarning, stacklevel=2)
        return self._in_units(yhat, record)

    # ------------------------------------------------------------------ description / persistence
    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "state_dict_"):
            d.update(
                {
                    "structure": {
                        "cell": self.cell,
                        "n_state": self.n_state,
                        "n_enc": self.n_enc,
                        "enc_hidden": list(self.enc_hidden),
                        "linear": int(self.linear),
                        "linear_order": int(self.linear),
                    },  # old key, kept for readers
                    **self._training_summary(),
                }
            )
        return d

    def _state(self) -> dict[str, Any]:
        if not hasattr(self, "state_dict_"):
            raise ConfigError(f"{self.name}: model is not fitted; nothing to save")
        return {"state_dict": {k: np.asarray(v) for k, v in self.state_dict_.items()}, **self._common_state()}

    def _load_state(self, state: dict[str, Any]) -> None:
        self._check_params(check_device=False)
        self._load_common(state, int(self.n_enc))
        ref = self._build(self.n_inputs_, self.n_outputs_).state_dict()
        sd = {k: saved_array(self.name, state["state_dict"], k, tuple(v.shape)) for k, v in ref.items()}
        self.state_dict_ = sd
        self.n_parameters_ = int(sum(v.size for v in sd.values()))
        self._net64 = None
