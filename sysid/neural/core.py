"""Building blocks shared by the neural identifiers.

- :class:`LagData` — the regression matrix Φ and targets Y of dissertation eq. 2-14 / 2-15 for one or several
  records (no regressor spans two records), kept as tensors on the training device. Row ``r`` holds, for a
  target time ``t``, ``[y(t-1) … y(t-ny), u(t-1) … u(t-nu)]`` (lag-major; all channels of one lag side by
  side). Small problems pre-build Φ once; very long lags (Φ larger than ``PREBUILD_LIMIT`` elements) gather
  rows on demand from the series instead, so lags up to 1024 fit in memory.
- :class:`FlatMLP` — the feed-forward network of eq. 2-10 (Glorot-uniform weights, zero biases: the Keras
  defaults the dissertation used), with all parameters in one flat tensor so that the optimiser is four
  tensor operations per step. Optional linear bypass (``linear=True``): output = L x + MLP(x), a linear
  model of the regressor plus a neural correction (a linear model refined by a network, as in BLA-initialised
  networks, Schoukens & Ljung 2019, and the linear skip of SUBNET, Beintema et al.). ``L`` is stored after the
  network's parameters in the same flat buffer (``n_out × n_in`` more entries).
- :class:`RMSprop` — eq. 2-25 / 2-26 on that flat tensor: ``v ← α v + (1-α) g²``,
  ``θ ← θ − η g / sqrt(v + ε)`` with the Keras defaults α = 0.9, ε = 1e-7.
- :func:`mlp_forward_np`, :func:`free_run_mlp` (numba-compiled recursion of eq. 2-29/2-30), :func:`k_step_mlp`
  — prediction in float64 on the CPU from exported weights.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from numba import njit

from sysid.errors import ConfigError, DataError

__all__ = [
    "grad_of",
    "regressor_lag",
    "ACTIVATIONS",
    "LagData",
    "FlatMLP",
    "RMSprop",
    "mlp_forward_np",
    "free_run_mlp",
    "k_step_mlp",
    "count_mlp_parameters",
    "n_mlp_weights",
    "least_squares_linear",
    "merge_ensemble",
]

ACTIVATIONS = ("sigmoid", "tanh", "relu")
ACT_CODE = {"relu": 0, "tanh": 1, "sigmoid": 2}
PREBUILD_LIMIT = 40_000_000  # elements of Φ (160 MB in float32) above which rows are gathered per batch


def grad_of(t: torch.Tensor) -> torch.Tensor:
    """The gradient buffer of a trained tensor: allocated with the network (views of one flat buffer) and written
    in place, so a missing one is a programming error."""
    if t.grad is None:
        raise RuntimeError("tensor has no gradient buffer")
    return t.grad


def regressor_lag(ny: int, nu: int, nk: int = 1) -> int:
    """Samples of history a regressor needs: y(t-1…t-ny) and u(t-nk … t-nk-nu+1)."""
    return max(int(ny), int(nk) + int(nu) - 1 if nu > 0 else 0)


def count_mlp_parameters(n_in: int, hidden: Sequence[int], n_out: int, linear: bool = False) -> int:
    """Weights + biases of a dense network (Table 4.2: 20 inputs, 4 × 25, 1 output → 2501), plus the
    ``n_out × n_in`` matrix of the linear bypass when ``linear``."""
    sizes = [int(n_in), *[int(h) for h in hidden], int(n_out)]
    return int(sum(a * b + b for a, b in zip(sizes[:-1], sizes[1:]))) + (int(n_in) * int(n_out) if linear else 0)


def n_mlp_weights(sizes: Sequence[int]) -> int:
    """Entries of the flat buffer that belong to the dense layers (the linear bypass, if any, follows them)."""
    return int(sum(int(a) * int(b) + int(b) for a, b in zip(sizes[:-1], sizes[1:])))


def merge_ensemble(
    members: Sequence[np.ndarray], sizes: Sequence[int], linear: bool = False
) -> tuple[np.ndarray, list[int]]:
    """One dense network computing the MEAN of k networks of the same layer sizes (flat layout of
    :class:`FlatMLP`), so every prediction path of a single network (numba free run, k-step, save/load) serves
    an ensemble unchanged. In free run the mean is what is fed back: one model, not k simulations.

    Hidden layer ``l`` of the merged net is the members' layers side by side (width k·h_l): the first layer's
    weights and biases stacked, deeper layers block-diagonal (zeros between members, so member i's units see
    only member i's units), the output weights side by side divided by k and the output bias the members'
    mean; the linear bypass L (``linear``) is the members' mean (in the NARX-MLP it is the same fixed
    least-squares ARX in every member, so it is that L). Exact up to float64 rounding.
    Returns (flat weights, merged sizes ``[n_in, k·h_1, …, k·h_L, n_out]``).
    """
    members = [np.asarray(m, dtype=np.float64) for m in members]
    k = len(members)
    sizes = [int(v) for v in sizes]
    n_layers = len(sizes) - 1
    if k < 1:
        raise ValueError("merge_ensemble needs at least one member")
    n_w = count_mlp_parameters(sizes[0], sizes[1:-1], sizes[-1], linear)
    if any(m.shape != (n_w,) for m in members):
        raise ValueError(f"merge_ensemble: every member needs {n_w} weights for sizes {sizes}")
    merged_sizes = [sizes[0], *[k * h for h in sizes[1:-1]], sizes[-1]]
    parts: list[np.ndarray] = []
    o = 0
    for layer in range(n_layers):
        a, b = sizes[layer], sizes[layer + 1]
        Ws = [m[o : o + a * b].reshape(b, a) for m in members]
        bs = [m[o + a * b : o + a * b + b] for m in members]
        o += a * b + b
        if n_layers == 1:  # no hidden layer: the mean of affine maps
            W, bias = sum(Ws) / k, sum(bs) / k
        elif layer == 0:
            W, bias = np.concatenate(Ws, axis=0), np.concatenate(bs)
        elif layer < n_layers - 1:
            W = np.zeros((k * b, k * a))
            for i, Wi in enumerate(Ws):
                W[i * b : (i + 1) * b, i * a : (i + 1) * a] = Wi
            bias = np.concatenate(bs)
        else:
            W, bias = np.concatenate(Ws, axis=1) / k, sum(bs) / k
        parts += [W.reshape(-1), bias]  # type: ignore[union-attr, list-item]  # sum() of arrays is an array
    if linear:
        Ls = [m[o : o + sizes[0] * sizes[-1]] for m in members]
        parts.append(Ls[0].copy() if all(np.array_equal(L, Ls[0]) for L in Ls) else sum(Ls) / k)  # type: ignore[arg-type]
    return np.concatenate(parts), merged_sizes


# ---------------------------------------------------------------------------------------------- data
class LagData:
    """Φ and Y (eq. 2-14, 2-15) for a list of normalised ``(u, y)`` pairs, 2-D arrays ``(N, channels)``."""

    def __init__(
        self,
        pairs: Sequence[tuple[np.ndarray, np.ndarray]],
        ny: int,
        nu: int,
        device: torch.device,
        dtype: torch.dtype = torch.float32,
        prebuild: bool | None = None,
        nk: int = 1,
    ):
        self.ny, self.nu, self.nk = int(ny), int(nu), int(nk)
        self.lag = regressor_lag(self.ny, self.nu, self.nk)
        self.ny_ch = pairs[0][1].shape[1]
        self.nu_ch = pairs[0][0].shape[1]
        self.n_yreg = self.ny * self.ny_ch
        self.n_in = self.n_yreg + self.nu * self.nu_ch
        ucat, ycat, row_time, seg, seg_bounds = [], [], [], [], []
        offset = rows = 0
        for k, (u, y) in enumerate(pairs):
            n = u.shape[0]
            if n <= self.lag:
                continue
            ucat.append(u)
            ycat.append(y)
            t = np.arange(self.lag, n) + offset
            row_time.append(t)
            seg.append(np.full(t.size, k))
            seg_bounds.append((rows, rows + t.size))
            rows += t.size
            offset += n
        if not row_time:
            raise DataError(f"records too short for lag {self.lag}: need more than {self.lag} samples")
        u_all = np.concatenate(ucat)
        y_all = np.concatenate(ycat)
        self.row_time_np = np.concatenate(row_time)
        self.seg_bounds = seg_bounds  # row ranges [a, b) of each record
        self.n_rows = int(self.row_time_np.size)
        self.device = device
        self.dtype = dtype
        self.u = torch.as_tensor(u_all, dtype=dtype, device=device)
        self.y = torch.as_tensor(y_all, dtype=dtype, device=device)
        self.row_time = torch.as_tensor(self.row_time_np, dtype=torch.long, device=device)
        self.ylags = torch.arange(1, self.ny + 1, device=device)
        self.ulags = torch.arange(self.nk, self.nk + self.nu, device=device)
        self.Y = self.y[self.row_time]
        if prebuild is None:
            prebuild = self.n_rows * self.n_in <= PREBUILD_LIMIT
        self.X = self._gather(self.row_time) if prebuild else None

    def _gather(self, t: torch.Tensor) -> torch.Tensor:
        yp = self.y[t[:, None] - self.ylags[None, :]].reshape(t.shape[0], -1)
        up = self.u[t[:, None] - self.ulags[None, :]].reshape(t.shape[0], -1)
        return torch.cat([yp, up], dim=1)

    def x(self, rows: torch.Tensor) -> torch.Tensor:
        """Regressor rows (eq. 2-14) for the given row indices."""
        return self.X[rows] if self.X is not None else self._gather(self.row_time[rows])

    def window_starts(self, window: int) -> np.ndarray:
        """Every row that can start a window of ``window`` consecutive targets inside one record."""
        out = [np.arange(a, b - window + 1) for a, b in self.seg_bounds if b - a >= window]
        return np.concatenate(out) if out else np.zeros(0, dtype=np.int64)


def least_squares_linear(
    pairs: Sequence[tuple[np.ndarray, np.ndarray]], ny: int, nu: int, nk: int = 1, chunk: int = 20_000
) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares linear model of the NARX regressor: ``y(t) ≈ L φ(t) + c`` over every regressor row of the
    (normalised) ``(u, y)`` pairs, φ(t) as in :class:`LagData` (eq. 2-14/2-15).

    This is the ARX model of the same lags with an intercept: least squares is affine invariant, so it predicts
    what an ARX fitted on the raw data with an intercept predicts. Solved in float64 from the normal equations
    accumulated over row chunks, columns scaled to a unit diagonal, with ``numpy.linalg.lstsq`` (minimum-norm
    solution if the regressor is rank deficient). Returns (L (n_out, n_in), c (n_out,)).
    """
    lag = regressor_lag(ny, nu, nk)
    G = b = None
    for u, y in pairs:
        for a0 in range(lag, y.shape[0], chunk):
            times = np.arange(a0, min(a0 + chunk, y.shape[0]))
            X = np.concatenate(
                [lag_matrix_np(y, ny, times), lag_matrix_np(u, nu, times, first=nk), np.ones((times.size, 1))], axis=1
            )
            G = X.T @ X if G is None else G + X.T @ X
            b = X.T @ y[times] if b is None else b + X.T @ y[times]
    if G is None or b is None:
        raise DataError(f"no regressor row: every record is at most {lag} samples long")
    d = np.sqrt(np.maximum(np.diag(G), 1e-300))
    theta = np.linalg.lstsq(G / d[:, None] / d[None, :], b / d[:, None], rcond=None)[0] / d[:, None]
    return theta[:-1].T.copy(), theta[-1].copy()


