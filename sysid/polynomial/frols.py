"""Candidate polynomial terms and Forward Regression Orthogonal Least Squares (dissertation §2.6, eq. 2-7 … 2-24).

Regressors (eq. 2-8) are lagged signals ``y_o(k−j)`` (j = 1..n_y), ``u_i(k−j)`` (j = n_k .. n_k+n_u−1) and
``e_o(k−j)`` (j = 1..n_e). Candidate terms are all products of at most ``degree`` regressors with
non-decreasing indices (eq. 2-23/2-24), the constant included: M = (n+l)!/(n! l!).

**FROLS from a Gram matrix.** The orthogonalisation that FROLS performs on the candidate columns (eq. 2-18,
2-19) needs only inner products, so one pass over the data accumulates the Gram matrix ``G = [P Y]ᵀ[P Y]`` in
chunks of rows (never all N × M candidate columns at once). Selecting a term p is then the Schur-complement
(Gram–Schmidt) update ``A ← A − A[:,p] A[p,:] / A[p,p]``: afterwards ``A[j,j] = ‖w_j‖²`` and ``A[j,y] = w_jᵀy``
for every remaining candidate j orthogonalised against the selected ones, so ERR_j = (w_jᵀy)² / (‖w_j‖² yᵀy)
(eq. 2-20), and ``A[y,y]`` is the residual sum of squares of the least-squares model on the selected terms.
Every model size is therefore scored in the same pass (incremental order selection): stop when
1 − ΣERR < ρ_p (eq. 2-21) or take the size minimising AIC, BIC, FPE or LILC. Nothing divides by a column's
first sample, so a column that starts with exact zeros (data recorded from rest) is harmless; a column that is
(numerically) a combination of already selected ones has ‖w_j‖² ≈ 0 and is skipped.

The final parameters are least squares on the selected terms, computed by a chunked QR (TSQR) in a second pass
over only the selected columns, with standard errors σ̂²(RᵀR)⁻¹.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from itertools import combinations_with_replacement

import numpy as np
from numba import njit
from scipy.linalg.blas import dsyrk as _dsyrk

from sysid._blas import blas_threads
from sysid.errors import ConfigError, DataError

__all__ = [
    "make_regressors",
    "candidate_terms",
    "term_name",
    "Structure",
    "gram_matrix",
    "frols",
    "FrolsResult",
    "least_squares",
    "CRITERIA",
]

CRITERIA = ("err", "aic", "bic", "fpe", "lilc")
DEFAULT_CHUNK = 16384
# Relative size below which an orthogonalised candidate is treated as linearly dependent on the selected terms
# (‖w_j‖² / ‖p_j‖²). The Gram update loses ~1e-16·cond² so this is safely above round-off.
DEPENDENT_TOL = 1e-10
# Least squares refuses a term whose column, orthogonalised against the terms before it, keeps less than this
# fraction of its own norm (|R_jj| / ‖R[:, j]‖, the sine of its angle to their span): scale-invariant.
LS_DEPENDENT_TOL = 1e-12
# Residual energy fraction 1 − ΣERR below which the fit is exact to round-off: no further term is added.
EXACT_FIT_TOL = 1e-11
# Most candidate terms: the Gram matrix is candidates² × 8 B (20 000 candidates: 3.2 GB).
MAX_CANDIDATES = 20_000


# ---------------------------------------------------------------------------------------------------- structure
def make_regressors(ny: int, nu: int, ne: int = 0, nk: int = 1, n_outputs: int = 1, n_inputs: int = 1):
    """Regressors of eq. 2-8 as ``(kind, channel, lag)``: y lags, then u lags, then e lags."""
    for name, v in (("ny", ny), ("nu", nu), ("ne", ne), ("nk", nk)):
        if int(v) != v or v < 0:
            raise ConfigError(f"{name} must be a non-negative integer, got {v}")
    count = n_outputs * (ny + ne) + n_inputs * nu
    if count > MAX_CANDIDATES:  # checked before building the list (ny=1e8 would take minutes to refuse)
        raise ConfigError(
            f"ny={ny}, nu={nu}, ne={ne} give {count:.4g} regressors (limit {MAX_CANDIDATES} candidate"
            " terms); lower the lags"
        )
    regs = []
    for o in range(n_outputs):
        regs += [("y", o, j) for j in range(1, ny + 1)]
    for i in range(n_inputs):
        regs += [("u", i, j) for j in range(nk, nk + nu)]
    for o in range(n_outputs):
        regs += [("e", o, j) for j in range(1, ne + 1)]
    return regs


def candidate_terms(
    n_regressors: int, degree: int, constant: bool = True, nonlinear_of: Sequence[int] | None = None
) -> list[tuple[int, ...]]:
    """All products of 1..degree regressors (indices non-decreasing, eq. 2-24), plus the constant ``()``; with
    ``nonlinear_of``, the products of two or more factors are of those regressors only (every regressor still
    enters linearly)."""
    if int(degree) != degree or degree < 1:
        raise ConfigError(f"degree must be an integer >= 1, got {degree}")
    pool = sorted(range(n_regressors) if nonlinear_of is None else set(nonlinear_of))
    k = len(pool)
    count = n_regressors + math.comb(k + int(degree), int(degree)) - 1 - k + bool(constant)
    if count > MAX_CANDIDATES:
        raise ConfigError(
            f"degree {degree} over {n_regressors} regressors gives {count:.4g} candidate terms (limit "
            f"{MAX_CANDIDATES}: the Gram matrix needs {count * count * 8 / 1e9:.3g} GB); lower the degree or the lags"
        )
    terms: list[tuple[int, ...]] = [()] if constant else []
    terms += [(r,) for r in range(n_regressors)]
    for d in range(2, degree + 1):
        terms += list(combinations_with_replacement(pool, d))
    return terms


def _signal_name(kind: str, ch: int, n_ch: int) -> str:
    return kind if n_ch == 1 else f"{kind}{ch + 1}"


def term_name(term: Sequence[int], regressors, n_outputs: int = 1, n_inputs: int = 1) -> str:
    """Readable term, e.g. ``y(k-1)*u(k-2)``, ``y(k-1)^2``, ``1`` for the constant."""
    if len(term) == 0:
        return "1"
    parts: list[str] = []
    counts: dict[int, int] = {}
    for r in term:
        counts[r] = counts.get(r, 0) + 1
    for r, c in counts.items():
        kind, ch, lag = regressors[r]
        n_ch = n_inputs if kind == "u" else n_outputs
        s = f"{_signal_name(kind, ch, n_ch)}(k-{lag})" if lag else f"{_signal_name(kind, ch, n_ch)}(k)"
        parts.append(s if c == 1 else f"{s}^{c}")
    return "*".join(parts)


@dataclass
class Structure:
    """Regressors and candidate terms of a polynomial model over records with n_inputs / n_outputs channels."""

    regressors: list
    terms: list
    n_outputs: int = 1
    n_inputs: int = 1

    @property
    def max_lag(self) -> int:
        return max([lag for _, _, lag in self.regressors] + [0])

    @property
    def has_e(self) -> bool:
        return any(k == "e" for k, _, _ in self.regressors)

    def names(self, terms=None) -> list[str]:
        return [
            term_name(t, self.regressors, self.n_outputs, self.n_inputs)
            for t in (self.terms if terms is None else terms)
        ]

    def column_of(self, r: int) -> int:
        """Column of regressor r in the signal matrix [y | u | e] of :mod:`sysid.polynomial.simulate`."""
        kind, ch, _ = self.regressors[r]
        return {"y": 0, "u": self.n_outputs, "e": self.n_outputs + self.n_inputs}[kind] + ch

    def is_noise(self, term) -> bool:
        return any(self.regressors[r][0] == "e" for r in term)


# ---------------------------------------------------------------------------------------------------- data pass
def _as2d(a: np.ndarray) -> np.ndarray:
    return a.reshape(a.shape[0], -1)


def lagged_chunks(
    records, structure: Structure, e_list=None, chunk: int = DEFAULT_CHUNK
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield ``(X, Y)``: lagged regressor values (rows, n_regressors) and outputs (rows, n_outputs) in chunks.

    Rows are the samples t ≥ max_lag of each record; no row mixes two records.
    """
    L = structure.max_lag
    nr = len(structure.regressors)
    for idx, rec in enumerate(records):
        u = _as2d(rec.u)
        y = _as2d(rec.y)
        e = None if e_list is None else _as2d(e_list[idx])
        sig = {"y": y, "u": u, "e": e}
        N = u.shape[0]
        for a in range(L, N, chunk):
            b = min(N, a + chunk)
            X = np.empty((b - a, nr))
            for r, (kind, ch, lag) in enumerate(structure.regressors):
                s = sig[kind]
                if s is None:
                    raise DataError("noise regressors need residuals (internal: e_list missing)")
                X[:, r] = s[a - lag : b - lag, ch]
            yield X, y[a:b]


