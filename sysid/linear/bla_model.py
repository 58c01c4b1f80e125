"""The ``bla`` identifier: a linear simulation model fitted to the Best Linear Approximation in the frequency
domain (registry id ``bla``).

``fit`` estimates the nonparametric BLA of the estimation records — the H1 FRF with Welch averaging over all
records (:func:`sysid.linear.frf.frf_welch`, arbitrary excitation) or, with ``periods = P``, the robust BLA of
multisine records that each hold ``P`` periods (:func:`sysid.linear.bla.best_linear_approximation`, one record per
realisation) — and fits ``B(z)/A(z)`` to it with :func:`sysid.linear.tfest.tfest` weighted by the input power
spectrum (the frequency-domain output-error criterion). Offsets: ``y = ȳ + G(q)(u − ū)`` with the means of
the estimation data (the BLA is a small-signal model around the operating point).

It is an output-error model (noise model 1), so its one-step-ahead predictor *is* its simulation:
``predict`` returns the free-run output for every horizon. Options in MATLAB's names: ``nb`` numerator
coefficients, ``nf`` poles (``tfest``'s ``np``), ``nk`` delay; ``nperseg`` Welch segment length; ``periods``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.signal

from sysid.base import Identifier, as_record_list
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError

__all__ = ["BLAModel"]


class BLAModel(Identifier):
    """Linear OE-type model B(q)/F(q) fitted to the nonparametric BLA (Welch H1 or multisine robust BLA).

    Parameters
    ----------
    nb, nf, nk : int
        Numerator coefficients, denominator order, input delay [samples] of
        G(q) = (b1 q^-nk + ... + b_nb q^-(nk+nb-1)) / (1 + f1 q^-1 + ... + f_nf q^-nf).
    nperseg : int
        Welch segment length (frequency resolution fs/nperseg) for non-periodic data.
    periods : int
        0: arbitrary excitation (Welch H1). P >= 1: every record holds P periods of a multisine (one record
        per realisation), the robust BLA at the excited lines is fitted.
    drop : int
        Periodic data: leading periods left out (transient).

    The parameter standard deviations (``describe()['parameters']``) come from the FRF variances by the
    sandwich formula of :func:`sysid.linear.tfest.tfest`: ``var_total`` of the BLA (noise + nonlinear distortion)
    with two or more multisine realisations, the noise variance with one, and the coherence-based variance of
    H1 (approximate: neighbouring Welch bins are correlated) for arbitrary excitation.

    Attributes
    ----------
    b_, a_ : ndarray
        Fitted polynomials (:func:`scipy.signal.lfilter` convention, ``b_`` with ``nk`` leading zeros).
    u_mean_, y_mean_ : float
        Operating point.
    fs_ : float
        Sampling rate of the estimation data [Hz].
    """

    name = "bla"

    def __init__(self, nb: int = 6, nf: int = 6, nk: int = 0, nperseg: int = 1024, periods: int = 0, drop: int = 0):
        self.nb = nb
        self.nf = nf
        self.nk = nk
        self.nperseg = nperseg
        self.periods = periods
        self.drop = drop

    def fit(self, data: Record | Sequence[Record]) -> BLAModel:
        from sysid.linear.tfest import tfest

        recs = as_record_list(data)
        for r in recs:
            if r.u.ndim != 1 or r.output.ndim != 1:
                raise DataError(f"{r.source}: bla is single-input single-output (got u{r.u.shape}, y{r.output.shape})")
            if abs(r.fs - recs[0].fs) > 1e-9 * recs[0].fs:
                raise DataError(f"{r.source}: fs {r.fs:g} Hz differs from the first record's {recs[0].fs:g} Hz")
        nb, nf, nk, periods = int(self.nb), int(self.nf), int(self.nk), int(self.periods)
        if nb < 1 or nf < 0 or nk < 0 or periods < 0:
            raise ConfigError(f"bla: need nb >= 1, nf >= 0, nk >= 0, periods >= 0 (got {nb}, {nf}, {nk}, {periods})")
        fs = recs[0].fs
        u_all = np.concatenate([r.u for r in recs])
        y_all = np.concatenate([r.y for r in recs])
        self.u_mean_, self.y_mean_ = float(u_all.mean()), float(y_all.mean())
        if periods == 0:
            f, G, W, var = self._welch(recs, fs)
        else:
            from sysid.linear.bla import best_linear_approximation
            from sysid.linear.frf import period_spectra

            res = best_linear_approximation([(r.u, r.y) for r in recs], fs, periods, drop=int(self.drop))
            f, G = res.f_hz, res.G
            W = np.mean(
                [np.abs(period_spectra(r.u, periods, int(self.drop)).mean(axis=0)[res.lines]) ** 2 for r in recs],
                axis=0,
            )
            self.nonlinearity_ = res.nonlinearity
            var = res.var_total if len(recs) >= 2 else res.var_noise
        tf = tfest(f, G, fs, nb=nb, na=nf, nk=nk, weight=W, var=var)
        self.b_, self.a_, self.fs_ = tf.b, tf.a, float(fs)
        self.fit_info_ = tf.info
        self.max_lag_ = 0
        self.n_parameters_ = nb + nf
        self.diverged_at_ = None
        return self

    def _welch(self, recs: list[Record], fs: float):
        """H1 from Welch spectra summed over the records (weighted by their segment counts)."""
        nper = int(self.nperseg)
        if nper < 8:
            raise ConfigError(f"bla: nperseg must be >= 8, got {nper}")
        s_uu = s_uy = s_yy = 0.0
        used = segments = 0
        for r in recs:
            if len(r) < nper:
                continue
            kw = dict(fs=fs, nperseg=nper, noverlap=nper // 2)
            f, puu = scipy.signal.welch(r.u - self.u_mean_, **kw)
            _, puy = scipy.signal.csd(r.u - self.u_mean_, r.output - self.y_mean_, **kw)
            _, pyy = scipy.signal.welch(r.output - self.y_mean_, **kw)
            s_uu = s_uu + len(r) * puu
            s_uy = s_uy + len(r) * puy
            s_yy = s_yy + len(r) * pyy
            segments += 1 + (len(r) - nper) // (nper - nper // 2)
            used += 1
        if not used:
            raise DataError(f"bla: every estimation record is shorter than nperseg={nper}; lower nperseg")
        with np.errstate(divide="ignore", invalid="ignore"):
            G = s_uy / s_uu
            coh = np.clip(np.abs(s_uy) ** 2 / (s_uu * s_yy), 1e-12, 1.0)
            # variance of the complex H1 estimate (Bendat & Piersol eq. 9.90 for |G| and the phase, each
            # (1 - γ²)/(2 n_d γ²)); overlapping segments are not independent: approximate (optimistic)
            var = np.abs(G) ** 2 * (1.0 - coh) / (segments * coh)
        return f, G, s_uu, var

    def _check_fitted(self) -> None:
        if not hasattr(self, "b_"):
            raise ConfigError("bla: model is not fitted; call fit first")

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """Simulation from rest, y = ȳ + G(q)(u − ū), for every horizon (output-error model)."""
        self._check_fitted()
        if record.u.ndim != 1:
            raise DataError(f"{record.source}: bla is single-input (got u{record.u.shape})")
        if abs(record.fs - self.fs_) > 1e-9 * self.fs_:
            raise DataError(f"{record.source}: fs {record.fs:g} Hz differs from the model's {self.fs_:g} Hz")
        return self.y_mean_ + scipy.signal.lfilter(self.b_, self.a_, record.u - self.u_mean_)

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "b_"):
            p = np.roots(self.a_)
            names = [f"b{i + 1}" for i in range(int(self.nb))] + [f"f{i + 1}" for i in range(int(self.nf))]
            values = list(self.b_[int(self.nk) :]) + list(self.a_[1:])
            info = getattr(self, "fit_info_", {})
            stds: list[float | None]
            if "std_b" in info:
                stds = [float(x) for x in (*info["std_b"], *info["std_a"])]
            else:
                stds = [None] * len(names)
            d.update(
                terms=names,
                parameters=[{"name": n, "value": float(v), "std": sd} for n, v, sd in zip(names, values, stds)],
                B=self.b_[int(self.nk) :].tolist(),
                F=self.a_.tolist(),
                poles_abs=np.abs(p).tolist(),
                fit={k: v for k, v in self.fit_info_.items() if k not in ("cov", "std_a", "std_b")},
            )
            if hasattr(self, "nonlinearity_"):
                d["nonlinearity"] = self.nonlinearity_
        return d

    def _state(self) -> dict[str, Any]:
        self._check_fitted()
        return {
            "b": self.b_.tolist(),
            "a": self.a_.tolist(),
            "u_mean": self.u_mean_,
            "y_mean": self.y_mean_,
            "fs": self.fs_,
        }

    def _load_state(self, state: dict[str, Any]) -> None:
        self.b_ = np.asarray(state["b"], dtype=float)
        self.a_ = np.asarray(state["a"], dtype=float)
        self.u_mean_, self.y_mean_, self.fs_ = float(state["u_mean"]), float(state["y_mean"]), float(state["fs"])
        self.max_lag_, self.n_parameters_, self.diverged_at_ = 0, int(self.nb) + int(self.nf), None
        self.fit_info_ = {}
