"""The blocks of a Wiener–Hammerstein model and their derivatives: G1 → static spline f → G2.

    x(t) = G1(q) u(t),   w(t) = f(x(t)),   ŷ(t) = G2(q) w(t),   G_i(q) = q^{-nk_i} B_i(q) / A_i(q)

(Schoukens & Tiels, "Identification of block-oriented nonlinear systems starting from linear approximations: a
survey", Automatica 85 (2017), §3 and §5.1; Sjöberg, Lauwers & Schoukens, "Identification of Wiener–Hammerstein
models: two algorithms based on the best split of a linear model applied to the SYSID'09 benchmark problem",
Control Engineering Practice 20 (2012) 1119-1125). The filters run in direct form (``scipy.signal.lfilter``)
from rest; f is a cubic B-spline with knots at quantiles of x, continued by its end tangents outside them.

Used by :class:`sysid.nonlinear.wiener_hammerstein.WienerHammerstein` (registry id ``wh-bla``):

- :func:`root_groups` / :func:`splits`: every way of sharing the BLA's poles and zeros between G1 and G2
  (complex pairs kept together);
- :class:`Spline`: f, its basis and its derivative;
- :func:`simulate` and :func:`jacobian`: the free run and the exact derivative of ŷ with respect to every
  parameter, by filtering (no finite differences): for G = B/A with A monic, ∂x/∂b_i = A⁻¹ u(t − nk − i) and
  ∂x/∂a_i = −A⁻¹ x(t − i); the G1 columns then pass through f′(x) and G2.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline
from scipy.signal import lfilter

__all__ = ["Filter", "Spline", "root_groups", "splits", "simulate", "jacobian", "shift"]

MAX_SPLITS = 4096  # 2^(pole groups + zero groups) above this is refused (12 real roots)


@dataclass
class Filter:
    """q^{-nk} B(q)/A(q): ``b`` = b_0 … b_m, ``a`` = 1, a_1 … a_n (dimensionless), ``nk`` delay in samples."""

    b: np.ndarray
    a: np.ndarray
    nk: int = 0

    def __call__(self, v: np.ndarray) -> np.ndarray:
        return shift(lfilter(self.b, self.a, v, axis=0), self.nk)

    def poles(self) -> np.ndarray:
        return np.roots(self.a) if len(self.a) > 1 else np.zeros(0, complex)

    def zeros(self) -> np.ndarray:
        b = np.trim_zeros(np.asarray(self.b, float), "b")
        return np.roots(b) if len(b) > 1 else np.zeros(0, complex)


def shift(v: np.ndarray, k: int) -> np.ndarray:
    """v delayed by k ≥ 0 samples, zeros in front (rows are samples)."""
    if k == 0:
        return v
    out = np.zeros_like(v)
    out[k:] = v[:-k]
    return out


def root_groups(roots: np.ndarray, tol: float = 1e-8) -> list[list[complex]]:
    """Roots grouped as they must move together: a complex root with its conjugate, a real root alone."""
    left = [complex(r) for r in roots]
    groups: list[list[complex]] = []
    while left:
        r = left.pop(0)
        if abs(r.imag) <= tol * max(1.0, abs(r)):
            groups.append([complex(r.real, 0.0)])
            continue
        j = int(np.argmin([abs(s - r.conjugate()) for s in left]))
        groups.append([r, left.pop(j)])
    return groups


def _poly(roots: list[complex]) -> np.ndarray:
    return np.real(np.poly(roots)) if roots else np.array([1.0])


def splits(zeros: np.ndarray, poles: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """Every (b1, a1, b2, a2) whose roots share the zeros and poles between G1 and G2 (gains left to the caller)."""
    zg, pg = root_groups(zeros), root_groups(poles)
    if 2 ** (len(zg) + len(pg)) > MAX_SPLITS:
        raise ValueError(
            f"{len(zg)} zero and {len(pg)} pole groups give {2 ** (len(zg) + len(pg))} splits "
            f"(at most {MAX_SPLITS}); lower the BLA's orders"
        )
    for zmask in itertools.product((True, False), repeat=len(zg)):
        z1 = [r for g, m in zip(zg, zmask) if m for r in g]
        z2 = [r for g, m in zip(zg, zmask) if not m for r in g]
        for pmask in itertools.product((True, False), repeat=len(pg)):
            p1 = [r for g, m in zip(pg, pmask) if m for r in g]
            p2 = [r for g, m in zip(pg, pmask) if not m for r in g]
            yield _poly(z1), _poly(p1), _poly(z2), _poly(p2)


class Spline:
    """Cubic B-spline f(x) = Σ_k c_k B_k(x) on knots ``inner`` (clamped ends), continued linearly outside.

    ``inner``: increasing breakpoints; the first and last bound the spline's interval [lo, hi]. Outside it f is
    the tangent at the nearer end, so f stays defined (and monotone where it was) on inputs wider than the
    estimation data's.
    """

    def __init__(self, inner: np.ndarray):
        inner = np.asarray(inner, float)
        self.inner = inner
        self.lo, self.hi = float(inner[0]), float(inner[-1])
        self.t = np.r_[[self.lo] * 3, inner, [self.hi] * 3]
        self.n = len(self.t) - 4
        eye = np.eye(self.n)
        self._slope = np.array(
            [[BSpline(self.t, eye[k], 3).derivative()(e) for k in range(self.n)] for e in (self.lo, self.hi)]
        )

    @classmethod
    def at_quantiles(cls, x: np.ndarray, knots: int, margin: float) -> Spline:
        """Knots at ``knots`` inner quantiles of x, the ends ``margin`` × RMS(x) beyond its extremes. Quantiles
        closer than 1e-6 × RMS(x) (x on a few levels, e.g. a quantised input through a short FIR) are merged, so
        such data get fewer knots."""
        s = float(np.sqrt(np.mean(x**2))) or 1.0
        inner = np.quantile(x, np.linspace(0.0, 1.0, knots + 2)[1:-1])
        inner = inner[np.r_[True, np.diff(inner) > 1e-6 * s]]
        return cls(np.r_[x.min() - margin * s, inner, x.max() + margin * s])

    def basis(self, x: np.ndarray) -> np.ndarray:
        """B_k(x), samples × n (dense), with the linear continuation outside [lo, hi]."""
        xc = np.clip(x, self.lo, self.hi)
        B = BSpline.design_matrix(xc, self.t, 3).toarray()
        below, above = np.minimum(x - self.lo, 0.0), np.maximum(x - self.hi, 0.0)
        return B + below[:, None] * self._slope[0] + above[:, None] * self._slope[1]

    def __call__(self, x: np.ndarray, c: np.ndarray) -> np.ndarray:
        xc = np.clip(x, self.lo, self.hi)
        return (
            BSpline(self.t, c, 3)(xc)
            + np.minimum(x - self.lo, 0.0) * (self._slope[0] @ c)
            + np.maximum(x - self.hi, 0.0) * (self._slope[1] @ c)
        )

    def derivative(self, x: np.ndarray, c: np.ndarray) -> np.ndarray:
        """f′(x) (the end slopes outside [lo, hi])."""
        return BSpline(self.t, c, 3).derivative()(np.clip(x, self.lo, self.hi))


def simulate(g1: Filter, f: Spline, c: np.ndarray, g2: Filter, u: np.ndarray) -> tuple[np.ndarray, ...]:
    """ŷ, x, w of the free run from rest (u: 1-D)."""
    x = g1(u)
    w = f(x, c)
    return g2(w), x, w


def jacobian(
    g1: Filter, f: Spline, c: np.ndarray, g2: Filter, u: np.ndarray, free_b1: np.ndarray, free_b2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """ŷ and ∂ŷ/∂θ for θ = (b1[free_b1], a1[1:], c, b2[free_b2], a2[1:]) (samples × parameters)."""
    x = g1(u)
    B = f.basis(x)
    w = B @ c
    yh = g2(w)
    fp = f.derivative(x, c)
    v1 = lfilter([1.0], g1.a, u)  # A1⁻¹ u
    z1 = lfilter([1.0], g1.a, x)  # A1⁻¹ x (x already carries the delay nk1)
    cols1 = [fp * shift(v1, g1.nk + i) for i in free_b1] + [-fp * shift(z1, i) for i in range(1, len(g1.a))]
    v2 = lfilter([1.0], g2.a, w)
    z2 = lfilter([1.0], g2.a, yh)
    parts = []
    if cols1:
        parts.append(g2(np.column_stack(cols1)))
    parts.append(g2(B))
    cols2 = [shift(v2, g2.nk + i) for i in free_b2] + [-shift(z2, i) for i in range(1, len(g2.a))]
    if cols2:
        parts.append(np.column_stack(cols2))
    return yh, np.hstack(parts)