def term_columns(X: np.ndarray, terms, out: np.ndarray | None = None) -> np.ndarray:
    """Candidate columns: out[:, j] = Π_{r in terms[j]} X[:, r] (constant → 1). Fortran-ordered."""
    n = X.shape[0]
    if out is None:
        out = np.empty((n, len(terms)), order="F")
    for j, t in enumerate(terms):
        col = out[:, j]
        if len(t) == 0:
            col.fill(1.0)
        elif len(t) == 1:
            col[:] = X[:, t[0]]
        else:
            np.multiply(X[:, t[0]], X[:, t[1]], out=col)
            for r in t[2:]:
                col *= X[:, r]
    return out


def _term_table(terms) -> np.ndarray:
    d = max([len(t) for t in terms] + [1])
    tab = -np.ones((len(terms), d), dtype=np.int64)
    for j, t in enumerate(terms):
        tab[j, : len(t)] = t
    return tab


@njit(cache=True)
def _fill_rows(Z, a, n, col, lag, tab, n_out, shift, out):
    """out[i, j] = Π_d Z[a+i−lag[r], col[r]] − shift[j] over r = tab[j, d] (constant → 1);
    out[i, M+o] = Z[a+i, o] − shift[M+o] (the outputs y_o).

    Row-major so that each sample's candidate values are contiguous (the layout the BLAS rank-k update wants).
    """
    M = tab.shape[0]
    D = tab.shape[1]
    for i in range(n):
        t = a + i
        for j in range(M):
            v = 1.0
            for d in range(D):
                r = tab[j, d]
                if r < 0:
                    break
                v *= Z[t - lag[r], col[r]]
            out[i, j] = v - shift[j]
        for o in range(n_out):
            out[i, M + o] = Z[t, o] - shift[M + o]