# ---------------------------------------------------------------------------------------------- network
class FlatMLP(torch.nn.Module):
    """Dense network of eq. 2-10 with hidden widths ``hidden`` and activation ``activation`` (linear output).

    Every weight matrix and bias is a leaf tensor whose storage is a slice of one flat buffer ``flat`` (and
    whose gradient is a slice of ``flat.grad``), so the forward pass is plain ``addmm`` calls and the
    optimiser updates all 2501 weights of the 4 × 25 net with a handful of whole-buffer operations.
    """

    def __init__(
        self,
        n_in: int,
        hidden: Sequence[int],
        n_out: int,
        activation: str,
        generator: torch.Generator,
        device: torch.device,
        dtype: torch.dtype = torch.float32,
        linear: bool = False,
    ):
        super().__init__()
        sizes = [int(n_in), *[int(h) for h in hidden], int(n_out)]
        self.sizes = sizes
        self.linear = bool(linear)
        self.activation = activation
        self.act = {"relu": torch.relu, "tanh": torch.tanh, "sigmoid": torch.sigmoid}[activation]
        n_total = count_mlp_parameters(n_in, hidden, n_out, self.linear)
        # Glorot-uniform init (Keras default) drawn on the CPU generator so the draw is device-independent.
        init = torch.zeros(n_total, dtype=torch.float64)
        o = 0
        for a, b in zip(sizes[:-1], sizes[1:]):
            lim = (6.0 / (a + b)) ** 0.5
            init[o : o + a * b] = (torch.rand(a * b, generator=generator, dtype=torch.float64) * 2 - 1) * lim
            o += a * b + b  # biases stay zero
        self.flat = torch.nn.Parameter(init.to(device=device, dtype=dtype))
        self.flat.grad = torch.zeros_like(self.flat)
        self.layers: list[tuple[torch.Tensor, torch.Tensor]] = []
        o = 0
        for a, b in zip(sizes[:-1], sizes[1:]):
            W = torch.empty(0, dtype=dtype, device=device)
            W.data = self.flat.data[o : o + a * b].view(b, a)
            W.requires_grad_(True)
            W.grad = self.flat.grad[o : o + a * b].view(b, a)
            o += a * b
            bias = torch.empty(0, dtype=dtype, device=device)
            bias.data = self.flat.data[o : o + b]
            bias.requires_grad_(True)
            bias.grad = self.flat.grad[o : o + b]
            o += b
            self.layers.append((W, bias))
        self.L: torch.Tensor | None = None
        if self.linear:  # the bypass starts at zero; init_linear() sets it (e.g. to least squares)
            L = torch.empty(0, dtype=dtype, device=device)
            L.data = self.flat.data[o : o + n_in * n_out].view(n_out, n_in)
            L.requires_grad_(True)
            L.grad = self.flat.grad[o : o + n_in * n_out].view(n_out, n_in)
            self.L = L

    @torch.no_grad()
    def init_linear(self, L: np.ndarray, c: np.ndarray) -> None:
        """Start from a linear model: bypass ``L`` (n_out × n_in), output bias ``c`` and the output layer's
        weights zero, so that the network computes exactly ``L x + c`` until training adds a correction."""
        if self.L is None:
            raise ValueError("init_linear needs a network built with linear=True")
        self.L.copy_(torch.as_tensor(np.asarray(L), dtype=self.L.dtype))
        W, b = self.layers[-1]
        W.zero_()
        b.copy_(torch.as_tensor(np.asarray(c), dtype=b.dtype))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        last = len(self.layers) - 1
        act = self.act
        x0 = x
        for i, (W, b) in enumerate(self.layers):
            x = torch.addmm(b, x, W.t())
            if i < last:
                x = act(x)
        if self.L is not None:
            x = torch.addmm(x, x0, self.L.t())
        return x

    @torch.no_grad()
    def freeze_linear(self) -> None:
        """Keep the linear bypass fixed in training: its gradient stays zero (so RMSprop does not move it)."""
        if self.L is None:
            raise ValueError("freeze_linear needs a network built with linear=True")
        self.L.requires_grad_(False)
        grad_of(self.L).zero_()

    @torch.no_grad()
    def mse_grad_(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """MSE loss of a batch and its gradient written into ``flat.grad`` (overwritten, not accumulated).
        A frozen linear bypass (:meth:`freeze_linear`) gets a zero gradient.

        Hand-written back-propagation for this plain dense network — the same derivatives autograd computes
        (checked in the tests), without the autograd engine's per-operation overhead, which dominates for
        networks this small (a 4 × 25 step: 36 small tensor operations). Returns the loss (0-d tensor).
        """
        acts = [x]
        last = len(self.layers) - 1
        a = x
        for i, (W, b) in enumerate(self.layers):
            a = torch.addmm(b, a, W.t())
            if i < last:
                a = self.act(a)
            acts.append(a)
        if self.L is not None:
            a = torch.addmm(a, x, self.L.t())
        diff = a - y
        loss = diff.pow(2).mean()
        delta = diff.mul_(2.0 / diff.numel())
        if self.L is not None:  # d loss / d L = delta^T x (the bypass is linear in L)
            if self.L.requires_grad:
                torch.mm(delta.t(), x, out=grad_of(self.L))
            else:
                grad_of(self.L).zero_()
        for i in range(last, -1, -1):
            W, b = self.layers[i]
            torch.mm(delta.t(), acts[i], out=W.grad)
            torch.sum(delta, 0, out=b.grad)
            if i > 0:
                back = delta.mm(W)
                h = acts[i]
                if self.activation == "relu":
                    delta = back.mul_(h > 0)
                elif self.activation == "tanh":
                    delta = back.mul_(1.0 - h * h)
                else:
                    delta = back.mul_(h * (1.0 - h))
        return loss

    def check_grad_storage(self) -> bool:
        """True while every layer's gradient still lives in ``flat.grad`` (autograd accumulates in place)."""
        g = grad_of(self.flat)
        leaves = [W for W, _ in self.layers] + ([self.L] if self.L is not None else [])
        return all(
            W.grad is not None and W.grad.untyped_storage().data_ptr() == g.untyped_storage().data_ptr() for W in leaves
        )

    def weights_np(self) -> np.ndarray:
        return self.flat.detach().to("cpu", torch.float64).numpy().copy()


class RMSprop:
    """RMSprop of eq. 2-25/2-26 on one flat parameter tensor (α = 0.9, ε = 1e-7: Keras defaults)."""

    def __init__(self, param: torch.nn.Parameter, lr: float, alpha: float = 0.9, eps: float = 1e-7):
        self.p = param
        self.lr, self.alpha, self.eps = float(lr), float(alpha), float(eps)
        self.v = torch.zeros_like(param)
        self._tmp = torch.empty_like(param)
        if param.grad is None:
            param.grad = torch.zeros_like(param)

    def zero_grad(self) -> None:
        grad_of(self.p).zero_()

    @torch.no_grad()
    def step(self) -> None:
        g = grad_of(self.p)
        p = self.p.data
        self.v.mul_(self.alpha).addcmul_(g, g, value=1.0 - self.alpha)  # eq. 2-25
        torch.add(self.v, self.eps, out=self._tmp).sqrt_()
        p.addcdiv_(g, self._tmp, value=-self.lr)  # eq. 2-26


# ---------------------------------------------------------------------------------------------- prediction
def _act_np(x: np.ndarray, code: int) -> np.ndarray:
    if code == 0:
        return np.maximum(x, 0.0)
    if code == 1:
        return np.tanh(x)
    return 1.0 / (1.0 + np.exp(-x))


def mlp_forward_np(
    flat: np.ndarray, sizes: Sequence[int], code: int, x: np.ndarray, linear: bool = False
) -> np.ndarray:
    """Batched float64 forward pass of the flat network: ``x`` (B, n_in) → (B, n_out); with ``linear`` the
    bypass ``x Lᵀ`` (L stored after the layers) is added."""
    o = 0
    last = len(sizes) - 2
    x0 = x
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        W = flat[o : o + a * b].reshape(b, a)
        o += a * b
        x = x @ W.T + flat[o : o + b]
        o += b
        if i < last:
            x = _act_np(x, code)
    if linear:
        x = x + x0 @ flat[o : o + sizes[0] * sizes[-1]].reshape(sizes[-1], sizes[0]).T
    return x


@njit(cache=True)
def _free_run_kernel(flat, sizes, code, y0, un, ny, nu, nk, start, bound, linear):  # pragma: no cover - compiled
    n, ny_ch = y0.shape
    nu_ch = un.shape[1]
    n_layers = sizes.shape[0] - 1
    out = y0.copy()
    width = 0
    for i in range(sizes.shape[0]):
        if sizes[i] > width:
            width = sizes[i]
    a_buf = np.empty(width)
    b_buf = np.empty(width)
    n_in = sizes[0]
    n_out = sizes[n_layers]
    x_buf = np.empty(n_in)
    lin0 = 0  # offset of the bypass L (n_out × n_in) after the layers
    for layer in range(n_layers):
        lin0 += sizes[layer] * sizes[layer + 1] + sizes[layer + 1]
    diverged = -1
    for t in range(start, n):
        # regressor: y(t-1..t-ny) (all channels per lag), then u(t-1..t-nu)
        k = 0
        for i in range(1, ny + 1):
            for c in range(ny_ch):
                a_buf[k] = out[t - i, c]
                k += 1
        for i in range(nk, nk + nu):
            for c in range(nu_ch):
                a_buf[k] = un[t - i, c]
                k += 1
        if linear:
            for m in range(n_in):
                x_buf[m] = a_buf[m]
        o = 0
        for layer in range(n_layers):
            na = sizes[layer]
            nb = sizes[layer + 1]
            for j in range(nb):
                s = flat[o + na * nb + j]
                base = o + j * na
                for m in range(na):
                    s += flat[base + m] * a_buf[m]
                if layer < n_layers - 1:
                    if code == 0:
                        s = s if s > 0.0 else 0.0
                    elif code == 1:
                        s = np.tanh(s)
                    else:
                        s = 1.0 / (1.0 + np.exp(-s))
                b_buf[j] = s
            o += na * nb + nb
            for j in range(nb):
                a_buf[j] = b_buf[j]
        if linear:
            for j in range(n_out):
                s = 0.0
                base = lin0 + j * n_in
                for m in range(n_in):
                    s += flat[base + m] * x_buf[m]
                a_buf[j] += s
        bad = False
        for c in range(ny_ch):
            v = a_buf[c]
            if not np.isfinite(v) or abs(v) > bound:
                bad = True
            out[t, c] = v
        if bad:
            diverged = t
            for tt in range(t, n):
                for c in range(ny_ch):
                    out[tt, c] = np.nan
            break
    return out, diverged


def free_run_mlp(
    flat: np.ndarray,
    sizes: Sequence[int],
    code: int,
    yn: np.ndarray,
    un: np.ndarray,
    ny: int,
    nu: int,
    bound: float,
    nk: int = 1,
    linear: bool = False,
) -> tuple[np.ndarray, int]:
    """Free-run simulation (eq. 2-29/2-30) in normalised units: the first ``regressor_lag`` samples of ``yn``
    are the measured initial conditions, the rest is simulated from ``un``. Returns (ŷ, diverged index or -1).
    ``linear``: the network has the linear bypass (see :class:`FlatMLP`)."""
    lag = regressor_lag(ny, nu, nk)
    return _free_run_kernel(
        np.ascontiguousarray(flat, dtype=np.float64),
        np.asarray(sizes, dtype=np.int64),
        int(code),
        np.ascontiguousarray(yn, dtype=np.float64),
        np.ascontiguousarray(un, dtype=np.float64),
        int(ny),
        int(nu),
        int(nk),
        int(lag),
        float(bound),
        bool(linear),
    )


def lag_matrix_np(series: np.ndarray, lags: int, times: np.ndarray, first: int = 1) -> np.ndarray:
    """``[s(t-first) … s(t-first-lags+1)]`` for each t in ``times`` (lag-major, channels side by side)."""
    idx = times[:, None] - np.arange(first, first + lags)[None, :]
    return series[idx].reshape(times.size, -1)


def k_step_mlp(
    flat: np.ndarray,
    sizes: Sequence[int],
    code: int,
    yn: np.ndarray,
    un: np.ndarray,
    ny: int,
    nu: int,
    k: int,
    bound: float,
    nk: int = 1,
    linear: bool = False,
) -> np.ndarray:
    """k-step-ahead prediction ŷ(t | t-k) at every sample t ≥ lag, vectorised over t.

    With P_j(t) = ŷ(t | t-j-1), P_0 is the one-step prediction and P_j uses, for lag i, the earlier
    prediction P_{j-i}(t-i) when i ≤ j and the measurement y(t-i) otherwise; P_{k-1} is returned. Costs k
    batched passes of the network; only the last ny arrays P are kept.
    """
    n, ny_ch = yn.shape
    lag = regressor_lag(ny, nu, nk)
    times = np.arange(lag, n)
    U = lag_matrix_np(un, nu, times, first=nk)
    Ymeas = lag_matrix_np(yn, ny, times).reshape(times.size, ny, ny_ch)
    hist: list[np.ndarray] = []  # hist[-i] = P_{j-i} over the full time axis (measured before lag)
    if k < 1:
        raise ConfigError(f"k-step prediction needs k >= 1, got {k}")
    P = yn
    with np.errstate(over="ignore", invalid="ignore"):
        for j in range(k):
            Yreg = Ymeas.copy()
            for i in range(1, min(j, ny) + 1):
                Pji = hist[-i]
                Yreg[:, i - 1, :] = Pji[times - i]
            x = np.concatenate([Yreg.reshape(times.size, -1), U], axis=1)
            pred = mlp_forward_np(flat, sizes, code, x, linear)
            pred[~np.isfinite(pred) | (np.abs(pred) > bound)] = np.nan
            P = yn.copy()
            P[lag:] = pred
            hist.append(P)
            if len(hist) > ny:
                hist.pop(0)
    return P
