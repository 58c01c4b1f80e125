"""Sample-by-sample free run of a fitted model: ``step(u_k) -> ŷ(k)`` (for FMUs and other real-time hosts).

The stepper reproduces ``model.predict(u)`` (free run from zero initial conditions, eq. 2-29) one sample at a
time: for ``k < max_lag_`` it returns the zero initial condition, afterwards the model's simulated output. It
keeps the last ``max_lag_ + 1`` samples and runs the model's *own* compiled free-run kernel on that window
(:func:`sysid.polynomial.simulate.free_run` for the polynomial family — ARX, ARMAX, NARX, NARMAX — and
:func:`sysid.neural.core.free_run_mlp` for the NARX networks, in their normalised units), so every sample is
computed by the same arithmetic in the same order as the whole-record free run: the two agree bit for bit.

Supported: every identifier whose free run is a function of a finite past (``arx``, ``armax``, ``narx-poly``,
``narmax-poly``, ``narx-mlp``, ``narx-mlp-sim``), ``pnlss``, whose state is carried from one sample to the
next through its own compiled kernel (:func:`sysid.nonlinear.pnlss_sim.simulate` with ``final_state``), and
``wh-bla``, whose
two filters carry their ``scipy.signal.lfilter`` states from one sample to the next. The recurrent
``rnn`` (a hidden state started by an encoder) is not.
"""

from __future__ import annotations

import math

import numpy as np

from sysid.errors import ConfigError

__all__ = ["make_stepper", "STEPPABLE", "MULTI_INPUT"]

STEPPABLE = ("arx", "armax", "narx-poly", "narmax-poly", "narx-mlp", "narx-mlp-sim", "pnlss", "wh-bla")
#: identifiers whose stepper takes several inputs (one output)
MULTI_INPUT = ("arx", "armax", "narx-poly", "narmax-poly")


class _WindowStepper:
    """Shared ring of the last ``L + 1`` inputs and outputs (``n_in`` input channels, one output)."""

    def __init__(self, L: int, n_in: int = 1):
        self.L = int(L)
        self.u = np.zeros((self.L + 1, int(n_in)))
        self.y = np.zeros((self.L + 1, 1))
        self.k = 0

    def reset(self) -> None:
        self.u[:] = 0.0
        self.y[:] = 0.0
        self.k = 0

    def _push_u(self, value) -> None:
        """``value``: a number, or one number per input channel."""
        self.u[:-1] = self.u[1:]
        self.u[-1] = value

    def _push_y(self, value: float) -> None:
        self.y[:-1] = self.y[1:]
        self.y[-1, 0] = value


class PolynomialStepper(_WindowStepper):
    """The polynomial family; several inputs (a multi-input single-output model, e.g. the remainder of a hybrid
    twin on [u, ŷ_twin]) are passed to :meth:`step` as one number per input, in the model's input order."""

    def __init__(self, model):
        super().__init__(model.max_lag_, int(getattr(model, "n_inputs_", 1)))
        self.compiled = model.compiled()
        self.bound = float(model.y_bound_)

    def step(self, u) -> float:
        from sysid.polynomial.simulate import free_run

        self._push_u(float(u) if self.u.shape[1] == 1 else np.asarray(u, dtype=float).reshape(-1))
        self._push_y(0.0)  # rows are now times k-L .. k; the last output is what this step computes
        if self.k >= self.L:  # before: the zero initial conditions, as predict(u) without y
            yw, _ = free_run(self.compiled, self.u, self.y, self.bound)
            self.y[-1, 0] = yw[-1, 0]
        self.k += 1
        return float(self.y[-1, 0])