def _signal_matrix(rec, structure: Structure, e) -> np.ndarray:
    """[y | u | e] columns of one record (the layout of :mod:`sysid.polynomial.simulate`)."""
    N = len(rec)
    parts = [_as2d(rec.y), _as2d(rec.u)]
    if structure.has_e:
        if e is None:
            raise DataError("noise regressors need residuals (internal: e_list missing)")
        parts.append(_as2d(e))
    return np.ascontiguousarray(np.hstack(parts).reshape(N, -1), dtype=np.float64)


class GramMatrix(np.ndarray):
    """The Gram matrix ``[P Y]ᵀ[P Y]`` (an ndarray) carrying, when a constant candidate exists, ``centred``: the
    same matrix for mean-removed columns, i.e. the exact Schur complement with respect to the constant, computed
    without the cancellation that forming it from the raw matrix would suffer when signals carry large offsets;
    and ``constant_index`` (the constant's column or None)."""

    centred: np.ndarray | None = None
    constant_index: int | None = None


def gram_matrix(records, structure: Structure, terms=None, e_list=None, chunk: int = DEFAULT_CHUNK):
    """One pass: ``G = [P Y]ᵀ [P Y]`` over all records (P = candidate columns, Y = outputs) and the row count.

    Rows are built ``chunk`` at a time by a compiled loop and added with a BLAS symmetric rank-k update
    (``dsyrk``), so memory stays at chunk × (M + n_outputs) × 8 bytes whatever N is. The rows are shifted by a
    reference (the column means of the first chunk) before accumulation: S = Σ(p−m)(p−m)ᵀ, s = Σ(p−m); then
    G = S + m sᵀ + s mᵀ + N m mᵀ and the centred matrix S − s sᵀ/N keep their precision under large offsets.
    Returns ``(G, n_rows)`` with G a :class:`GramMatrix`.
    """
    terms = structure.terms if terms is None else terms
    M = len(terms)
    n_out = structure.n_outputs
    K = M + n_out
    S = np.zeros((K, K), order="F")
    tab = _term_table(terms)
    col = np.array([structure.column_of(r) for r in range(len(structure.regressors))], dtype=np.int64)
    lag = np.array([lg for _, _, lg in structure.regressors], dtype=np.int64)
    L = structure.max_lag
    buf = np.empty((max(1, int(chunk)), K))
    ssum = np.zeros(K)
    shift = None
    with blas_threads():
        n_rows = 0
        for idx, rec in enumerate(records):
            Z = _signal_matrix(rec, structure, None if e_list is None else e_list[idx])
            N = Z.shape[0]
            for a in range(L, N, chunk):
                n = min(N, a + chunk) - a
                b = buf[:n]
                if shift is None:
                    _fill_rows(Z, a, n, col, lag, tab, n_out, np.zeros(K), b)
                    shift = b.mean(axis=0)
                _fill_rows(Z, a, n, col, lag, tab, n_out, shift, b)
                # b is C-ordered (n × K): its transpose is a Fortran K × n matrix, so syrk computes bᵀb without a copy
                S2 = _dsyrk(1.0, b.T, beta=1.0, c=S, trans=0, lower=0, overwrite_c=1)
                if S2 is not S:  # pragma: no cover - f2py copied (should not happen for a Fortran-ordered S)
                    S[...] = S2
                ssum += b.sum(axis=0)
                n_rows += n
    if shift is None:
        shift = np.zeros(K)
    S = np.triu(S) + np.triu(S, 1).T
    G = S + np.outer(shift, ssum) + np.outer(ssum, shift) + n_rows * np.outer(shift, shift)
    out = np.ascontiguousarray(G).view(GramMatrix)
    const = [j for j, t in enumerate(terms) if len(t) == 0]
    out.constant_index = const[0] if const else None
    out.centred = (S - np.outer(ssum, ssum) / max(n_rows, 1)) if const else None
    return out, n_rows


