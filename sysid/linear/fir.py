"""Least-squares FIR model (registry id ``fir``): the reference a practitioner fits first.

Model (Ljung, *System Identification*, 2nd ed., §4.2, eq. 4.46: ARX with A = 1), per output o, inputs i::

    y_o(t) = Σ_i Σ_{k=0}^{nb−1} h_{o,i}(k) u_i(t − nk − k) + e_o(t)

by linear least squares over t ≥ nk + nb − 1 of each record. Free run, k-step and one-step predictions are the
same (no output feedback): it never diverges.

Normal equations without the regressor matrix: each block G_ab(i, j) = Σ_t u_a(t − i) u_b(t − j) has
cross-correlations (``scipy.signal.correlate``) as its first row and column and follows from the shift recursion
G_ab(i+1, j+1) = G_ab(i, j) + u_a(L−1−i) u_b(L−1−j) − u_a(N−1−i) u_b(N−1−j): O(N log N + (m·nb)²) work. G + λI
(λ = ``JITTER`` × mean diagonal, raised while Cholesky fails) is factored once; the leading block of its factor
serves every smaller tap count.

Tap count (``nb=None``): FIRs on a geometric grid (``GRID_RATIO``) up to ``max_order`` are fitted without the last
``HOLDOUT`` of each record and scored by the free-run NRMSE there; the smallest within ``TOLERANCE`` of the best
is kept (the rule of :mod:`sysid.linear.order`), refitted on all data; a choice on the grid's end is flagged
(``order_search["corner"]``). Ridge (``ridge=None`` with chosen taps): a band-limited input fixes the taps only in
its band, so the relative ridges of ``RIDGE_GRID`` are scored on the same hold-out and the largest within the
tolerance kept (as MATLAB's ``impulseest`` regularises by default). Given ``nb`` without ``ridge``: plain least
squares; a number ``ridge`` ≥ 0 sets λ/mean diagonal. Measurements: docs/linear-identification.md.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.linalg

from sysid.base import Identifier, as_record_list, check_prediction, check_records
from sysid.errors import ConfigError, DataError, OrderSearchWarning

__all__ = ["FIR", "fir_normal_equations", "holdout_fir_search", "holdout_tolerance", "tap_grid"]

HOLDOUT = 0.3
TOLERANCE = 0.01
GRID_RATIO = 1.25
GRID_START = 4
MIN_FIT_PER_TAP = 4
JITTER = 1e-10
RIDGE_GRID = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8)


def holdout_tolerance(n_holdout: int) -> float:
    """Relative NRMSE difference below which two candidates of an order search count as equal: ``TOLERANCE``, or
    the standard deviation of an NRMSE estimated from n independent residuals, 1/√(2n) (the MSE's relative std is
    √(2/n)), when that is larger — a short hold-out cannot rank candidates more finely."""
    return max(TOLERANCE, 1.0 / math.sqrt(2.0 * max(int(n_holdout), 1)))


# --------------------------------------------------------------------------------------- normal equations
def _lag_corr(x: np.ndarray, v: np.ndarray, M: int, L: int) -> np.ndarray:
    """c(j) = Σ_{t=L}^{N−1} x(t) v(t − j), j = 0 … M−1 (requires L ≥ M − 1)."""
    N = len(x)
    import scipy.signal  # on first use: importing it costs about a second

    z = scipy.signal.correlate(v[L - M + 1 : N], x[L:N], mode="valid")
    return z[::-1]


def _lag_gram(ua: np.ndarray, ub: np.ndarray, M: int, L: int) -> np.ndarray:
    """B(i, j) = Σ_{t=L}^{N−1} ua(t − i) ub(t − j), i, j < M, by the shift recursion of the module docstring."""
    N = len(ua)
    B = np.empty((M, M))
    B[0] = _lag_corr(ua, ub, M, L)
    B[:, 0] = _lag_corr(ub, ua, M, L)
    if M > 1:
        sa, ea = ua[L - 1 - np.arange(M - 1)], ua[N - 1 - np.arange(M - 1)]
        sb, eb = ub[L - 1 - np.arange(M - 1)], ub[N - 1 - np.arange(M - 1)]
        for i in range(M - 1):
            B[i + 1, 1:] = B[i, :-1] + sa[i] * sb - ea[i] * eb
    return B


def fir_normal_equations(pairs: Sequence[tuple[np.ndarray, np.ndarray]], M: int) -> tuple[np.ndarray, np.ndarray, int]:
    """G = ΦᵀΦ (m·M × m·M, lag-major) and g = ΦᵀY (m·M × outputs) of a FIR with M taps summed over ``pairs`` of
    delay-aligned (u (N × m), y (N × l)) arrays, each fitted over t ≥ M − 1; also the number of fitted rows."""
    m, n_out = pairs[0][0].shape[1], pairs[0][1].shape[1]
    G = np.zeros((m * M, m * M))
    g = np.zeros((m * M, n_out))
    rows = 0
    L = M - 1
    for u, y in pairs:
        for a in range(m):
            for b in range(a, m):
                B = _lag_gram(u[:, a], u[:, b], M, L)
                G[a::m, b::m] += B
                if b != a:
                    G[b::m, a::m] += B.T
            for o in range(n_out):
                g[a::m, o] += _lag_corr(y[:, o], u[:, a], M, L)
        rows += len(u) - L
    return G, g, rows


def _cholesky(G: np.ndarray, ridge: float = JITTER) -> np.ndarray:
    """Lower Cholesky factor of G + λI, λ = ``ridge`` × mean diagonal (module docstring: raised ×100 while the
    factorisation fails)."""
    scale = max(float(np.mean(np.diag(G))), 1e-300)
    lam = max(float(ridge), JITTER) * scale
    for _ in range(6):
        try:
            return scipy.linalg.cholesky(G + lam * np.eye(len(G)), lower=True, check_finite=False)
        except np.linalg.LinAlgError:
            lam *= 100.0
    raise DataError(
        "fir: the input's lag covariance is not positive definite (is the input constant or "
        "periodic with fewer samples per period than taps?); give fewer taps (nb)"
    )


def _solve_leading(Lc: np.ndarray, g: np.ndarray, q: int) -> np.ndarray:
    """θ of the leading q parameters: (L_q L_qᵀ) θ = g_q with L_q the leading block of the factor."""
    Lq = Lc[:q, :q]
    z = scipy.linalg.solve_triangular(Lq, g[:q], lower=True, check_finite=False)
    return scipy.linalg.solve_triangular(Lq.T, z, lower=False, check_finite=False)


def _aligned(u: np.ndarray, y: np.ndarray, nk: int) -> tuple[np.ndarray, np.ndarray]:
    """(u(t − nk), y(t)) rows, t ≥ nk: the delay folded into the data so that the FIR starts at lag 0."""
    N = len(u)
    return u[: N - nk], y[nk:]


def _simulate(u: np.ndarray, taps: np.ndarray, nk: int) -> np.ndarray:
    """Σ_i Σ_k h_{o,i}(k) u_i(t − nk − k) from zero past input; taps shaped (l, m, nb); returns (N, l)."""
    import scipy.signal

    N = u.shape[0]
    n_out, m, _ = taps.shape
    out = np.zeros((N, n_out))
    for o in range(n_out):
        for i in range(m):
            c = scipy.signal.convolve(u[:, i], taps[o, i])[: N - nk]
            out[nk:, o] += c
    return out


def _taps_from_theta(theta: np.ndarray, m: int) -> np.ndarray:
    """Lag-major θ (m·nb × l) → taps (l, m, nb)."""
    q, n_out = theta.shape
    return theta.reshape(q // m, m, n_out).transpose(2, 1, 0).copy()


def tap_grid(cap: int) -> list[int]:
    """Geometric grid of tap counts GRID_START … cap (ratio GRID_RATIO), cap included."""
    if cap <= GRID_START:
        return list(range(1, cap + 1))
    k = int(math.floor(math.log(cap / GRID_START) / math.log(GRID_RATIO)))
    grid = sorted({int(round(GRID_START * GRID_RATIO**j)) for j in range(k + 1)} | {int(cap)})
    return [n for n in grid if n <= cap]


def holdout_fir_search(
    records: Sequence[Any], nk: int, max_order: int, holdout: float = HOLDOUT
) -> tuple[int, list[dict[str, Any]], dict[str, Any]]:
    """Tap count by hold-out free-run NRMSE (module docstring): ``(nb, rows, search)`` with one row per grid point
    (``order``, ``n_parameters``, ``holdout_nrmse``, ``chosen``) and ``search`` = {criterion, holdout, grid_max,
    corner, best_holdout_nrmse, memory_samples} (memory: nb + nk of the choice, the lag beyond which the data show
    no more impulse response)."""
    recs = list(records)
    m = recs[0].n_inputs
    cuts = [int(round(len(r) * (1.0 - holdout))) for r in recs]
    fit_rows = min(c - nk for c in cuts)
    cap = min(int(max_order), fit_rows // MIN_FIT_PER_TAP)
    if cap < 1:
        raise DataError(
            f"fir: {min(len(r) for r in recs)} samples per record are too few to choose the taps on a "
            f"{holdout:.0%} hold-out; give nb explicitly or a longer record"
        )
    us = [r.u.reshape(len(r), -1).astype(float) for r in recs]
    ys = [r.output.reshape(len(r), -1).astype(float) for r in recs]
    pairs = [_aligned(u[:c], y[:c], nk) for u, y, c in zip(us, ys, cuts)]
    G, g, _ = fir_normal_equations(pairs, cap)
    Lc = _cholesky(G)
    y_hold = np.concatenate([y[c:] for y, c in zip(ys, cuts)])
    ref = float(np.linalg.norm(y_hold - y_hold.mean(axis=0)))
    rows: list[dict[str, Any]] = []
    for n in tap_grid(cap):
        taps = _taps_from_theta(_solve_leading(Lc, g, n * m), m)
        e = np.concatenate([y[c:] - _simulate(u, taps, nk)[c:] for u, y, c in zip(us, ys, cuts)])
        nrmse = float(np.linalg.norm(e) / max(ref, 1e-300))
        rows.append({"order": int(n), "n_parameters": int(n * m * ys[0].shape[1]), "holdout_nrmse": nrmse})
    best = min(float(r["holdout_nrmse"]) for r in rows)
    tol = holdout_tolerance(len(y_hold))
    chosen = min(r["order"] for r in rows if r["holdout_nrmse"] <= best * (1.0 + tol))
    for r in rows:
        r["chosen"] = r["order"] == chosen
    ridge, ridge_rows = _choose_ridge(G, g, chosen * m, m, nk, us, ys, cuts, ref, best, tol)
    search = {
        "criterion": "hold-out free-run NRMSE",
        "holdout": holdout,
        "tolerance": tol,
        "grid_max": int(cap),
        "corner": bool(chosen == rows[-1]["order"] and len(rows) > 1),
        "best_holdout_nrmse": best,
        "memory_samples": int(chosen + nk),
        "ridge": ridge,
        "ridge_selection": ridge_rows,
    }
    return chosen, rows, search


def _choose_ridge(G, g, q, m, nk, us, ys, cuts, ref, best, tol) -> tuple[float, list[dict[str, Any]]]:
    """The largest relative ridge of RIDGE_GRID whose FIR (q leading parameters) is within ``tol`` of the best
    hold-out NRMSE (module docstring); JITTER when none is."""
    Gq, rows = G[:q, :q], []
    for ridge in RIDGE_GRID:
        taps = _taps_from_theta(_solve_leading(_cholesky(Gq, ridge), g, q), m)
        e = np.concatenate([y[c:] - _simulate(u, taps, nk)[c:] for u, y, c in zip(us, ys, cuts)])
        rows.append({"ridge": ridge, "holdout_nrmse": float(np.linalg.norm(e) / max(ref, 1e-300))})
    best = min([best] + [r["holdout_nrmse"] for r in rows])
    ok = [r["ridge"] for r in rows if r["holdout_nrmse"] <= best * (1.0 + tol)]
    chosen = max(ok) if ok else JITTER
    for r in rows:
        r["chosen"] = r["ridge"] == chosen
    return chosen, rows


# --------------------------------------------------------------------------------------- the identifier
class FIR(Identifier):
    """Least-squares FIR model (module docstring).

    Parameters
    ----------
    nb : number of taps per input (lags nk … nk + nb − 1); ``None`` (default) = chosen on a hold-out part of the
        estimation data and reported in ``chosen_orders_`` / ``order_table_`` / ``order_search_``.
    nk : input delay [samples], ≥ 0, the same for every input (default 0: a direct feed-through tap, which least
        squares sets near zero when the system has none).
    max_order : largest tap count of the search (default 2048; at most a quarter of the fitting samples).
    ridge : Tikhonov term λ / mean diagonal of the normal equations; ``None`` (default): chosen on the hold-out with
        the taps (module docstring), plain least squares when ``nb`` is given.

    No constant term: a record with offsets should have its means removed first (``piezotwin preprocess``).

    Attributes: ``taps_`` (outputs × inputs × nb impulse-response coefficients, units of y per unit of u),
    ``nb_``, ``max_lag_`` = nk + nb − 1 (samples whose prediction would need input from before the record).
    """

    name = "fir"

    def __init__(self, nb: Any = None, nk: int = 0, max_order: int = 2048, ridge: Any = None):
        self.nb = nb
        self.nk = nk
        self.max_order = max_order
        self.ridge = ridge

    def _options(self) -> tuple[int | None, int]:
        nb = self.nb
        if isinstance(nb, str) and nb.lower() in ("none", "auto"):
            nb = None
        for key, v, lo in (("nb", nb, 1), ("nk", self.nk, 0), ("max_order", self.max_order, 1)):
            if v is None:
                continue
            if isinstance(v, bool) or float(v) != int(float(v)) or int(float(v)) < lo:
                raise ConfigError(f"fir: {key} must be an integer >= {lo}, got {v!r}")
        return (None if nb is None else int(float(nb))), int(float(self.nk))

    def fit(self, data) -> FIR:
        records = as_record_list(data)
        nb, nk = self._options()
        check_records(records, nk, 2, self.name)
        self.chosen_orders_, self.order_table_, self.order_search_ = {}, None, None
        ridge = JITTER
        if self.ridge is not None:
            if isinstance(self.ridge, bool) or not float(self.ridge) >= 0.0:
                raise ConfigError(f"fir: ridge must be a number >= 0, got {self.ridge!r}")
            ridge = float(self.ridge)
        if nb is None:
            nb, self.order_table_, self.order_search_ = holdout_fir_search(records, nk, int(float(self.max_order)))
            self.chosen_orders_ = {"nb": int(nb)}
            if self.ridge is None:
                ridge = float(self.order_search_["ridge"])
            if self.order_search_["corner"]:
                warnings.warn(
                    f"fir: the tap count chosen on the hold-out, {nb}, is the largest of the grid "
                    f"(max_order {self.order_search_['grid_max']}): the record may be too short for the "
                    "system's memory; more taps or a longer record may fit better",
                    OrderSearchWarning,
                    stacklevel=2,
                )
        short = [r for r in records if len(r) - nk < nb + 1]
        if short:
            raise DataError(
                f"{short[0].source}: {len(short[0])} samples are too few for a FIR with nb={nb} taps and "
                f"nk={nk} (need more than nb + nk = {nb + nk} samples per record)"
            )
        m = records[0].n_inputs
        us = [r.u.reshape(len(r), -1).astype(float) for r in records]
        ys = [r.output.reshape(len(r), -1).astype(float) for r in records]
        G, g, rows = fir_normal_equations([_aligned(u, y, nk) for u, y in zip(us, ys)], nb)
        if rows <= m * nb:
            raise DataError(
                f"fir: {rows} fitted samples are too few for {m * nb} taps (nb={nb} per input); give "
                "fewer taps or more data"
            )
        theta = _solve_leading(_cholesky(G, ridge), g, m * nb)
        self.ridge_ = ridge
        self.taps_ = _taps_from_theta(theta, m)
        res = np.concatenate([y[nk + nb - 1 :] - _simulate(u, self.taps_, nk)[nk + nb - 1 :] for u, y in zip(us, ys)])
        self.noise_variance_ = float(np.mean(res**2))
        self.nb_, self.nk_ = int(nb), nk
        self._set_common()
        return self

    def _set_common(self) -> None:
        self.n_outputs_, self.n_inputs_, nb = self.taps_.shape
        self.nb_ = int(nb)
        self.n_parameters_ = int(self.taps_.size)
        self.max_lag_ = int(self.nk_ + nb - 1)
        self.diverged_at_ = None

    def _check_fitted(self) -> None:
        if not hasattr(self, "taps_"):
            raise ConfigError("fir: model is not fitted (call fit first)")

    def predict(self, record, horizon: int | None = 1) -> np.ndarray:
        """The FIR simulation (every horizon is the same prediction); the first ``max_lag_`` samples are copied
        from the measurement, as every identifier does."""
        self._check_fitted()
        check_prediction(self, record, horizon)
        u = record.u.reshape(len(record), -1).astype(float)
        y = record.y.reshape(len(record), -1)
        yhat = _simulate(u, self.taps_, self.nk_)
        L = min(self.max_lag_, len(record))
        yhat[:L] = y[:L]
        return yhat.reshape(record.y.shape)

    def impulse_response(self, output: int = 0, input: int = 0) -> np.ndarray:
        """h(k), k = 0 … nk + nb − 1 (the first nk are zero) for one input/output pair."""
        self._check_fitted()
        return np.concatenate([np.zeros(self.nk_), self.taps_[output, input]])

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "taps_"):
            taps = self.taps_[0, 0].tolist() if self.taps_.shape[:2] == (1, 1) else self.taps_.tolist()
            d.update(
                nb=self.nb_,
                nk=self.nk_,
                taps=taps,
                ridge=self.ridge_,
                noise_variance=self.noise_variance_,
                max_lag=self.max_lag_,
                terms=[],
                chosen_orders=self.chosen_orders_,
            )
            if self.order_table_:
                d["order_selection"] = self.order_table_
                d["order_search"] = self.order_search_
        return d

    def summary(self) -> str:
        how = "chosen on the hold-out" if self.chosen_orders_ else "given"
        h = self.taps_[0, 0]
        k = int(np.argmax(np.abs(h)))
        return f"fir: nb = {self.nb_} taps ({how}), nk = {self.nk_}; largest tap h({k + self.nk_}) = {h[k]:.6g}" + (
            " (output 1, input 1)" if self.taps_.shape[:2] != (1, 1) else ""
        )

    def _state(self) -> dict[str, Any]:
        self._check_fitted()
        return {
            "taps": np.asarray(self.taps_, float),
            "nk": self.nk_,
            "ridge": self.ridge_,
            "chosen": self.chosen_orders_,
            "noise_variance": self.noise_variance_,
            "order_table": self.order_table_,
            "order_search": self.order_search_,
        }

    def _load_state(self, state: dict[str, Any]) -> None:
        taps = np.asarray(state["taps"], float)
        if taps.ndim != 3:
            raise ValueError(f"taps must be outputs × inputs × nb, got shape {taps.shape}")
        self.taps_ = taps
        self.nk_ = int(state["nk"])
        self.ridge_ = float(state.get("ridge", JITTER))
        self.chosen_orders_ = dict(state.get("chosen") or {})
        self.noise_variance_ = float(state["noise_variance"])
        self.order_table_ = state.get("order_table")
        self.order_search_ = state.get("order_search")
        self._set_common()