class NeuralNARXStepper(_WindowStepper):
    """Works in the model's normalised units (as its free run does) and scales each output back."""

    def __init__(self, model):
        from sysid.neural.core import ACT_CODE

        super().__init__(model.max_lag_)
        self.m = model
        self.code = ACT_CODE[model.activation]
        self.norm = model.normaliser_
        self.y0n = float(self.norm.transform_y(np.zeros((1, 1)))[0, 0])  # normalised zero initial condition
        self.y[:] = self.y0n

    def reset(self) -> None:
        super().reset()
        self.y[:] = self.y0n

    def step(self, u: float) -> float:
        from sysid.neural.core import free_run_mlp
        from sysid.neural.records import DIVERGENCE_BOUND

        m = self.m
        self._push_u(float(self.norm.transform_u(np.array([[float(u)]]))[0, 0]))
        self._push_y(self.y0n)  # rows are now times k-L .. k
        if self.k < self.L:
            self.k += 1
            return 0.0
        yw, _ = free_run_mlp(
            m.weights_, m.sizes_, self.code, self.y, self.u, m.ny, m.nu, DIVERGENCE_BOUND, m.nk, m.linear
        )
        vn = float(yw[-1, 0])
        self.y[-1, 0] = vn
        self.k += 1
        return float(self.norm.inverse_y(np.array([[vn]]))[0, 0]) if math.isfinite(vn) else float("nan")


class StateSpaceStepper:
    """PNLSS: the state from the model's input-only start (``model.predict(u)``), advanced one sample per step by
    the compiled kernel; outputs before ``max_lag_`` are the zero initial conditions, as in the free run."""

    def __init__(self, model):
        self.model = model
        self.reset()

    def reset(self) -> None:
        self.x = np.mean(self.model.x0_, axis=0).astype(float)
        self.k = 0

    def step(self, u: float) -> float:
        from sysid.nonlinear import pnlss_sim as ps

        m = self.model
        A, B, E, C, D, F = m._unpack(m._pack())
        with np.errstate(all="ignore"):
            y, _, _, self.x = ps.simulate(
                A,
                B,
                C,
                D,
                E,
                F,
                m.facE_,
                m.facF_,
                np.array([[u]]) / m.u_scale_,
                self.x,
                m.bound_,
                False,
                final_state=True,
            )
        self.k += 1
        return 0.0 if self.k <= m.max_lag_ else float(y[0, 0] * m.y_scale_[0])


class BlockStepper:
    """Wiener–Hammerstein (``wh-bla``): G1 and G2 advanced one sample per step with their ``lfilter`` states (the
    delays as short input queues), the spline between; outputs before ``max_lag_`` are the zero initial
    conditions, as in the free run."""

    def __init__(self, model):
        from scipy.signal import lfilter

        self.model = model
        self._lfilter = lfilter  # imported once here, not on every sample
        self.reset()

    def reset(self) -> None:
        m = self.model
        self.z = [np.zeros(max(len(g.a), len(g.b)) - 1) for g in (m.g1_, m.g2_)]
        self.queues = [np.zeros(g.nk) for g in (m.g1_, m.g2_)]  # v(k-1), ..., v(k-nk)
        self.k = 0

    def _filter(self, i: int, g, v: float) -> float:
        q = self.queues[i]
        if q.size:
            v, q[1:], q[0] = float(q[-1]), q[:-1].copy(), v
        if self.z[i].size == 0:
            return float(g.b[0] * v)
        out, self.z[i] = self._lfilter(g.b, g.a, [v], zi=self.z[i])
        return float(out[0])

    def step(self, u: float) -> float:
        m = self.model
        x = self._filter(0, m.g1_, float(u))
        w = float(m.spline_(np.array([x]), m.c_)[0])
        y = self._filter(1, m.g2_, w)
        self.k += 1
        return 0.0 if self.k <= m.max_lag_ else y


def make_stepper(model):
    """A fresh stepper (state at rest) for a fitted single-output ``model`` (several inputs: :data:`MULTI_INPUT`)."""
    if model.name not in STEPPABLE:
        raise ConfigError(f"{model.name}: no per-sample stepper (an FMU needs one); supported: {', '.join(STEPPABLE)}")
    n_in, n_out = int(getattr(model, "n_inputs_", 1)), int(getattr(model, "n_outputs_", 1))
    if n_out != 1 or (n_in != 1 and model.name not in MULTI_INPUT):
        raise ConfigError(
            f"{model.name}: the stepper handles one output, and several inputs only for "
            f"{', '.join(MULTI_INPUT)}; the model has {n_in} / {n_out}"
        )
    if model.name.startswith("narx-mlp"):
        return NeuralNARXStepper(model)
    if model.name == "pnlss":
        return StateSpaceStepper(model)
    if model.name == "wh-bla":
        return BlockStepper(model)
    return PolynomialStepper(model)