# ---------------------------------------------------------------------------------------------------- FROLS
@dataclass
class FrolsResult:
    selected: list[int]  # candidate indices in order of selection
    err: list[float]  # ERR of each selected term (eq. 2-20)
    criterion_values: list[float]  # information criterion after 1, 2, ... terms (nan for criterion="err")
    n_samples: int
    ssr: list[float] = field(default_factory=list)  # residual sum of squares after each kept term
    scored: list[int] = field(default_factory=list)  # every term added in the pass (criterion_values[i] ↔ scored[:i+1])


def _info_criterion(name: str, n_theta: int, n_samples: int, e_var: float) -> float:
    """AIC, BIC, FPE, LILC: N ln σ̂² + penalty, σ̂² = SSR/N (Akaike 1974; Schwarz 1978; Hannan–Quinn LILC)."""
    if e_var <= 0:
        return -math.inf
    base = n_samples * math.log(e_var)
    if name == "aic":
        return base + 2.0 * n_theta
    if name == "bic":
        return base + n_theta * math.log(n_samples)
    if name == "fpe":
        if n_samples <= n_theta:
            return math.inf
        return base + n_samples * math.log((n_samples + n_theta) / (n_samples - n_theta))
    if name == "lilc":
        return base + 2.0 * n_theta * math.log(math.log(n_samples))
    raise ConfigError(f"unknown criterion {name!r}; valid: {', '.join(CRITERIA)}")


