"""Uncertainty of linear models: pole and frequency-response standard deviations, simulation bands.

First-order (delta-method) propagation of a parameter covariance P (Ljung, *System Identification*, 2nd ed.,
§9.4, eq. 9.52): for a smooth function g(θ), Cov g(θ̂) ≈ (∂g/∂θ) P (∂g/∂θ)ᵀ. For a complex quantity z (a pole, a
frequency response value) the reported "std" is the standard deviation of the complex number,
σ_z = sqrt(E|ẑ − z|²) = sqrt(var Re z + var Im z).

- :func:`root_sensitivity` / :func:`poles_with_std`: roots of a monic polynomial 1 + a₁q⁻¹ + … + aₙq⁻ⁿ. With
  P(z) = zⁿ + a₁zⁿ⁻¹ + … + aₙ, implicit differentiation of P(p) = 0 gives ∂p/∂a_k = −p^{n−k} / P′(p).
- :func:`tf_response_with_std`: G(e^{iω}) = e^{−iωn_k} B(e^{iω}) / F(e^{iω}) and its std,
  ∂G/∂b_k = e^{−iω(n_k+k−1)} / F, ∂G/∂f_k = −G e^{−iωk} / F.
- :func:`monte_carlo_band`: simulated output of parameter draws θ ~ N(θ̂, P) (seeded); mean ± z·std per sample.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["root_sensitivity", "poles_with_std", "tf_response_with_std", "monte_carlo_band", "complex_std"]


def root_sensitivity(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Roots p of the monic polynomial ``a`` = [1, a₁, …, aₙ] (in q⁻¹) and ∂p_j/∂a_k, shape (n, n), complex."""
    a = np.asarray(a, dtype=float)
    n = a.size - 1
    if n < 1:
        return np.zeros(0, complex), np.zeros((0, 0), complex)
    p = np.roots(a).astype(complex)
    dP = np.polyval(np.polyder(a), p)  # P'(p) with P(z) = z^n + a1 z^(n-1) + ... + an
    k = np.arange(1, n + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        grad = -(p[:, None] ** (n - k)[None, :]) / dP[:, None]
    return p, grad


def complex_std(grad: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """σ = sqrt(var Re + var Im) of complex quantities with gradients ``grad`` (rows) w.r.t. θ of covariance cov."""
    g = np.atleast_2d(grad)
    vr = np.einsum("ij,jk,ik->i", g.real, cov, g.real)
    vi = np.einsum("ij,jk,ik->i", g.imag, cov, g.imag)
    return np.sqrt(np.maximum(vr + vi, 0.0))


def poles_with_std(a: np.ndarray, cov: np.ndarray | None) -> list[dict[str, float | None]]:
    """Poles (roots of ``a``) as ``[{"re", "im", "abs", "std"}]``, ``std`` = complex std (module docstring) from the
    covariance ``cov`` of (a₁ … aₙ); None without covariance."""
    p, grad = root_sensitivity(a)
    std = complex_std(grad, cov) if cov is not None and p.size else np.full(p.size, np.nan)
    order = np.lexsort((-p.imag, -np.abs(p)))
    return [
        {
            "re": float(p[j].real),
            "im": float(p[j].imag),
            "abs": float(abs(p[j])),
            "std": (None if not np.isfinite(std[j]) else float(std[j])),
        }
        for j in order
    ]


def tf_response_with_std(
    b: np.ndarray, f: np.ndarray, nk: int, w: np.ndarray, cov: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """G(e^{iw}) of B/F with delay nk at normalised angular frequencies ``w`` [rad/sample] and its complex std.

    ``cov`` is the covariance of (b₁ … b_nb, f₁ … f_nf) (in that order)."""
    b = np.asarray(b, float)
    f = np.asarray(f, float)
    z = np.exp(-1j * np.asarray(w, float))
    zb = z[:, None] ** (nk + np.arange(b.size))[None, :]
    zf = z[:, None] ** np.arange(f.size)[None, :]
    Bz = zb @ b
    Fz = zf @ f
    G = Bz / Fz
    if cov is None:
        return G, None
    grad = np.hstack([zb / Fz[:, None], -(G / Fz)[:, None] * zf[:, 1:]])
    return G, complex_std(grad, cov)


def monte_carlo_band(
    simulate: Callable[[np.ndarray], np.ndarray], theta: np.ndarray, cov: np.ndarray, n_draws: int = 100, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation per sample of ``simulate(θ)`` over ``n_draws`` draws θ ~ N(θ̂, cov).

    Draws whose simulation is not finite (an unstable draw) are dropped; ``simulate`` returns an array."""
    rng = np.random.default_rng(seed)
    cov = 0.5 * (cov + cov.T)
    w, V = np.linalg.eigh(cov)
    L = V * np.sqrt(np.maximum(w, 0.0))
    outs = []
    for _ in range(int(n_draws)):
        th = theta + L @ rng.standard_normal(theta.size)
        y = np.asarray(simulate(th), float)
        if np.isfinite(y).all():
            outs.append(y)
    if not outs:
        base = np.asarray(simulate(theta), float)
        return base, np.full_like(base, np.nan)
    arr = np.stack(outs)
    return arr.mean(axis=0), arr.std(axis=0, ddof=1) if len(outs) > 1 else np.zeros_like(arr[0])
