"""Subspace identification of MIMO state-space models, PO-MOESP with a memory-bounded QR (registry id ``n4sid``).

Model: x(t+1) = A x(t) + B u(t), y(t) = C x(t) + D u(t) + v(t), an output-error state-space model (``predict``
simulates it: one-step and free-run predictions coincide).

Algorithm (past-output MOESP: Verhaegen, Automatica 30(1), 1994; Verhaegen & Verdult, *Filtering and System
Identification*, 2007, §9.6): the LQ factorisation of [U_f; Z_p; Y_f] (future inputs, past inputs and outputs,
future outputs; i block rows) gives the extended observability matrix Γ_i from the column space of L32; the
order from its singular values (:func:`choose_order`, the last step by a factor ≥ 2; one candidate of
:func:`sysid.linear.order.select_n4sid_order` when ``nx`` is not given); C as Γ_i's first block row, A from its
shift invariance. B and D by least squares on Γ⊥ᵀ L31 L11⁻¹ = Γ⊥ᵀ H_i (``focus="subspace"``), or, by default
(``focus="simulation"``, as MATLAB's n4sid), poles outside the unit circle reflected (``reflected_poles_``) and
B, D by the linear least squares of the simulation error given A and C (modal regressors u_b/(q − λ_a)).

Memory: the Hankel matrix is never formed; R (L = Rᵀ) is accumulated by QR of [R; chunk] over chunks of
``chunk`` rows (Golub & Van Loan, *Matrix Computations*, §6.5): O(chunk · 2i(m+l) + (2i(m+l))²) whatever N.

Uncertainty: ``segments`` consecutive parts with their own R factors; the delete-one jackknife (Efron &
Tibshirani 1993, §11.2) re-estimates the model without each part (a QR of the others' R factors) and its spread
gives the std of the poles, of the frequency response, and a band on the simulated output.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit
from numpy.lib.stride_tricks import sliding_window_view
from scipy.optimize import linear_sum_assignment

from sysid.base import Identifier, as_record_list, check_prediction, check_records, stop_at_divergence
from sysid.data.record import Record
from sysid.errors import ConfigError

__all__ = ["N4SID", "ss_simulate", "choose_order"]

DIVERGENCE_FACTOR = 1e3
ORDER_GAP = 2.0


@njit(cache=True)
def _ss_loop(A, B, C, D, u, x0):
    N = u.shape[0]
    n = A.shape[0]
    y = np.empty((N, C.shape[0]))
    x = x0.copy()
    for t in range(N):
        y[t] = C @ x + D @ u[t]
        xn = A @ x + B @ u[t]
        for k in range(n):
            x[k] = xn[k]
    return y


@njit(cache=True)
def _modal_filter(u, lam):
    """w_a(t) = Σ_{k<t} λ_a^{t−1−k} u(k), i.e. u/(q − λ_a), for every λ_a: (N, len(lam)) complex."""
    N = u.shape[0]
    q = lam.shape[0]
    w = np.zeros((N, q), dtype=np.complex128)
    for a in range(q):
        acc = 0.0 + 0.0j
        for t in range(N):
            w[t, a] = acc
            acc = lam[a] * acc + u[t]
    return w


def ss_simulate(A, B, C, D, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """y(t) of x(t+1) = A x + B u, y = C x + D u from x(0) = x0 (zeros): (N, l). Compiled loop."""
    A, B, C, D = (np.ascontiguousarray(np.asarray(M, float)) for M in (A, B, C, D))
    u = np.ascontiguousarray(np.asarray(u, float).reshape(len(u), -1))
    x0 = np.zeros(A.shape[0]) if x0 is None else np.asarray(x0, float)
    return _ss_loop(A, B, C, D, u, x0)


def choose_order(s: np.ndarray, n_max: int, gap: float = ORDER_GAP) -> int:
    """Order from the singular values ``s`` of L32: the largest n ≤ ``n_max`` with s_n / s_{n+1} ≥ ``gap`` and
    s_n > 1e-9 s₁ (past the true order the values are a noise floor whose neighbours differ by ~10 %; a mode, even
    a weak one, stands above it by a step), else the n of the largest ratio."""
    s = np.maximum(np.asarray(s, float), 1e-300)
    k = min(int(n_max), s.size - 1)
    ratio = s[:k] / s[1 : k + 1]
    ok = (ratio >= gap) & (s[:k] > 1e-9 * s[0])
    return int(np.flatnonzero(ok)[-1]) + 1 if ok.any() else int(np.argmax(ratio)) + 1


def _hankel_rows(u: np.ndarray, y: np.ndarray, i: int, j0: int, j1: int) -> np.ndarray:
    """Rows j0..j1−1 of the transposed block-Hankel matrix [U_f | U_p | Y_p | Y_f] (time-ordered block rows)."""
    m, l = u.shape[1], y.shape[1]
    W = sliding_window_view(u[j0 : j1 + 2 * i - 1], 2 * i, axis=0).transpose(0, 2, 1).reshape(j1 - j0, 2 * i * m)
    V = sliding_window_view(y[j0 : j1 + 2 * i - 1], 2 * i, axis=0).transpose(0, 2, 1).reshape(j1 - j0, 2 * i * l)
    return np.hstack([W[:, i * m :], W[:, : i * m], V[:, : i * l], V[:, i * l :]])


def _qr_r(M: np.ndarray) -> np.ndarray:
    # numpy's stubs type every mode as QRResult; mode="r" returns the array R alone
    return np.linalg.qr(M, mode="r")  # type: ignore[return-value]


def _bd_grams(A, C, us, ys, K: int, chunk: int):
    """Per-segment normal equations of the output-error least squares of (B, D) given (A, C) (module docstring,
    "focus simulation"): y(t) = Σ_{a,b} (CV)_a B̃_ab w_ab(t) + D u(t), with A = V Λ V⁻¹, B̃ = V⁻¹ B and the modal
    regressors w_ab = u_b / (q − λ_a) (a complex first-order filter; a conjugate pair gives two real columns
    2 Re(·) and −2 Im(·)). Returns (grams [(G_s, g_s)], unpack(β) -> (B, D)) or None when A is not
    diagonalisable in a well-conditioned basis."""
    lam, V = np.linalg.eig(A)
    if not np.all(np.isfinite(lam)) or np.linalg.cond(V) > 1e10:
        return None
    n, l, m = A.shape[0], C.shape[0], us[0].shape[1]
    upper = [a for a in range(n) if lam[a].imag > 0 or lam[a].imag == 0]
    real = {a: lam[a].imag == 0 for a in upper}
    CV = C @ V
    p = sum(1 if real[a] else 2 for a in upper) * m + l * m
    total = sum(len(u) for u in us)
    bounds = np.linspace(0, total, K + 1).round().astype(int)
    grams = [(np.zeros((p, p)), np.zeros(p)) for _ in range(K)]
    g0 = 0
    for u, y in zip(us, ys):
        W = {}
        for b in range(m):
            wb = _modal_filter(np.ascontiguousarray(u[:, b], dtype=float), np.ascontiguousarray(lam[upper]))
            for j, a in enumerate(upper):
                W[(a, b)] = wb[:, j]
        for s in range(K):
            lo, hi = max(bounds[s], g0) - g0, min(bounds[s + 1], g0 + len(u)) - g0
            for t0 in range(lo, hi, chunk):
                t1 = min(t0 + chunk, hi)
                cols = []
                for b in range(m):
                    for a in upper:
                        cw = W[(a, b)][t0:t1, None] * CV[None, :, a]
                        cols.append(cw.real if real[a] else 2.0 * cw.real)
                        if not real[a]:
                            cols.append(-2.0 * cw.imag)
                for b in range(m):
                    for o in range(l):
                        z = np.zeros((t1 - t0, l))
                        z[:, o] = u[t0:t1, b]
                        cols.append(z)
                Phi = np.stack(cols, axis=-1).reshape(-1, p)
                G, g = grams[s]
                G += Phi.T @ Phi
                g += Phi.T @ y[t0:t1].reshape(-1)
        g0 += len(u)

    def unpack(beta):
        Bt = np.zeros((n, m), complex)
        j = 0
        for b in range(m):
            for a in upper:
                if real[a]:
                    Bt[a, b] = beta[j]
                    j += 1
                else:
                    Bt[a, b] = beta[j] + 1j * beta[j + 1]
                    partner = int(np.argmin(np.abs(lam - np.conj(lam[a])) + (np.arange(n) == a) * 1e300))
                    Bt[partner, b] = beta[j] - 1j * beta[j + 1]
                    j += 2
        D = beta[j:].reshape(m, l).T
        return np.real(V @ Bt), D

    return grams, unpack


def _stable(A: np.ndarray) -> tuple[np.ndarray, int]:
    """A with every eigenvalue |λ| > 1 reflected to 1/λ̄ (same eigenvectors; conjugate pairs stay pairs), and the
    number reflected. A simulation model must be stable; the subspace estimate of a non-linear or under-modelled
    system can have a pole just outside the circle."""
    lam, V = np.linalg.eig(A)
    bad = np.abs(lam) > 1.0
    if not bad.any():
        return A, 0
    if np.linalg.cond(V) > 1e10:
        return A, 0
    lam = np.where(bad, lam / np.abs(lam) ** 2, lam)
    return np.real(V @ np.diag(lam) @ np.linalg.inv(V)), int(bad.sum())


def _solve(G, g):
    try:
        return np.linalg.solve(G, g)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(G, g, rcond=None)[0]


class N4SID(Identifier):
    """Subspace (PO-MOESP) state-space identifier, MIMO (module docstring).

    Parameters
    ----------
    nx : state dimension; ``None`` = chosen by hold-out free-run error over the orders up to ``max_order`` and the
        singular-value choice (:func:`sysid.linear.order.select_n4sid_order`; reported as ``nx_`` / ``chosen_orders_``,
        the table in ``order_table_``, the search in ``order_search_``).
    max_order : largest order considered when ``nx`` is None.
    block_rows : i (past and future horizon, samples); ``None`` = max(ceil((n_max + 1)/l) + 1, 10).
    segments : parts of the data for the jackknife uncertainty (≥ 2; more parts = finer std, same cost order).
    chunk : Hankel rows per QR update (memory ≈ chunk · 2i(m+l) · 8 bytes).
    focus : ``"simulation"`` (B, D by output-error least squares given A, C: the best simulation of the data for
        those poles) or ``"subspace"`` (B, D from the L factors alone, the Toeplitz formula).
    """

    name = "n4sid"

    def __init__(
        self,
        nx: Any = None,
        max_order: int = 20,
        block_rows: Any = None,
        segments: int = 20,
        chunk: int = 20_000,
        focus: str = "simulation",
    ):
        self.nx = nx
        self.focus = focus
        self.max_order = max_order
        self.block_rows = block_rows
        self.segments = segments
        self.chunk = chunk

    # ------------------------------------------------------------------ fitting
    def _r_factors(self, us, ys, i: int, K: int) -> list[np.ndarray]:
        cols = [len(u) - 2 * i + 1 for u in us]
        total = sum(cols)
        bounds = np.linspace(0, total, K + 1).round().astype(int)
        width = 2 * i * (us[0].shape[1] + ys[0].shape[1])
        Rs: list[np.ndarray | None] = [None] * K
        g0 = 0  # global column index of the record's first column
        for u, y, J in zip(us, ys, cols):
            for s in range(K):
                a, b = max(bounds[s], g0) - g0, min(bounds[s + 1], g0 + J) - g0
                for c0 in range(a, b, int(self.chunk)):
                    c1 = min(c0 + int(self.chunk), b)
                    H = _hankel_rows(u, y, i, c0, c1)
                    prev = Rs[s]
                    Rs[s] = _qr_r(H if prev is None else np.vstack([prev, H]))
            g0 += J
        return [np.zeros((0, width)) if R is None else R for R in Rs]

    @staticmethod
    def _blocks(R: np.ndarray, i: int, m: int, l: int):
        L = R.T
        w = L.shape[0]
        if R.shape[0] < w:  # fewer rows than columns: pad the triangle
            L = np.hstack([L, np.zeros((w, w - L.shape[1]))])
        a, b = i * m, i * m + i * (m + l)
        return L[:a, :a], L[b:, :a], L[b:, a:b]

    def _estimate(self, R: np.ndarray, i: int, m: int, l: int, n: int | None, n_max: int):
        L11, L31, L32 = self._blocks(R, i, m, l)
        U, s, _ = np.linalg.svd(L32, full_matrices=True)
        if n is None:
            n = choose_order(s, n_max)
        G = U[:, :n] * np.sqrt(s[:n])
        C = G[:l]
        A = np.linalg.lstsq(G[:-l], G[l:], rcond=None)[0]
        P = U[:, n:].T  # Γ⊥ᵀ
        M = P @ L31 @ np.linalg.pinv(L11)
        rows_K, rows_M = [], []
        for c in range(i):
            Lc = P[:, c * l : (c + 1) * l]
            if c < i - 1:
                right = P[:, (c + 1) * l :] @ G[: (i - c - 1) * l]
            else:
                right = np.zeros((P.shape[0], n))
            rows_K.append(np.hstack([Lc, right]))
            rows_M.append(M[:, c * m : (c + 1) * m])
        DB = np.linalg.lstsq(np.vstack(rows_K), np.vstack(rows_M), rcond=None)[0]
        return A, DB[l:], C, DB[:l], s, n

    def _bd_simulation(self, A, C, us, ys, K, B0, D0, leave_out: int | None = None):
        """(B, D) by output-error least squares given (A, C) on every segment but ``leave_out``; falls back on the
        subspace (Toeplitz) estimate (B0, D0) when A has no well-conditioned eigenbasis."""
        res = _bd_grams(A, C, us, ys, K, int(self.chunk))
        if res is None:
            return B0, D0
        grams, unpack = res
        keep = [gr for s, gr in enumerate(grams) if s != leave_out]
        G = sum(gr[0] for gr in keep)
        g = sum(gr[1] for gr in keep)
        return unpack(_solve(G, g))

    def fit(self, data: Record | Sequence[Record]) -> N4SID:
        records = as_record_list(data)
        m, l = records[0].n_inputs, records[0].n_outputs
        n_fixed = (
            None
            if self.nx is None or (isinstance(self.nx, str) and self.nx.lower() in ("none", "auto"))
            else int(self.nx)
        )
        if n_fixed is not None and n_fixed < 1:
            raise ConfigError(f"n4sid: nx must be >= 1, got {self.nx!r}")
        n_max = n_fixed if n_fixed is not None else int(self.max_order)
        if n_max < 1:
            raise ConfigError(f"n4sid: max_order must be >= 1, got {self.max_order!r}")
        i = int(self.block_rows) if self.block_rows is not None else max(math.ceil((n_max + 1) / l) + 1, 10)
        if i * l <= n_max:
            raise ConfigError(f"n4sid: block_rows={i} too small for order {n_max} with {l} outputs (need i·l > n)")
        K = int(self.segments)
        if K < 2:
            raise ConfigError(f"n4sid: segments must be >= 2, got {self.segments!r}")
        if self.focus not in ("simulation", "subspace"):
            raise ConfigError(f"n4sid: focus must be 'simulation' or 'subspace', got {self.focus!r}")
        if int(self.chunk) < 1:
            raise ConfigError(f"n4sid: chunk must be >= 1, got {self.chunk!r}")
        width = 2 * i * (m + l)
        check_records(records, 2 * i, width * 2, self.name)
        us = [r.u.reshape(len(r), -1).astype(float) for r in records]
        ys = [r.output.reshape(len(r), -1).astype(float) for r in records]
        su = np.sqrt(np.mean(np.vstack(us) ** 2, axis=0))
        sy = np.sqrt(np.mean(np.vstack(ys) ** 2, axis=0))
        Rs = self._r_factors([u / su for u in us], [y / sy for y in ys], i, K)
        R = _qr_r(np.vstack(Rs))
        n_use = n_fixed
        self.order_table_, self.order_search_ = None, None
        # hold-out free-run search (sysid.linear.order), the singular-value choice among the candidates
        if n_fixed is None:
            from sysid.linear.order import select_n4sid_order

            n_sv = self._estimate(R, i, m, l, None, n_max)[5]
            n_use, self.order_table_, self.order_search_ = select_n4sid_order(
                records, {"block_rows": i, "focus": self.focus, "chunk": self.chunk}, n_max, extra=[n_sv]
            )
            self.order_search_["singular_value_choice"] = int(n_sv)
        A, B, C, D, s, n = self._estimate(R, i, m, l, n_use, n_max)
        un, yn = [u / su for u in us], [y / sy for y in ys]
        self.reflected_poles_ = 0
        if self.focus == "simulation":
            A, self.reflected_poles_ = _stable(A)
            B, D = self._bd_simulation(A, C, un, yn, K, B, D)
        J = sum(len(u) - 2 * i + 1 for u in us)
        self.singular_values_ = (s / math.sqrt(J)).tolist()
        self.nx_ = int(n)
        self.chosen_orders_ = {} if n_fixed is not None else {"nx": int(n)}
        self.block_rows_ = i
        scale = (np.diag(1 / su), np.diag(sy))
        self.A_, self.B_, self.C_, self.D_ = A, B @ scale[0], scale[1] @ C, scale[1] @ D @ scale[0]
        # delete-one jackknife over the segments (module docstring)
        reps = []
        for k in range(K):
            if Rs[k].shape[0] == 0:
                continue
            Rk = _qr_r(np.vstack([Rs[j] for j in range(K) if j != k]))
            Ak, Bk, Ck, Dk, _, _ = self._estimate(Rk, i, m, l, n, n)
            if self.focus == "simulation":
                Ak = _stable(Ak)[0]
                Bk, Dk = self._bd_simulation(Ak, Ck, un, yn, K, Bk, Dk, leave_out=k)
            reps.append((Ak, Bk @ scale[0], scale[1] @ Ck, scale[1] @ Dk @ scale[0]))
        self.replicates_ = reps
        self.n_inputs_, self.n_outputs_ = m, l
        self.y_bound_ = DIVERGENCE_FACTOR * max(max(float(np.max(np.abs(y))) for y in ys), 1e-300)
        self._set_common()
        return self

    def _set_common(self) -> None:
        n, l = self.nx_, self.n_outputs_
        self.max_lag_ = int(2 * math.ceil(n / l))
        self.n_parameters_ = int(n * (n + self.n_inputs_ + l) + l * self.n_inputs_)
        self.diverged_at_ = None

    # ------------------------------------------------------------------ prediction
    def _check_fitted(self) -> None:
        if not hasattr(self, "A_"):
            raise ConfigError("n4sid: model is not fitted (call fit first)")

    def _simulate(self, u: np.ndarray, y: np.ndarray | None, A=None, B=None, C=None, D=None) -> np.ndarray:
        """Simulation with x(0) fitted by least squares to the first max_lag_ samples of y (if given)."""
        A, B, C, D = (
            self.A_ if A is None else A,
            self.B_ if B is None else B,
            self.C_ if C is None else C,
            self.D_ if D is None else D,
        )
        y0 = ss_simulate(A, B, C, D, u)
        L = min(self.max_lag_, len(u))
        if y is None or L == 0:
            return y0
        O = np.empty((L * C.shape[0], A.shape[0]))
        M = C.copy()
        for t in range(L):
            O[t * C.shape[0] : (t + 1) * C.shape[0]] = M
            M = M @ A
        x0 = np.linalg.lstsq(O, (y[:L] - y0[:L]).reshape(-1), rcond=None)[0]
        return ss_simulate(A, B, C, D, u, x0)

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """Simulated output for every ``horizon`` (no noise model: one-step = k-step = free run)."""
        self._check_fitted()
        check_prediction(self, record, horizon)
        u = record.u.reshape(len(record), -1)
        y = record.output.reshape(len(record), -1)
        yhat = self._simulate(u, y)
        L = min(self.max_lag_, len(y))
        yhat[:L] = y[:L]
        return stop_at_divergence(self, yhat, "simulation").reshape(record.output.shape)

    # ------------------------------------------------------------------ uncertainty and reporting
    def _jack_std(self, est: np.ndarray, reps: list[np.ndarray]) -> np.ndarray:
        K = len(reps)
        if K < 2:
            return np.full(est.shape, np.nan)
        R = np.stack(reps)
        return np.sqrt((K - 1) / K * np.sum(np.abs(R - R.mean(axis=0)) ** 2, axis=0))

    def poles(self) -> list[dict[str, float | None]]:
        """Eigenvalues of A with their jackknife complex std (replicate poles matched to these ones)."""
        self._check_fitted()
        p = np.linalg.eigvals(self.A_)
        reps = []
        for Ak, *_ in self.replicates_:
            q = np.linalg.eigvals(Ak)
            r, c = linear_sum_assignment(np.abs(p[:, None] - q[None, :]))
            out = np.empty_like(p)
            out[r] = q[c]
            reps.append(out)
        std = self._jack_std(p, reps)
        order = np.lexsort((-p.imag, -np.abs(p)))
        return [
            {
                "re": float(p[j].real),
                "im": float(p[j].imag),
                "abs": float(abs(p[j])),
                "std": None if not np.isfinite(std[j]) else float(std[j]),
            }
            for j in order
        ]

    @staticmethod
    def _freq(A, B, C, D, z: np.ndarray) -> np.ndarray:
        n = A.shape[0]
        return np.stack([C @ np.linalg.solve(zz * np.eye(n) - A, B) + D for zz in z])

    def frequency_response(self, f_hz: np.ndarray, fs: float) -> dict[str, np.ndarray]:
        """G(e^{iωT}) (shape (F, l, m)) at ``f_hz`` [Hz], sampling rate ``fs`` [Hz], and its jackknife std."""
        self._check_fitted()
        z = np.exp(2j * np.pi * np.asarray(f_hz, float) / fs)
        G = self._freq(self.A_, self.B_, self.C_, self.D_, z)
        std = self._jack_std(G, [self._freq(*rep, z) for rep in self.replicates_])
        return {"f_hz": np.asarray(f_hz, float), "G": G, "std": std}

    def simulation_band(self, record: Record, n_draws: int = 0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Simulated output and its jackknife std per sample (``n_draws``/``seed`` unused: kept for symmetry with
        the polynomial models' Monte-Carlo band)."""
        self._check_fitted()
        u = record.u.reshape(len(record), -1)
        y = record.output.reshape(len(record), -1)
        base = self._simulate(u, y)
        reps = []
        for rep in self.replicates_:
            with np.errstate(all="ignore"):
                yk = self._simulate(u, y, *rep)
            if np.isfinite(yk).all():
                reps.append(yk)
        return base.reshape(record.output.shape), self._jack_std(base, reps).reshape(record.output.shape)

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "A_"):
            d.update(
                nx=self.nx_,
                chosen_orders=self.chosen_orders_,
                block_rows=self.block_rows_,
                reflected_poles=self.reflected_poles_,
                singular_values=self.singular_values_[: 2 * int(self.max_order) + 2],
                poles=self.poles(),
                state_space={k: getattr(self, k + "_").tolist() for k in "ABCD"},
                max_lag=self.max_lag_,
                terms=[],
            )
            if getattr(self, "order_table_", None):
                d.update(order_selection=self.order_table_, order_search=self.order_search_)
        return d

    def summary(self) -> str:
        sv = ", ".join(f"{v:.3g}" for v in self.singular_values_[: min(len(self.singular_values_), self.nx_ + 4)])
        how = "chosen on the hold-out" if self.chosen_orders_ else "given"
        lines = [f"n4sid: nx = {self.nx_} ({how}; block rows {self.block_rows_}); singular values {sv} ..."]
        for p in self.poles():
            sd = "" if p["std"] is None else f" ± {p['std']:.2g}"
            lines.append(f"  pole {p['re']: .5f}{p['im']:+.5f}j  |p| = {p['abs']:.5f}{sd}")
        return "\n".join(lines)

    # ------------------------------------------------------------------ persistence
    def _state(self) -> dict[str, Any]:
        return {
            "A": self.A_.tolist(),
            "B": self.B_.tolist(),
            "C": self.C_.tolist(),
            "D": self.D_.tolist(),
            "replicates": [[M.tolist() for M in rep] for rep in self.replicates_],
            "singular_values": self.singular_values_,
            "chosen": self.chosen_orders_,
            "block_rows": self.block_rows_,
            "y_bound": self.y_bound_,
            "reflected_poles": self.reflected_poles_,
        }

    def _load_state(self, state: dict[str, Any]) -> None:
        self.A_, self.B_, self.C_, self.D_ = (np.asarray(state[k], float) for k in "ABCD")
        reps = [[np.asarray(M, float) for M in rep] for rep in state["replicates"]]
        self.replicates_ = [(A, B, C, D) for A, B, C, D in reps]
        self.singular_values_ = list(state["singular_values"])
        self.chosen_orders_ = dict(state["chosen"])
        self.block_rows_ = int(state["block_rows"])
        self.y_bound_ = float(state["y_bound"])
        self.reflected_poles_ = int(state.get("reflected_poles", 0))
        self.nx_ = self.A_.shape[0]
        self.n_outputs_, self.n_inputs_ = self.D_.shape
        self._set_common()