def frols(
    G: np.ndarray,
    n_candidates: int,
    output: int = 0,
    n_samples: int = 0,
    criterion: str = "bic",
    rho: float = 1e-4,
    max_terms: int | None = None,
    forced: Sequence[int] = (),
    allowed=None,
    continue_err: bool = False,
) -> FrolsResult:
    """FROLS term selection on a Gram matrix from :func:`gram_matrix`.

    Parameters
    ----------
    G : (M + n_outputs, M + n_outputs) Gram matrix; column ``M + output`` is the target.
    criterion : ``"err"`` — add the term of largest ERR until 1 − ΣERR < ``rho`` (eq. 2-21); with
        ``continue_err`` the rule is instead "add while the best ERR ≥ rho" (the noise-term threshold ρ_n);
        ``"aic" | "bic" | "fpe" | "lilc"`` — score every model size 1..max_terms in the same pass and keep the
        minimiser.
    forced : candidates selected first, in this order (e.g. process terms before noise terms in ELS).
    allowed : boolean mask of candidates that may be selected (default all).
    """
    criterion = str(criterion).lower()
    if criterion not in CRITERIA:
        raise ConfigError(f"unknown criterion {criterion!r}; valid: {', '.join(CRITERIA)}")
    M = n_candidates
    iy = M + output
    keep = list(range(M)) + [iy]
    centred = getattr(G, "centred", None)
    const = getattr(G, "constant_index", None)
    A = np.asarray(G)[np.ix_(keep, keep)].astype(float, copy=True)
    iy = M
    yy = float(A[iy, iy])
    if yy <= 0:
        raise DataError("output is identically zero: nothing to identify")
    diag0 = np.diag(A)[:M].copy()
    # exact-fit reference: the output's energy about its mean when a constant can absorb the mean
    exact_ref = yy if centred is None else max(float(np.asarray(centred)[M + output, M + output]), 1e-300)
    avail = np.ones(M, bool) if allowed is None else np.asarray(allowed, bool).copy()
    avail &= diag0 > 0
    max_terms = M if max_terms is None else int(min(max_terms, M))
    selected: list[int] = []
    errs: list[float] = []
    ssr: list[float] = []
    ic: list[float] = []

    def schur(j: int) -> None:
        colj = A[:, j].copy()
        A[:, :] -= np.outer(colj, colj / colj[j])

    def pivot(j: int) -> float:
        d = A[j, j]
        e = A[j, iy] ** 2 / (d * yy)
        if j == const and centred is not None:
            # Schur complement w.r.t. the constant = the centred Gram (exact); re-apply the earlier pivots on it
            A[:, :] = np.asarray(centred)[np.ix_(keep, keep)]
            for k in selected:
                schur(k)
            diag0[:] = np.where(np.arange(M) == const, diag0, np.diag(np.asarray(centred)[np.ix_(keep, keep)])[:M])
        else:
            schur(j)
        avail[j] = False
        selected.append(j)
        errs.append(float(e))
        ssr.append(max(float(A[iy, iy]), 0.0))
        ic.append(
            _info_criterion(criterion, len(selected), n_samples, ssr[-1] / n_samples)
            if criterion != "err"
            else math.nan
        )
        return e

    for j in forced:
        if A[j, j] <= DEPENDENT_TOL * max(diag0[j], 1e-300):
            raise DataError(f"forced term {j} is linearly dependent on the others (or identically zero)")
        pivot(int(j))
    n_forced = len(selected)

    while len(selected) < max_terms:
        if ssr and ssr[-1] <= EXACT_FIT_TOL * exact_ref:
            break
        d = np.diag(A)[:M]
        valid = avail & (d > DEPENDENT_TOL * diag0)
        if not valid.any():
            break
        score = np.where(valid, A[:M, iy] ** 2 / np.where(valid, d, 1.0), -1.0) / yy
        j = int(np.argmax(score))
        if criterion == "err" and continue_err and score[j] < rho:
            break
        pivot(j)
        if criterion == "err" and not continue_err and 1.0 - sum(errs) < rho:
            break

    scored = list(selected)
    if criterion != "err" and len(selected) > n_forced:
        vals = np.asarray(ic[n_forced:])
        best = n_forced + int(np.argmin(vals)) + 1
        # an exact fit (round-off residual, IC → −∞) ends the pass, so the minimiser is the exact model
        selected, errs, ssr = selected[:best], errs[:best], ssr[:best]
    return FrolsResult(selected=selected, err=errs, criterion_values=ic, n_samples=n_samples, ssr=ssr, scored=scored)


