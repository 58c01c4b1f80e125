"""Differentiable linear dynamical (IIR) layer: y = G(q) u with G(q) = B(q)/A(q), filtered by ``scipy.signal.lfilter``.

The transfer function of one input–output pair, in the shift operator q (q⁻¹ u(t) = u(t-1)), is

    G(q) = q^{-nk} B(q)/A(q),   B(q) = b_0 + b_1 q⁻¹ + … + b_{nb-1} q^{-(nb-1)},
                                 A(q) = 1 + a_1 q⁻¹ + … + a_na q^{-na},

i.e. the difference equation y(t) = Σ_j b_j u(t-nk-j) − Σ_{j≥1} a_j y(t-j), run from rest (zero initial state,
u = y = 0 before the first sample). This is the linear dynamical operator of Forgione & Piga, "dynoNet: a neural
network architecture for learning dynamical systems" (Int. J. Adaptive Control and Signal Processing, 2021),
written here from its mathematics.

Derivatives (the backward pass is filtering too; T samples, loss L, output gradient g(t) = ∂L/∂y(t)). The
sensitivities are ∂y/∂b_j = q^{-j}/A · u and ∂y/∂a_j = −q^{-j}/A · y (paper, eq. 17–18), so

    ∂L/∂b_j = Σ_t g(t) (q^{-j}/A u)(t),     ∂L/∂a_j = −Σ_t g(t) (q^{-j}/A y)(t),     ∂L/∂u = G(q)ᵀ g.

Causal LTI operators on a record started from rest are lower-triangular Toeplitz matrices and commute, so every
one of the three sums reads from the same anti-causally filtered gradient g̃ = (1/A)ᵀ g (``lfilter(1, A, ·)`` on
the time-reversed g, reversed back):

    ∂L/∂b_j = Σ_s g̃(s+j) u(s),   ∂L/∂a_j = −Σ_s g̃(s+j) y(s),   ∂L/∂u(s) = Σ_j b_j g̃(s+j)

— one lfilter and nb + na shifted dot products per pair, instead of one lfilter per coefficient. The tests check
these against ``torch.autograd.gradcheck`` (finite differences of the forward definition) in float64.

The filtering runs in float64 numpy on the CPU whatever the tensors' device (tensors on a GPU are copied to the CPU
and back): lfilter is a sequential recursion, which a GPU would not speed up for these few channels.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.signal import lfilter

__all__ = ["IIRFilter", "MIMOFilter", "iir_filter", "LinearDynamic", "filter_np"]


def _np(t: torch.Tensor) -> np.ndarray:
    return t.detach().to("cpu", torch.float64).numpy()


def _shifted_dots(gt: np.ndarray, x: np.ndarray, n: int, first: int) -> np.ndarray:
    """``Σ_batch Σ_s gt(s+j) x(s)`` for j = first … first+n-1 (arrays (B, T))."""
    T = x.shape[1]
    return np.array([float(np.vdot(gt[:, j:], x[:, : T - j])) if j < T else 0.0 for j in range(first, first + n)])


def _pair_backward(
    g: np.ndarray, u: np.ndarray, y: np.ndarray, b: np.ndarray, a: np.ndarray, gu: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of one pair y = B/A u (arrays (B, T)) from its output gradient ``g``: returns (∂L/∂b, ∂L/∂a) and,
    when ``gu`` is given, adds ∂L/∂u to it in place."""
    gt = np.ascontiguousarray(lfilter([1.0], np.concatenate([[1.0], a]), g[:, ::-1], axis=1)[:, ::-1])  # g̃ = (1/A)ᵀ g
    if gu is not None:
        T = u.shape[1]
        for j, bj in enumerate(b):
            if j < T:
                gu[:, : T - j] += bj * gt[:, j:]
    return _shifted_dots(gt, u, b.size, 0), -_shifted_dots(gt, y, a.size, 1)


