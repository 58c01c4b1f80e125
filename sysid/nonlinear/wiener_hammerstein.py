"""Wiener–Hammerstein model from the best split of the BLA, refined on simulation error (registry id ``wh-bla``).

Model (:mod:`sysid.nonlinear.wh_blocks`)::

    ŷ(t) = G2(q) f(G1(q) u(t)),   G1 = q^{-nk} B1/A1,   G2 = B2/A2,   f: cubic spline of ``knots`` inner knots

The procedure (Sjöberg, Lauwers & Schoukens 2012, §2-3; Schoukens & Tiels 2017, §5.1):

1. **BLA**: an output-error model B/F (``nb``, ``nf``, ``nk``; :class:`sysid.linear.pem.OE`). Under Gaussian
   excitation the BLA is G1·G2 up to a gain (Bussgang), so its poles and zeros are the two filters'.
2. **Best split**: every sharing of the BLA's poles and zeros between G1 and G2 (conjugate pairs together, at
   most 2^12) is scored on the first ``split_samples`` samples by the spline fitted by linear least squares
   to G2[B_k(G1 u)] on knots at quantiles; the lowest RMS residual wins.
3. **Refinement**: knots placed again over all records, then every coefficient of B1, A1, f, B2, A2 by
   Levenberg–Marquardt on the simulation error with the exact Jacobian
   (:func:`sysid.nonlinear.wh_blocks.jacobian`), B2's largest coefficient pinned (the gain f and G2 exchange
   exactly). ``extra_zeros`` zero coefficients are then appended to B1 and B2 and a second search starts from
   the first one's end; while x leaves the knots' interval the knots are placed again and the search
   repeated (``RESTAGES``). Unstable trials are rejected; a result worse than the start is never kept.

Records are separate experiments, each simulated from rest, its first ``warmup`` samples out of the cost.
Prediction is the free run from rest (every ``horizon`` alike), the first ``max_lag_ = warmup`` samples copied
from the measurement (the benchmark's initialisation window: 50 on Wiener–Hammerstein 2009). Single input,
single output. Measurements behind these choices: docs/identifiers.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from sysid.base import Identifier, as_record_list, check_prediction, check_records, stop_at_divergence
from sysid.config import int_option
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.nonlinear import wh_blocks as wb

__all__ = ["WienerHammerstein"]

DIVERGENCE_FACTOR = 1e3  # a simulation leaving this multiple of max|y| has diverged
DIVERGED_RESIDUAL = 1e3  # residual (times max|y|) of every sample of a diverged trial
KNOT_MARGIN = 1.0  # spline interval: the extremes of x ± this × RMS(x)
RESTAGES = 2  # most extra searches, each after placing the knots again, while x leaves the spline's interval


def _int_option(name: str, value: Any, low: int) -> int:
    return int_option("wh-bla", name, value, low)


class WienerHammerstein(Identifier):
    """G1 → cubic spline → G2, started from the best split of the BLA's poles and zeros (module docstring).

    Parameters
    ----------
    nb, nf, nk : int
        Orders of the BLA (output-error model): numerator coefficients, poles, input delay (samples).
    knots : int
        Inner knots of the static spline f (at quantiles of x; f has ``knots + 4`` coefficients).
    extra_zeros : int
        Numerator coefficients appended to each of B1 and B2 before the refinement.
    split_samples : int
        Leading samples of the first record on which the splits are scored (0: all).
    warmup : int
        Leading samples of every record out of the cost and copied in predictions (``max_lag_``).
    max_nfev : int
        Most simulations of the Levenberg–Marquardt refinement (0: the best split is the model).
    xtol, ftol : float
        Relative step / cost tolerances of the refinement.
    """

    name = "wh-bla"

    def __init__(
        self,
        nb: int = 7,
        nf: int = 6,
        nk: int = 0,
        knots: int = 30,
        extra_zeros: int = 2,
        split_samples: int = 20000,
        warmup: int = 50,
        max_nfev: int = 400,
        xtol: float = 1e-8,
        ftol: float = 1e-10,
    ):
        self.nb = nb
        self.nf = nf
        self.nk = nk
        self.knots = knots
        self.extra_zeros = extra_zeros
        self.split_samples = split_samples
        self.warmup = warmup
        self.max_nfev = max_nfev
        self.xtol = xtol
        self.ftol = ftol

    # ------------------------------------------------------------------ fitting
    def _check_options(self) -> dict[str, int]:
        out = {
            k: _int_option(k, getattr(self, k), low)
            for k, low in (
                ("nb", 1),
                ("nf", 1),
                ("nk", 0),
                ("knots", 1),
                ("extra_zeros", 0),
                ("split_samples", 0),
                ("warmup", 0),
                ("max_nfev", 0),
            )
        }
        for k in ("xtol", "ftol"):
            v = getattr(self, k)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                raise ConfigError(f"wh-bla: {k}={v!r} must be a positive number")
        return out

    def fit(self, data: Record | Sequence[Record]) -> WienerHammerstein:
        from sysid.linear.pem import OE

        o = self._check_options()
        records = as_record_list(data)
        if records[0].n_inputs != 1 or records[0].n_outputs != 1:
            raise DataError(
                f"wh-bla: one input and one output only; the data have {records[0].n_inputs} / {records[0].n_outputs}"
            )
        n_par = o["nb"] + o["nf"] + o["knots"] + 4 + 2 * o["extra_zeros"]
        check_records(records, o["warmup"] + o["nb"] + o["nf"] + o["nk"], n_par + 1, self.name)
        us = [r.u.reshape(-1).astype(float) for r in records]
        ys = [r.output.reshape(-1).astype(float) for r in records]
        self.n_inputs_, self.n_outputs_ = 1, 1
        self.y_bound_ = DIVERGENCE_FACTOR * max(float(np.max(np.abs(np.concatenate(ys)))), 1e-300)
        bla = OE(nb=o["nb"], nf=o["nf"], nk=o["nk"]).fit(records)
        self.bla_ = {"b": np.asarray(bla.b_[0], float), "a": np.asarray(bla.f_[0], float)}
        g1, f, c, g2, cost = self._best_split(self.bla_["b"], self.bla_["a"], o, us[0], ys[0])
        self.split_ = {
            "rms": cost,
            "g1_poles": len(g1.a) - 1,
            "g2_poles": len(g2.a) - 1,
            "g1_zeros": len(g1.zeros()),
            "g2_zeros": len(g2.zeros()),
        }
        stages: list[dict[str, Any]] = []
        f, c = self._spline_on_all(g1, g2, us, ys, o)
        for k in range(2 + RESTAGES):
            if k == 1 and o["extra_zeros"]:
                g1.b, g2.b = np.r_[g1.b, np.zeros(o["extra_zeros"])], np.r_[g2.b, np.zeros(o["extra_zeros"])]
            elif k >= 1 and self._inside(g1, f, us, o):
                break  # a further search only while x leaves the spline's interval
            if k >= 1:
                f, c = self._spline_on_all(g1, g2, us, ys, o)
            g1, c, g2, info = self._refine(g1, f, c, g2, us, ys, o)
            stages.append(info)
        self.g1_, self.c_, self.g2_, self.spline_ = g1, c, g2, f
        self.optimisation_ = {**stages[-1], "converged": all(s["converged"] for s in stages), "stages": stages}
        self._set_common()
        return self

    def _best_split(self, b: np.ndarray, a: np.ndarray, o: dict[str, int], u: np.ndarray, y: np.ndarray):
        """Step 2 of the module docstring: (G1, f, c, G2, RMS) of the best split on the leading samples."""
        n = len(u) if o["split_samples"] == 0 else min(len(u), o["split_samples"])
        u, y, w0 = u[:n], y[:n], min(o["warmup"], n // 2)
        try:
            bla = wb.Filter(b, a)
            candidates = list(wb.splits(bla.zeros(), bla.poles()))
        except ValueError as exc:
            raise ConfigError(f"wh-bla: {exc}") from None
        best: tuple | None = None
        for b1, a1, b2, a2 in candidates:
            g1 = wb.Filter(b1, a1, o["nk"])
            x = g1(u)
            s = float(np.sqrt(np.mean(x[w0:] ** 2)))
            if not np.isfinite(s) or s == 0.0:
                continue
            g1.b = b1 / s
            x = x / s
            g2 = wb.Filter(b2, a2)
            s2 = float(np.sqrt(np.mean(g2(x)[w0:] ** 2)))
            if not np.isfinite(s2) or s2 == 0.0:
                continue
            g2.b = b2 / s2
            f = wb.Spline.at_quantiles(x[w0:], o["knots"], KNOT_MARGIN)
            Phi = g2(f.basis(x))[w0:]
            c = np.linalg.lstsq(Phi, y[w0:], rcond=None)[0]
            rms = float(np.sqrt(np.mean((y[w0:] - Phi @ c) ** 2)))
            if best is None or rms < best[-1]:
                best = (g1, f, c, g2, rms)
        if best is None:
            raise DataError("wh-bla: no split of the BLA gives a finite, non-zero intermediate signal")
        return best

    @staticmethod
    def _inside(g1: wb.Filter, f: wb.Spline, us, o) -> bool:
        """Whether x = G1 u stays inside the spline's knot interval on every record (after the warm-up)."""
        w0 = o["warmup"]
        return all(f.lo <= float(np.min(x[w0:])) and float(np.max(x[w0:])) <= f.hi for x in (g1(u) for u in us))

    @staticmethod
    def _spline_on_all(g1: wb.Filter, g2: wb.Filter, us, ys, o) -> tuple[wb.Spline, np.ndarray]:
        """The spline's knots at quantiles of x over every record (the split saw only the leading samples) and its
        coefficients by linear least squares on all of them."""
        w0 = o["warmup"]
        xs = [g1(u) for u in us]
        f = wb.Spline.at_quantiles(np.concatenate([x[w0:] for x in xs]), o["knots"], KNOT_MARGIN)
        Phi = np.vstack([g2(f.basis(x))[w0:] for x in xs])
        c = np.linalg.lstsq(Phi, np.concatenate([y[w0:] for y in ys]), rcond=None)[0]
        return f, c

    def _refine(self, g1: wb.Filter, f: wb.Spline, c: np.ndarray, g2: wb.Filter, us, ys, o):
        """One Levenberg–Marquardt search of step 3 (module docstring): (G1, c, G2, summary)."""
        j2 = int(np.argmax(np.abs(g2.b)))
        free1 = np.arange(len(g1.b))  # every coefficient of B1 (module docstring: why G1's gain stays free)
        free2 = np.array([i for i in range(len(g2.b)) if i != j2], dtype=int)
        n1b, n1a, n2a, nc = len(g1.b), len(g1.a) - 1, len(g2.a) - 1, len(c)
        w0 = o["warmup"]
        scale = self.y_bound_ / DIVERGENCE_FACTOR

        def unpack(th: np.ndarray):
            b1 = th[:n1b]
            i = n1b
            a1 = np.r_[1.0, th[i : i + n1a]]
            i += n1a
            cc = th[i : i + nc]
            i += nc
            b2 = g2.b.copy()
            b2[free2] = th[i : i + len(free2)]
            i += len(free2)
            a2 = np.r_[1.0, th[i : i + n2a]]
            return wb.Filter(b1, a1, g1.nk), cc, wb.Filter(b2, a2, g2.nk)

        def fun(th: np.ndarray) -> np.ndarray:
            h1, cc, h2 = unpack(th)
            out = []
            with np.errstate(all="ignore"):
                for u, y in zip(us, ys):
                    e = (wb.simulate(h1, f, cc, h2, u)[0] - y)[w0:]
                    bad = ~(np.abs(e) <= self.y_bound_)
                    if bad.any():
                        e = np.where(np.arange(e.size) >= np.argmax(bad), DIVERGED_RESIDUAL * scale, e)
                    out.append(e)
            return np.concatenate(out)

        def jac(th: np.ndarray) -> np.ndarray:
            h1, cc, h2 = unpack(th)
            with np.errstate(all="ignore"):
                J = np.vstack([wb.jacobian(h1, f, cc, h2, u, free1, free2)[1][w0:] for u in us])
            return np.nan_to_num(J, nan=0.0, posinf=0.0, neginf=0.0)

        th0 = np.concatenate([g1.b, g1.a[1:], c, g2.b[free2], g2.a[1:]])
        r0 = fun(th0)
        cost0 = float(np.mean(r0**2))
        info: dict[str, Any] = {"start_rms": float(np.sqrt(cost0)), "nfev": 0, "status": "start", "converged": False}
        th, cost_kept = th0, cost0
        if o["max_nfev"] > 0:
            res = least_squares(
                fun,
                th0,
                jac=jac,
                method="lm",
                x_scale="jac",
                max_nfev=o["max_nfev"],
                xtol=float(self.xtol),
                ftol=float(self.ftol),
            )
            cost = float(np.mean(res.fun**2))
            info.update(nfev=int(res.nfev), status=str(res.message), converged=bool(res.status > 0))
            if np.isfinite(cost) and cost <= cost0:
                th, cost_kept = res.x, cost
            else:
                info["status"] = "refinement ended worse than its start; the best split is kept"
        h1, cc, h2 = unpack(th)
        info["rms"] = float(np.sqrt(cost_kept))
        return h1, cc, h2, info

    def _set_common(self) -> None:
        self.max_lag_ = int(self.warmup)
        self.diverged_at_ = None
        # B1, A1 less its leading 1, f, B2 less its pinned coefficient, A2 less its leading 1
        self.n_parameters_ = int(
            len(self.g1_.b) + len(self.g1_.a) - 1 + len(self.c_) + len(self.g2_.b) - 1 + len(self.g2_.a) - 1
        )

    # ------------------------------------------------------------------ prediction
    def _check_fitted(self) -> None:
        if not hasattr(self, "g1_"):
            raise ConfigError("wh-bla: model is not fitted (call fit first)")

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """Free run from rest for every ``horizon`` (an output-error model); the first ``max_lag_`` samples are the
        measurement's."""
        self._check_fitted()
        check_prediction(self, record, horizon)
        y = record.output.reshape(-1).astype(float)
        with np.errstate(all="ignore"):
            yhat = wb.simulate(self.g1_, self.spline_, self.c_, self.g2_, record.u.reshape(-1).astype(float))[0]
        L = min(self.max_lag_, len(y))
        yhat[:L] = y[:L]
        return stop_at_divergence(self, yhat, "simulation").reshape(record.output.shape)

    # ------------------------------------------------------------------ reporting
    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "g1_"):

            def roots(r: np.ndarray) -> list[dict[str, float]]:
                return [{"re": float(z.real), "im": float(z.imag), "abs": float(abs(z))} for z in r]

            d.update(
                g1={
                    "b": self.g1_.b.tolist(),
                    "a": self.g1_.a.tolist(),
                    "nk": self.g1_.nk,
                    "poles": roots(self.g1_.poles()),
                    "zeros": roots(self.g1_.zeros()),
                },
                g2={
                    "b": self.g2_.b.tolist(),
                    "a": self.g2_.a.tolist(),
                    "nk": self.g2_.nk,
                    "poles": roots(self.g2_.poles()),
                    "zeros": roots(self.g2_.zeros()),
                },
                spline={"knots": self.spline_.inner.tolist(), "coefficients": self.c_.tolist()},
                split=dict(self.split_),
                optimisation=dict(self.optimisation_),
                max_lag=self.max_lag_,
                terms=[],
            )
        return d

    # ------------------------------------------------------------------ persistence
    def _state(self) -> dict[str, Any]:
        return {
            "g1": {"b": self.g1_.b.tolist(), "a": self.g1_.a.tolist(), "nk": self.g1_.nk},
            "g2": {"b": self.g2_.b.tolist(), "a": self.g2_.a.tolist(), "nk": self.g2_.nk},
            "knots": self.spline_.inner.tolist(),
            "c": self.c_.tolist(),
            "bla": {k: v.tolist() for k, v in self.bla_.items()},
            "split": self.split_,
            "optimisation": self.optimisation_,
            "y_bound": self.y_bound_,
        }

    def _load_state(self, state: dict[str, Any]) -> None:
        self.g1_, self.g2_ = (
            wb.Filter(np.asarray(state[g]["b"], float), np.asarray(state[g]["a"], float), int(state[g]["nk"]))
            for g in ("g1", "g2")
        )
        self.spline_ = wb.Spline(np.asarray(state["knots"], float))
        self.c_ = np.asarray(state["c"], float)
        self.bla_ = {k: np.asarray(v, float) for k, v in state["bla"].items()}
        self.split_ = dict(state["split"])
        self.optimisation_ = dict(state["optimisation"])
        self.y_bound_ = float(state["y_bound"])
        self.n_inputs_, self.n_outputs_ = 1, 1
        self._set_common()