# ---------------------------------------------------------------------------------------------------- final LS
@dataclass
class LSResult:
    theta: np.ndarray
    stderr: np.ndarray
    ssr: float
    n_samples: int


def least_squares(
    records, structure: Structure, terms, output: int = 0, e_list=None, chunk: int = DEFAULT_CHUNK
) -> LSResult:
    """Least squares on the given terms by chunked QR (TSQR): θ, standard errors σ̂²(RᵀR)⁻¹ and SSR."""
    k = len(terms)
    R = np.zeros((0, k + 1))
    n_rows = 0
    buf = None
    with blas_threads():
        for X, Y in lagged_chunks(records, structure, e_list, chunk):
            n = X.shape[0]
            if buf is None or buf.shape[0] != n:
                buf = np.empty((n, k + 1), order="F")
            term_columns(X, terms, buf[:, :k])
            buf[:, k] = Y[:, output]
            R = np.linalg.qr(np.vstack([R, buf]), mode="r")  # type: ignore[assignment]  # numpy stubs: QRResult
            n_rows += n
    if n_rows <= k:
        raise DataError(f"too few samples ({n_rows} usable rows) for {k} parameters")
    if R.shape[0] < k + 1:
        R = np.vstack([R, np.zeros((k + 1 - R.shape[0], k + 1))])
    if not np.isfinite(R).all():
        raise DataError(
            "least squares on non-finite or overflowing regressors (e.g. a diverged residual recursion); "
            "no parameters estimated"
        )
    Rk = R[:k, :k]
    if k:
        # Scale-invariant rank test: |R_jj| is the norm of column j orthogonalised against the columns before it,
        # ‖R[:, j]‖ the column's own norm, so their ratio is the sine of the angle between column j and the span
        # of the others — independent of units (comparing |R_jj| with max|R_ii| refused Bouc–Wen in N and m,
        # where u³ ~ 1e6 and y³ ~ 1e-9 are perfectly independent).
        col_norm = np.linalg.norm(Rk, axis=0)
        rel = np.abs(np.diag(Rk)) / np.where(col_norm > 0, col_norm, 1.0)
        if not np.all(rel > LS_DEPENDENT_TOL):
            j = int(np.argmin(rel))
            raise DataError(
                f"the selected regressors are linearly dependent (rank-deficient least squares: term "
                f"{j + 1} of {k} is a combination of the others to {rel[j]:.1e} relative); the input may "
                "not excite the system enough"
            )
    theta = np.linalg.solve(Rk, R[:k, k]) if k else np.zeros(0)
    if not np.isfinite(theta).all():
        raise DataError("least squares gave non-finite parameters (non-finite or overflowing regressors)")
    ssr = float(R[k, k] ** 2)
    dof = max(n_rows - k, 1)
    sigma2 = ssr / dof
    if k:
        Rinv = np.linalg.solve(Rk, np.eye(k))
        cov = sigma2 * (Rinv @ Rinv.T)
        stderr = np.sqrt(np.maximum(np.diag(cov), 0.0))
    else:
        stderr = np.zeros(0)
    return LSResult(theta=theta, stderr=stderr, ssr=ssr, n_samples=n_rows)


def fitted_residuals(
    records, structure: Structure, terms_per_output, theta_per_output, e_list=None, chunk: int = DEFAULT_CHUNK
) -> list[np.ndarray]:
    """e(t) = y(t) − Σ θ p(t) per record (zeros for t < max_lag), computed with the given lagged e (ELS step)."""
    L = structure.max_lag
    out = []
    for idx, rec in enumerate(records):
        N = len(rec)
        e = np.zeros((N, structure.n_outputs))
        one = [rec]
        el = None if e_list is None else [e_list[idx]]
        row = L
        for X, Y in lagged_chunks(one, structure, el, chunk):
            n = X.shape[0]
            for o in range(structure.n_outputs):
                P = term_columns(X, terms_per_output[o])
                e[row : row + n, o] = Y[:, o] - P @ theta_per_output[o]
            row += n
        out.append(e)
    return out
