"""Output-error model with a reverberation path (registry id ``oe-echo``), fitted on the simulation error.

Model, one input, one output::

    y(t) = B(q) / A(q) · u(t − nk) + e(t),      A(q) = F(q) − q^{−τ} C(q),   C(q) = Σ_{k=−w}^{w} c_k q^{−k}

so that B/A = (B/F) · Σ_n (q^{−τ} C/F)^n: the direct arrival followed by every echo, each one round trip τ
[samples] later and once more through C/F — a transmission through a fluid between two reflecting plates
(physics notes B.6; dissertation §3.2), whose round trip (≈ 900 samples at 6.75 MHz over 100 mm of water) no
dense polynomial of practical order holds.

From the estimation data (:func:`echo_lags`): τ is the quefrency of the largest real-cepstrum peak of log|Ĝ|
above ``min_echo_lag`` (Bogert, Healy & Tukey 1963; Ĝ the H1 FRF over the band where the input has ≥ 1 % of
its peak power), no echo below ``echo_snr`` × the cepstrum's median; nk is the first arrival of the impulse
response's envelope less nb/8 samples.

Estimation: B, F by simplified refined IV (:func:`sysid.linear.pem_init.sriv`, Ljung §7.6), C by ridge least
squares on the equation error F·y − B·u = q^{−τ}C·y, the whole structure by further SRIV iterations, then every
parameter by Levenberg–Marquardt on the free-run error with the analytic Jacobian (Ljung eq. 10.42), the first
``max_lag_`` measured outputs as initial conditions.

Stability: F's roots inside the unit circle and |C/F| < ``LOOP_MARGIN`` on a grid of ``GRID`` frequencies; by
Rouché's theorem A = F − q^{−τ}C then has no root outside the unit circle. A step leaving that set is refused.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.ndimage
import scipy.signal
from scipy.optimize import least_squares
from scipy.signal import hilbert, lfilter, lfiltic

from sysid.base import Identifier, as_record_list, check_prediction, check_records, stop_at_divergence
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.linear.pem_init import is_stable, shift, sriv, stabilise

__all__ = ["EchoOE", "echo_lags"]

GRID = 8192  # frequency points of the loop-gain check |C/F|
LOOP_MARGIN = 0.999  # largest loop gain a step may reach
INIT_LOOP_GAIN = 0.95  # the initial echo estimate is scaled down to this loop gain when above it
EXCITED = 1e-2  # the excited band: where the input's power spectrum is at least this fraction of its peak
DIVERGENCE_FACTOR = 1e3
IV_ITERATIONS = 8  # Steiglitz-McBride iterations of the whole structure before Levenberg-Marquardt


def echo_lags(records: Sequence[Record], min_echo_lag: int = 50, echo_snr: float = 8.0) -> dict[str, Any]:
    """Delay and echo round trip of a SISO system from its records (module docstring).

    Returns ``{"onset", "peak", "echo_lag", "echo_snr", "nperseg"}``: the first arrival's lag [samples], the impulse
    response's peak lag, the round trip (0 when no cepstral peak reaches ``echo_snr`` times the median) and the peak's
    ratio to the median.
    """
    from sysid.linear.frf import frf_welch

    rec = max(records, key=len)
    u, y = rec.u.reshape(-1), rec.output.reshape(-1)
    n = u.size
    nper = 1 << int(np.floor(np.log2(max(n // 2, 16))))
    fr = frf_welch(u, y, 1.0, nperseg=nper)
    _, s_uu = scipy.signal.welch(u, nperseg=nper)
    excited = np.isfinite(fr.G) & (s_uu >= EXCITED * np.max(s_uu))
    if np.count_nonzero(excited) < 8:
        raise DataError(
            f"{rec.source}: the input excites {np.count_nonzero(excited)} frequencies of {nper // 2 + 1}; "
            "too few to locate a delay or an echo"
        )
    g = np.fft.irfft(np.where(excited, fr.G, 0.0), nper)[: nper // 2]
    idx = np.flatnonzero(excited)
    i0, i1 = int(idx[0]), int(idx[-1]) + 1
    # envelope at the band's resolution: moving maximum over two lags per excited bandwidth
    env = scipy.ndimage.maximum_filter1d(np.abs(hilbert(g)), max(2 * nper // (i1 - i0), 1))
    peak = int(np.argmax(env))
    floor = max(float(np.median(env)), 1e-300 * env[peak])
    level = np.sqrt(floor * env[peak])  # halfway between the floor and the peak in dB
    below = np.flatnonzero(env[:peak] < level)
    onset = int(below[-1]) + 1 if below.size else 0
    lg = np.log(np.maximum(np.abs(fr.G[i0:i1]), 1e-300))
    lg = (lg - lg.mean()) * np.hanning(lg.size)
    m = 16 * lg.size
    cep = np.abs(np.fft.fft(lg, m))
    q = np.arange(m) * nper / m  # quefrency [samples]
    ok = (q >= min_echo_lag) & (q <= nper / 2)
    tau, snr = 0, 0.0
    if ok.any():
        j = int(np.flatnonzero(ok)[np.argmax(cep[ok])])
        snr = float(cep[j] / max(np.median(cep[ok]), 1e-300))
        if snr >= echo_snr:
            tau = int(round(q[j]))
    return {"onset": onset, "peak": peak, "echo_lag": tau, "echo_snr": snr, "nperseg": nper}


class EchoOE(Identifier):
    """Output-error model B/(F − q^{−τ}C) with the delay and echo round trip found in the data (module docstring).

    Parameters: ``nb`` (taps of B), ``nf`` (order of F), ``echo_width`` (C spans lags τ − w … τ + w),
    ``nk`` and ``echo_lag`` (``None``: found by :func:`echo_lags`; ``echo_lag=0``: no echo term),
    ``min_echo_lag`` and ``echo_snr`` (the cepstral search), ``ridge`` (relative ridge of the initial echo
    estimate), ``max_iter`` (most residual evaluations of Levenberg–Marquardt; 0 keeps the initial estimate).
    """

    name = "oe-echo"

    def __init__(
        self,
        nb: int = 200,
        nf: int = 4,
        echo_width: int = 25,
        nk: Any = None,
        echo_lag: Any = None,
        min_echo_lag: int = 50,
        echo_snr: float = 8.0,
        ridge: float = 0.1,
        max_iter: int = 40,
    ):
        self.nb = nb
        self.nf = nf
        self.echo_width = echo_width
        self.nk = nk
        self.echo_lag = echo_lag
        self.min_echo_lag = min_echo_lag
        self.echo_snr = echo_snr
        self.ridge = ridge
        self.max_iter = max_iter

    # ------------------------------------------------------------------ structure
    def _check_options(self) -> None:
        for key, low in (("nb", 1), ("nf", 0), ("echo_width", 0), ("min_echo_lag", 1), ("max_iter", 0)):
            v = getattr(self, key)
            if isinstance(v, bool) or int(v) != v or v < low:
                raise ConfigError(f"{self.name}: {key} must be an integer >= {low}, got {v!r}")
        for key in ("nk", "echo_lag"):
            v = getattr(self, key)
            if v is not None and (isinstance(v, bool) or int(v) != v or v < 0):
                raise ConfigError(f"{self.name}: {key} must be an integer >= 0 or None (found in the data), got {v!r}")
        if not (float(self.ridge) >= 0 and float(self.echo_snr) > 0):
            raise ConfigError(
                f"{self.name}: ridge must be >= 0 and echo_snr > 0, got {self.ridge!r}, {self.echo_snr!r}"
            )

    def _structure(self, records: list[Record]) -> dict[str, Any]:
        nb, nf, w = int(self.nb), int(self.nf), int(self.echo_width)
        found: dict[str, Any] = {}
        if self.nk is None or self.echo_lag is None:
            found = echo_lags(records, int(self.min_echo_lag), float(self.echo_snr))
        nk = int(self.nk) if self.nk is not None else max(found["onset"] - nb // 8, 0)
        tau = int(self.echo_lag) if self.echo_lag is not None else found["echo_lag"]
        if tau and tau - w <= nf:
            raise ConfigError(f"{self.name}: echo lag {tau} minus echo_width {w} must exceed nf={nf}")
        w = w if tau else 0  # no echo: C is empty
        return {
            "nb": nb,
            "nf": nf,
            "nk": nk,
            "echo_lag": tau,
            "echo_width": w,
            "n_echo": 2 * w + 1 if tau else 0,
            "found": found,
        }

    def _polys(self, theta: np.ndarray, s: dict[str, Any] | None = None):
        s = self.structure_ if s is None else s
        nb, nf, nk, tau, w = s["nb"], s["nf"], s["nk"], s["echo_lag"], s["echo_width"]
        b = np.zeros(nk + nb)
        b[nk:] = theta[:nb]
        f = np.concatenate([[1.0], theta[nb : nb + nf]])
        c = np.asarray(theta[nb + nf :], float)
        a = np.zeros(max(nf, tau + w if tau else 0) + 1)
        a[: nf + 1] = f
        if tau:
            a[tau - w : tau + w + 1] -= c
        return b, f, c, a

    @staticmethod
    def _max_lag(s: dict[str, Any]) -> int:
        return max(s["nk"] + s["nb"] - 1, s["nf"], s["echo_lag"] + s["echo_width"] if s["echo_lag"] else 0)

    @staticmethod
    def _loop_gain(f: np.ndarray, c: np.ndarray) -> float:
        """max over ω of |C(e^{iω})/F(e^{iω})| (C placed at its own lags −w…w; the delay τ has modulus 1)."""
        if c.size == 0:
            return 0.0
        C = np.fft.rfft(c, GRID)
        F = np.fft.rfft(f, GRID)
        return float(np.max(np.abs(C) / np.maximum(np.abs(F), 1e-300)))

    def _admissible(self, f, c) -> bool:
        return is_stable(f) and self._loop_gain(f, c) < LOOP_MARGIN

    @staticmethod
    def _columns(s: dict[str, Any], xu: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """The model's regressors in θ order from an input-side and an output-side signal: xu(t − nk − k) for the
        nb taps of B, −xy(t − k) for F's k = 1 … nf, xy(t − k) for C's lags τ − w … τ + w."""
        nb, nf, nk, tau, w = s["nb"], s["nf"], s["nk"], s["echo_lag"], s["echo_width"]
        echo = range(tau - w, tau + w + 1) if tau else range(0)
        return np.column_stack(
            [shift(xu, nk + k) for k in range(nb)]
            + [-shift(xy, k) for k in range(1, nf + 1)]
            + [shift(xy, k) for k in echo]
        )

    def _free_runs(self, theta, us, ys, s, L) -> list[np.ndarray] | None:
        """The free run of every record (the first L samples measured), or None where θ is not admissible or a
        run is not finite."""
        b, f, c, a = self._polys(theta, s)
        if not self._admissible(f, c):
            return None
        runs = [self._run(b, a, u_, y_, L) for u_, y_ in zip(us, ys)]
        return runs if all(np.isfinite(r).all() for r in runs) else None

    # ------------------------------------------------------------------ simulation
    @staticmethod
    def _run(b, a, u, y, L):
        """Free run of A·ŷ = B·u with ŷ = y (measured) over the first L samples as initial conditions."""
        out = np.empty_like(u)
        out[:L] = y[:L]
        if L >= u.size:
            return out
        if L > 0:
            zi = lfiltic(b, a, y[L - 1 :: -1], u[L - 1 :: -1])
            out[L:] = lfilter(b, a, u[L:], zi=zi)[0]
        else:
            out[:] = lfilter(b, a, u)
        return out

    # ------------------------------------------------------------------ estimation
    def fit(self, data: Record | Sequence[Record]) -> EchoOE:
        records = as_record_list(data)
        if records[0].n_inputs != 1 or records[0].n_outputs != 1:
            raise ConfigError(
                f"{self.name}: one input and one output supported, the data have "
                f"{records[0].n_inputs} / {records[0].n_outputs}"
            )
        self._check_options()
        s = self._structure(records)
        nb, nf, nk, tau, w = s["nb"], s["nf"], s["nk"], s["echo_lag"], s["echo_width"]
        L = self._max_lag(s)
        n_par = nb + nf + s["n_echo"]
        check_records(records, L, n_par + 1, self.name)
        us = [r.u.reshape(-1) for r in records]
        ys = [r.output.reshape(-1) for r in records]

        b0, f0 = sriv(us, ys, nb, nf, nk)
        c0 = np.zeros(s["n_echo"])
        if tau:
            lags_c = list(range(tau - w, tau + w + 1))
            Z = np.vstack([np.column_stack([shift(y_, k) for k in lags_c])[L:] for y_ in ys])
            v = np.concatenate(
                [(lfilter(f0, [1.0], y_) - lfilter(np.r_[np.zeros(nk), b0], [1.0], u_))[L:] for u_, y_ in zip(us, ys)]
            )
            ZZ = Z.T @ Z
            lam = float(self.ridge) * float(np.trace(ZZ)) / ZZ.shape[0]
            c0 = np.linalg.solve(ZZ + lam * np.eye(ZZ.shape[0]), Z.T @ v)
            gain = self._loop_gain(f0, c0)
            if gain >= INIT_LOOP_GAIN:
                c0 *= INIT_LOOP_GAIN / gain
        theta0 = self._refine_iv(np.concatenate([b0, f0[1:], c0]), us, ys, s, L)
        n_res = sum(len(y_) - L for y_ in ys)
        y_all = np.concatenate(ys)
        penalty = 1e3 * (max(float(np.std(y_all)), 1e-300) + float(np.max(np.abs(y_all))))

        last: dict[str, Any] = {}  # the runs of the θ the residual was last evaluated at: the Jacobian's point

        def residual(theta):
            runs = self._free_runs(theta, us, ys, s, L)
            last.update(theta=np.array(theta), runs=runs)
            return (
                np.full(n_res, penalty) if runs is None else np.concatenate([(y_ - r)[L:] for y_, r in zip(ys, runs)])
            )

        def jac(theta):
            b, f, c, a = self._polys(theta, s)
            runs = last["runs"] if "theta" in last and np.array_equal(last["theta"], theta) else None
            if runs is None:
                runs = [self._run(b, a, u_, y_, L) for u_, y_ in zip(us, ys)]
            blocks = []
            for u_, r in zip(us, runs):
                mask = np.zeros_like(u_)
                mask[L:] = 1.0  # the initial window is measured: no sensitivity before L
                wu = lfilter([1.0], a, u_ * mask)
                wy = lfilter([1.0], a, r * mask)
                blocks.append(-self._columns(s, wu, wy)[L:])
            return np.vstack(blocks)

        theta, status = theta0, "initial estimate (max_iter=0)"
        if not self._admissible(f0, c0):  # pragma: no cover - sriv stabilises F and c0 is scaled
            raise DataError(f"{self.name}: no stable initial estimate")
        if int(self.max_iter) > 0:
            sol = least_squares(
                residual,
                theta0,
                jac=jac,
                method="lm",
                x_scale="jac",
                xtol=1e-10,
                ftol=1e-10,
                gtol=1e-10,
                max_nfev=int(self.max_iter),
            )
            if np.sum(sol.fun**2) <= np.sum(residual(theta0) ** 2):
                theta, status = sol.x, str(sol.message)
        r = residual(theta)
        self.structure_ = s
        self.theta_ = np.asarray(theta, float)
        self.noise_variance_ = float(r @ r) / max(r.size - n_par, 1)
        self.fit_status_ = status
        self.y_bound_ = DIVERGENCE_FACTOR * max(float(np.max(np.abs(y_all))), 1e-300)
        self._set_common()
        return self

    def _cost(self, theta, us, ys, s, L) -> float:
        runs = self._free_runs(theta, us, ys, s, L)
        if runs is None:
            return np.inf
        v = float(sum(np.sum((y_ - r)[L:] ** 2) for y_, r in zip(ys, runs)))
        return v if np.isfinite(v) else np.inf

    def _refine_iv(self, theta, us, ys, s, L) -> np.ndarray:
        """Steiglitz–McBride / SRIV iterations (Ljung §7.6) over the whole structure, echo included: the data are
        prefiltered by 1/A of the current model and the output lags instrumented by its noise-free simulation;
        F is stabilised and C scaled to the initial loop gain after each solve. Returns the iterate of least
        simulation error (the starting point when no iterate improves on it)."""
        nb, nf = s["nb"], s["nf"]
        best = (self._cost(theta, us, ys, s, L), theta)
        for _ in range(IV_ITERATIONS):
            b, f, c, a = self._polys(theta, s)
            ZP, Zy = 0.0, 0.0
            for u_, y_ in zip(us, ys):
                uf, yf = lfilter([1.0], a, u_), lfilter([1.0], a, y_)
                xf = lfilter([1.0], a, self._run(b, a, u_, np.zeros_like(y_), 0))
                P, Z = self._columns(s, uf, yf)[L:], self._columns(s, uf, xf)[L:]
                ZP = ZP + Z.T @ P
                Zy = Zy + Z.T @ yf[L:]
            try:
                new = np.linalg.lstsq(ZP, Zy, rcond=None)[0]
            except np.linalg.LinAlgError:  # pragma: no cover - singular instruments
                break
            f_new = stabilise(np.r_[1.0, new[nb : nb + nf]])
            new[nb : nb + nf] = f_new[1:]
            gain = self._loop_gain(f_new, new[nb + nf :])
            if gain >= INIT_LOOP_GAIN:
                new[nb + nf :] *= INIT_LOOP_GAIN / gain
            theta = new
            cost = self._cost(theta, us, ys, s, L)
            if cost < best[0]:
                best = (cost, theta)
        return best[1]

    def _set_common(self) -> None:
        s = self.structure_
        self.b_, self.f_, self.c_, self.a_ = self._polys(self.theta_, s)
        self.loop_gain_ = self._loop_gain(self.f_, self.c_)
        self.n_parameters_ = int(self.theta_.size)
        self.max_lag_ = int(self._max_lag(s))
        self.n_inputs_ = self.n_outputs_ = 1
        self.diverged_at_ = None

    # ------------------------------------------------------------------ prediction
    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """Free run from the first ``max_lag_`` measured outputs. An output-error model predicts every horizon by
        its simulation (its noise model is 1), so ``horizon`` only has to be valid."""
        if not hasattr(self, "theta_"):
            raise ConfigError(f"{self.name}: model is not fitted (call fit first)")
        check_prediction(self, record, horizon)
        u, y = record.u.reshape(-1).astype(float), record.output.reshape(-1).astype(float)
        yhat = self._run(self.b_, self.a_, u, y, min(self.max_lag_, u.size))
        return stop_at_divergence(self, yhat).reshape(record.output.shape)

    def frequency_response(self, f_hz: Any, fs: float) -> dict[str, np.ndarray]:
        """G(e^{iωT}) = B/A at ``f_hz`` [Hz] for the sampling rate ``fs`` [Hz] (delay included)."""
        if not hasattr(self, "theta_"):
            raise ConfigError(f"{self.name}: model is not fitted (call fit first)")
        f_hz = np.asarray(f_hz, float)
        z = np.exp(-1j * 2 * np.pi * f_hz / float(fs))
        return {"f_hz": f_hz, "G": np.polyval(self.b_[::-1], z) / np.polyval(self.a_[::-1], z)}

    # ------------------------------------------------------------------ reporting / persistence
    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "theta_"):
            s = self.structure_
            d.update(
                orders={k: s[k] for k in ("nb", "nf", "nk", "echo_lag", "echo_width")},
                found=s["found"],
                loop_gain=self.loop_gain_,
                noise_variance=self.noise_variance_,
                fit=self.fit_status_,
                max_lag=self.max_lag_,
                terms=[],
            )
        return d

    def summary(self) -> str:
        """Orders, where the delay and the round trip came from, and the loop gain (printed by ``identify``)."""
        s, found = self.structure_, self.structure_["found"] or {}
        lines = [
            f"{self.name}: nb={s['nb']}, nf={s['nf']}, nk={s['nk']}"
            + (f" (found: first arrival at lag {int(found['onset'])})" if self.nk is None and found else "")
        ]
        if s["echo_lag"]:
            how = (
                f" (found: cepstral peak {found['echo_snr']:.1f}x the median)"
                if self.echo_lag is None and found
                else ""
            )
            lines.append(
                f"  echo round trip {s['echo_lag']} samples{how}, C over lags "
                f"{s['echo_lag'] - s['echo_width']}..{s['echo_lag'] + s['echo_width']}, "
                f"loop gain max|C/F| = {self.loop_gain_:.4f}"
            )
        elif self.echo_lag is None and found:
            lines.append(
                f"  no echo term: the largest cepstral peak is {found['echo_snr']:.1f}x the median "
                f"(needs {float(self.echo_snr):g}x)"
            )
        return "\n".join(lines)

    def _state(self) -> dict[str, Any]:
        return {
            "structure": self.structure_,
            "theta": self.theta_.tolist(),
            "noise_variance": self.noise_variance_,
            "y_bound": self.y_bound_,
            "fit": self.fit_status_,
        }

    def _load_state(self, state: dict[str, Any]) -> None:
        self.structure_ = dict(state["structure"])
        self.theta_ = np.asarray(state["theta"], float)
        self.noise_variance_ = float(state["noise_variance"])
        self.y_bound_ = float(state["y_bound"])
        self.fit_status_ = str(state.get("fit", ""))
        self._set_common()