class IIRFilter(torch.autograd.Function):
    """``y = B(q)/A(q) u`` along the time axis of ``u`` (B, T); ``b`` (nb,), ``a`` (na,) without the leading 1 of A."""

    @staticmethod
    def forward(ctx, u: torch.Tensor, b: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        un, bn, an = np.ascontiguousarray(_np(u)), _np(b), _np(a)
        y = lfilter(bn, np.concatenate([[1.0], an]), un, axis=1)
        ctx.save_for_backward(u, b, a)
        ctx.y = y
        return torch.as_tensor(y, dtype=u.dtype, device=u.device)

    @staticmethod
    def backward(ctx, grad_y: torch.Tensor):
        u, b, a = ctx.saved_tensors
        un = np.ascontiguousarray(_np(u))
        gun = np.zeros_like(un) if ctx.needs_input_grad[0] else None
        gb, ga = _pair_backward(_np(grad_y), un, ctx.y, _np(b), _np(a), gun)
        as_t = lambda x, like: torch.as_tensor(x, dtype=like.dtype, device=like.device)  # noqa: E731
        return (
            None if gun is None else as_t(gun, u),
            as_t(gb, b) if ctx.needs_input_grad[1] else None,
            as_t(ga, a) if ctx.needs_input_grad[2] else None,
        )


def iir_filter(u: torch.Tensor, b: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
    """Differentiable ``B(q)/A(q) u`` over the last axis of ``u`` (B, T)."""
    return IIRFilter.apply(u, b, a)


class MIMOFilter(torch.autograd.Function):
    """All pairs of a :class:`LinearDynamic` layer in one autograd node: ``u`` (B, T, n_in), ``b`` (n_out, n_in, nb),
    ``a`` (n_out, n_in, na) → ``y`` (B, T, n_out), ``y_o = Σ_i B_oi/A_oi u_i``. The same mathematics as
    :class:`IIRFilter` pair by pair, with the channel loops in numpy (one graph node instead of one per pair)."""

    @staticmethod
    def forward(ctx, u: torch.Tensor, b: torch.Tensor, a: torch.Tensor) -> torch.Tensor:
        un = np.ascontiguousarray(np.moveaxis(_np(u), 2, 0))  # (n_in, B, T)
        bn, an = _np(b), _np(a)
        n_out, n_in = bn.shape[:2]
        ys = np.empty((n_out, n_in) + un.shape[1:])
        for o in range(n_out):
            for i in range(n_in):
                ys[o, i] = lfilter(bn[o, i], np.concatenate([[1.0], an[o, i]]), un[i], axis=1)
        ctx.save_for_backward(b, a)
        ctx.un, ctx.ys, ctx.u_meta = un, ys, (u.dtype, u.device)
        return torch.as_tensor(np.ascontiguousarray(np.moveaxis(ys.sum(axis=1), 0, 2)), dtype=u.dtype, device=u.device)

    @staticmethod
    def backward(ctx, grad_y: torch.Tensor):
        b, a = ctx.saved_tensors
        bn, an, un, ys = _np(b), _np(a), ctx.un, ctx.ys
        g = np.ascontiguousarray(np.moveaxis(_np(grad_y), 2, 0))  # (n_out, B, T)
        n_out, n_in = bn.shape[:2]
        gun = np.zeros_like(un) if ctx.needs_input_grad[0] else None
        gb, ga = np.zeros_like(bn), np.zeros_like(an)
        for o in range(n_out):
            for i in range(n_in):
                gb[o, i], ga[o, i] = _pair_backward(
                    g[o], un[i], ys[o, i], bn[o, i], an[o, i], None if gun is None else gun[i]
                )
        dtype, device = ctx.u_meta
        gu = (
            None
            if gun is None
            else torch.as_tensor(np.ascontiguousarray(np.moveaxis(gun, 0, 2)), dtype=dtype, device=device)
        )
        return (
            gu,
            torch.as_tensor(gb, dtype=b.dtype, device=b.device),
            torch.as_tensor(ga, dtype=a.dtype, device=a.device),
        )


def filter_np(u: np.ndarray, b: np.ndarray, a: np.ndarray, nk: int = 0) -> np.ndarray:
    """The MIMO-by-channel filtering of :class:`LinearDynamic` in numpy: ``u`` (B, T, n_in), ``b`` (n_out, n_in, nb),
    ``a`` (n_out, n_in, na) → ``y`` (B, T, n_out), each output the sum over inputs of its pair's filter."""
    u = np.asarray(u, dtype=np.float64)
    if nk:
        u = np.concatenate([np.zeros((u.shape[0], nk, u.shape[2])), u[:, : u.shape[1] - nk]], axis=1)
    n_out, n_in = b.shape[:2]
    y = np.zeros((u.shape[0], u.shape[1], n_out))
    for o in range(n_out):
        for i in range(n_in):
            y[:, :, o] += lfilter(b[o, i], np.concatenate([[1.0], a[o, i]]), u[:, :, i], axis=1)
    return y


class LinearDynamic(torch.nn.Module):
    """MIMO linear dynamical layer, one SISO transfer function per (output, input) pair:
    ``y_o(t) = Σ_i q^{-nk} B_oi(q)/A_oi(q) u_i(t)`` for ``u`` (B, T, n_in) → ``y`` (B, T, n_out), from rest.

    Initialisation: denominators at zero (all poles at the origin, a stable start: an FIR filter) plus a small
    perturbation, numerators uniform in ±1/sqrt(n_in · nb) (a unit-size response summed over the inputs).
    """

    def __init__(
        self,
        n_in: int,
        n_out: int,
        nb: int,
        na: int,
        nk: int = 0,
        generator: torch.Generator | None = None,
        dtype: torch.dtype = torch.float64,
    ):
        super().__init__()
        self.n_in, self.n_out, self.nb, self.na, self.nk = int(n_in), int(n_out), int(nb), int(na), int(nk)
        gen = generator or torch.Generator().manual_seed(0)
        lim = 1.0 / np.sqrt(self.n_in * self.nb)
        self.b = torch.nn.Parameter(
            ((torch.rand(n_out, n_in, nb, generator=gen, dtype=torch.float64) * 2 - 1) * lim).to(dtype)
        )
        self.a = torch.nn.Parameter((torch.randn(n_out, n_in, na, generator=gen, dtype=torch.float64) * 0.01).to(dtype))

    def forward(self, u: torch.Tensor) -> torch.Tensor:
        if self.nk:
            u = torch.nn.functional.pad(u, (0, 0, self.nk, 0))[:, : u.shape[1]]
        return MIMOFilter.apply(u, self.b, self.a)

    def numpy_weights(self) -> dict[str, np.ndarray]:
        return {"b": _np(self.b).copy(), "a": _np(self.a).copy()}
