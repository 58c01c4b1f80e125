"""The cantilever micromanipulator twin (dissertation §3.1 and ch. 4; physics notes part A)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from sysid.data.record import Record, check_array
from sysid.errors import ConfigError, DataError
from twins.base import Twin
from twins.cantilever import cache
from twins.cantilever import kernels as K
from twins.cantilever.effects import EFFECTS
from twins.cantilever.params import CantileverParams
from twins.cantilever.protocols import BUILDERS, PROTOCOLS

__all__ = ["CantileverTwin", "CantileverStepper"]

#: the additive drift after the sensor: its effects and parameters (the cached base output excludes them)
_DRIFT_EFFECTS = frozenset({"thermal_drift", "slow_drift"})
_DRIFT_FIELDS = frozenset(
    {"thermal_drift_um", "thermal_tau_s", "drift_rate_um_per_s", "drift_sin_um", "drift_cos_um", "drift_period_s"}
)


class CantileverTwin(Twin):
    """Piezo cantilever micromanipulator: amplifier → hysteresis + creep → two-mode D(s) → sensor (y in µm).

    Chain (physics notes A.1, Rakotondrabe et al. 2010): u [V] → delay → amplifier (soft saturation, clip at
    ±amp_limit_v, first-order bandwidth) → v → Γ[v] (Bouc–Wen, Low & Guo form with n = 1, or
    Prandtl–Ishlinskii; ``hysteresis`` parameter) + Cr(s)·v (Kelvin–Voigt creep chain reproducing the log
    law) → D(s) = φ₁ω₁²/(s² + 2ζ₁ω₁s + ω₁²) + φ₂ω₂²/(s² + 2ζ₂ω₂s + ω₂²) with ω₂ = 6.27ω₁, φ = 0.92/0.08,
    D(0) = 1 → sensor 2nd-order Butterworth low-pass (5 kHz) + offset + drift + noise + 10 nm quantiser
    → y [µm] sampled at fs (any fs; the input is a first-order hold between samples).

    Default configuration (effects on): creep, second_mode, sensor_lowpass, sensor_quantization,
    measurement_noise — the dissertation's bench as described in §3.1. Off by default (for the discrepancy
    analysis to find): input_delay, thermal_drift, slow_drift, saturation, rate_dependent_hysteresis,
    asymmetric_hysteresis, amplifier_bandwidth. ``--effects none`` is the noise-free core: hysteresis,
    single-mode D(s), clip, offset.

    Integration: every linear part is discretised exactly (matrix exponential, first-order hold); the
    Bouc–Wen ODE is integrated in closed form for the piecewise-linear input; sub-steps of at most
    ``max_substep_s`` (10 µs) inside each sample; one numba kernel shared by :meth:`simulate` and
    :meth:`make_stepper`. Deterministic for a seed (the seed only drives the measurement noise).
    """

    name = "cantilever"
    Params = CantileverParams
    EFFECTS = EFFECTS
    PROTOCOLS = PROTOCOLS
    units = {"u": "V", "y": "um"}
    #: fitted by ``piezotwin calibrate`` (Bouc–Wen; with hysteresis=prandtl-ishlinskii the PI weights replace α, β, γ)
    CALIBRATION_PARAMS = (
        "gain_um_per_v",
        "bw_alpha",
        "bw_beta",
        "bw_gamma",
        "f1_hz",
        "zeta1",
        "creep_per_decade",
        "offset_um",
        "initial_state_um",
    )
    #: the remanent hysteresis state a record starts in (the actuator's history before it): per record
    INITIAL_CONDITION_PARAMS = ("initial_state_um",)
    #: parameters that may change while a simulation runs (FMU ``tunable``, :meth:`CantileverStepper.retune`):
    #: every real-valued field except the three that are not a property of the running physics:
    #: ``input_delay_s`` (sets the length of the delay buffer, a state), ``max_substep_s`` (sets the number
    #: of sub-steps, the length of a state array) and ``initial_state_um`` (an initial condition, used only
    #: at rest). Integers (``pi_operators``, ``creep_elements``: array lengths) and ``hysteresis`` (which
    #: operator's state is live) are structural as well.
    TUNABLE_PARAMS = tuple(
        f.name
        for f in dataclasses.fields(CantileverParams)
        if f.type in ("float", float) and f.name not in ("input_delay_s", "max_substep_s", "initial_state_um")
    )

    #: parameters that enter the output additively and linearly (the drifts' sizes: the slow drift's coefficients
    #: and the settling drift's final value): a calibration solves them by linear least squares for each value of
    #: the others (:mod:`twins.calibration`)
    OUTPUT_LINEAR_PARAMS = ("drift_rate_um_per_s", "drift_sin_um", "drift_cos_um", "thermal_drift_um")
    #: the parameters that shape only their basis (the cycle's period, the settling time constant), each scanned on
    #: a log grid before the search (:mod:`twins.calibration`)
    OUTPUT_BASIS_SHAPE_PARAMS = ("drift_period_s", "thermal_tau_s")

    def __init__(self, params: Any = None, effects: Iterable[str] | None = None, seed: int | None = 0):
        super().__init__(params, effects, seed)
        self._cache: dict[float, dict[str, Any]] = {}

    def output_basis(self, name: str, n: int, fs: float) -> np.ndarray | None:
        """d y[k]/d ``name`` at the samples k = 0 … n−1 (rate ``fs``) for a parameter of
        :data:`OUTPUT_LINEAR_PARAMS`, or None when its effect is off (then it does not act)."""
        if name == "thermal_drift_um":
            if not self.has("thermal_drift"):
                return None
            # the kernel's D·(1 − e^(−t/τ)), as it computes it (−expm1)
            return -np.expm1(-(np.arange(n) * (1.0 / float(fs))) / self.params.thermal_tau_s)
        if name not in self.OUTPUT_LINEAR_PARAMS or not self.has("slow_drift"):
            return None
        t = np.arange(n) * (1.0 / float(fs))
        w = 2 * math.pi / self.params.drift_period_s
        if name == "drift_rate_um_per_s":
            return t
        return np.sin(w * t) if name == "drift_sin_um" else 1.0 - np.cos(w * t)

    # ------------------------------------------------------------------ derived quantities
    def pi_weights(self) -> tuple[np.ndarray, float, np.ndarray]:
        """Thresholds r_i (i = 1…n) [V], linear weight p_0 and play weights p_i [µm/V] of the PI operator.

        p_0 = pi_p0_fraction·d and p_i ∝ exp(−pi_decay·i) with Σ_{i≥1} p_i = (1 − pi_p0_fraction)·d, so the
        slope of a loop larger than r_max is d (physics notes A.4).
        """
        p = self.params
        n = int(p.pi_operators)
        i = np.arange(1, n + 1)
        r = i * p.pi_r_max_v / n
        w = np.exp(-p.pi_decay * i)
        pi = (1.0 - p.pi_p0_fraction) * p.gain_um_per_v * w / w.sum()
        return r, p.pi_p0_fraction * p.gain_um_per_v, pi

    def creep_taus(self) -> np.ndarray:
        p = self.params
        return p.creep_tau_min_s * 10.0 ** np.arange(int(p.creep_elements))

    def effect_frequency_hz(self, effect: str, params: dict[str, float]) -> float | None:
        """The frequency [Hz] an effect stands for (:mod:`twins.discrepancy.band`): the second mode's f₂ =
        mode_ratio·f₁; None for the others (their parameters in Hz are used)."""
        if effect != "second_mode":
            return None
        return float(params.get("mode_ratio", self.params.mode_ratio)) * float(self.params.f1_hz)

    def linear_system(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Continuous (A, B, C) of D(s) followed by the sensor low-pass; states [x₁, ẋ₁, x₂, ẋ₂, s, ṡ]."""
        p = self.params
        w1 = 2 * math.pi * p.f1_hz
        w2 = p.mode_ratio * w1
        share2 = p.mode2_share if self.has("second_mode") else 0.0
        ws = 2 * math.pi * p.sensor_bandwidth_hz
        A = np.zeros((K.NZ, K.NZ))
        B = np.zeros(K.NZ)
        A[0, 1] = 1.0
        A[1, 0], A[1, 1] = -w1 * w1, -2 * p.zeta1 * w1
        B[1] = w1 * w1 * (1.0 - share2)
        A[2, 3] = 1.0
        A[3, 2], A[3, 3] = -w2 * w2, -2 * p.zeta2 * w2
        B[3] = w2 * w2 * share2
        A[4, 5] = 1.0
        A[5, 4], A[5, 5] = -ws * ws, -math.sqrt(2.0) * ws
        A[5, 0] = A[5, 2] = ws * ws
        C = np.zeros(K.NZ)
        if self.has("sensor_lowpass"):
            C[4] = 1.0
        else:
            C[0] = C[2] = 1.0
        return A, B, C

    def frequency_response(self, f_hz: np.ndarray) -> np.ndarray:
        """Complex response of D(s)·sensor (normalised, 1 at DC) at ``f_hz`` (linear part only)."""
        A, B, C = self.linear_system()
        s = 2j * np.pi * np.atleast_1d(np.asarray(f_hz, dtype=float))
        eye = np.eye(A.shape[0])
        return np.array([C @ np.linalg.solve(si * eye - A, B) for si in s])

    def sampled_frequency_response(self, f_hz: np.ndarray, fs: float) -> np.ndarray:
        """Exact FRF from the input samples u[k] [V] to the noise-free output samples y[k] [µm] at ``fs`` of
        the twin with its hysteresis replaced by the line Γ = d·v (d = ``gain_um_per_v``).

        This is the response :meth:`simulate` produces when Γ is linear — ``hysteresis=prandtl-ishlinskii``
        with ``pi_p0_fraction=1`` (all weight on the r = 0 operator) and no clip (|u| < ``amp_limit_v``) —
        including the sampling: the input is a first-order hold between samples, so every linear part is
        the FOH discretisation (:func:`kernels.foh_discretise`, Franklin & Powell §6.3) evaluated at
        z = e^{j2πf/fs}:

        H(z) = z^{-D}((1 − μ) + μz^{-1}) · d·(1 + Σ_i g_i (b1_i + b0_i z^{-1})/(1 − a_i z^{-1}))
               · C (I − Φ z^{-1})^{-1} (G1 + G0 z^{-1})

        with the input delay D + μ samples (effect ``input_delay``), the Kelvin–Voigt creep elements
        (effect ``creep``) and (Φ, G0, G1) of D(s)·sensor over one sample. The sub-steps of the kernel change
        nothing: a force linear over the sample is linear over every sub-step. Refused for
        ``amplifier_bandwidth`` (its output is not linear between samples) and for ``saturation``.
        """
        for eff in ("amplifier_bandwidth", "saturation"):
            if self.has(eff):
                raise ConfigError(f"cantilever: no exact sampled FRF with the effect {eff}; remove it")
        fs = float(fs)
        p = self.params
        T = 1.0 / fs
        zi = np.exp(-2j * np.pi * np.atleast_1d(np.asarray(f_hz, dtype=float)) / fs)  # z^{-1}
        A, B, C = self.linear_system()
        Phi, G0, G1 = K.foh_discretise(A, B, T)
        eye = np.eye(A.shape[0])
        lin = np.array([C @ np.linalg.solve(eye - Phi * q, G1 + G0 * q) for q in zi])
        force = np.full(zi.shape, p.gain_um_per_v, dtype=complex)
        if self.has("creep"):
            for tau in self.creep_taus():
                a, b0, b1 = _first_order_foh(tau, T)
                force += p.gain_um_per_v * p.creep_per_decade * (b1 + b0 * zi) / (1.0 - a * zi)
        delay = np.ones(zi.shape, dtype=complex)
        if self.has("input_delay"):
            dl = p.input_delay_s * fs
            D = int(math.floor(dl + 1e-12))
            mu = max(0.0, dl - D)
            delay = zi**D * ((1.0 - mu) + mu * zi)
        return delay * force * lin

    def substeps(self, fs: float) -> int:
        return max(1, int(math.ceil(1.0 / (fs * self.params.max_substep_s) - 1e-9)))

    # ------------------------------------------------------------------ discretisation (cached per fs)
    def _config(self, fs: float) -> dict[str, Any]:
        fs = float(fs)
        if fs in self._cache:
            return self._cache[fs]
        p = self.params
        T = 1.0 / fs
        M = self.substeps(fs)
        h = T / M
        A, B, C = self.linear_system()
        Phi, G0, G1 = cache.discretise(A, B, h)
        icfg = np.zeros(K.N_ICFG, dtype=np.int64)
        fcfg = np.zeros(K.N_FCFG)
        icfg[K.I_M] = M
        delay = p.input_delay_s * fs if self.has("input_delay") else 0.0
        D = int(math.floor(delay + 1e-12))
        mu = max(0.0, delay - D)
        if mu < 1e-12:
            mu = 0.0
        icfg[K.I_DELAY] = D
        fcfg[K.F_MU] = mu
        icfg[K.I_HYST] = 0 if p.hysteresis == "bouc-wen" else 1
        r, p0, pw = self.pi_weights()
        icfg[K.I_NPI] = r.size
        taus = self.creep_taus()
        icfg[K.I_NCR] = taus.size if self.has("creep") else 0
        icfg[K.I_SAT] = self.has("saturation")
        icfg[K.I_AMPLP] = self.has("amplifier_bandwidth")
        icfg[K.I_RATE] = self.has("rate_dependent_hysteresis")
        icfg[K.I_ASYM] = self.has("asymmetric_hysteresis")
        icfg[K.I_DRIFT] = self.has("thermal_drift") or self.has("slow_drift")
        icfg[K.I_QUANT] = self.has("sensor_quantization")
        fcfg[K.F_T], fcfg[K.F_H] = T, h
        fcfg[K.F_VS], fcfg[K.F_SATP], fcfg[K.F_LIM] = p.sat_voltage_v, p.sat_sharpness, p.amp_limit_v
        a_lp, b0_lp, b1_lp = _first_order_foh(1.0 / (2 * math.pi * p.amp_bandwidth_hz), h)
        fcfg[K.F_LPA], fcfg[K.F_LPB0], fcfg[K.F_LPB1] = a_lp, b0_lp, b1_lp
        fcfg[K.F_D], fcfg[K.F_ALPHA], fcfg[K.F_BETA], fcfg[K.F_GAMMA] = (
            p.gain_um_per_v,
            p.bw_alpha,
            p.bw_beta,
            p.bw_gamma,
        )
        fcfg[K.F_RATEREF], fcfg[K.F_ASYM] = p.rate_ref_v_per_s, p.asym_factor
        fcfg[K.F_OFFSET], fcfg[K.F_DRIFTTAU] = p.offset_um, p.thermal_tau_s
        fcfg[K.F_DRIFT] = p.thermal_drift_um if self.has("thermal_drift") else 0.0
        if self.has("slow_drift"):
            fcfg[K.F_DRATE], fcfg[K.F_DSIN], fcfg[K.F_DCOS] = p.drift_rate_um_per_s, p.drift_sin_um, p.drift_cos_um
        fcfg[K.F_DOMEGA] = 2 * math.pi / p.drift_period_s
        fcfg[K.F_Q] = p.quant_um
        fcfg[K.F_RATEA] = math.exp(-h / p.rate_tau_s)
        cr = np.array([_first_order_foh(tau, T) for tau in taus]).reshape(-1, 3)
        cfg: dict[str, Any] = dict(
            icfg=icfg,
            fcfg=fcfg,
            Phi=np.ascontiguousarray(Phi),
            G0=G0,
            G1=G1,
            Cout=C,
            cr_a=cr[:, 0].copy(),
            cr_b0=cr[:, 1].copy(),
            cr_b1=cr[:, 2].copy(),
            cr_g=np.full(taus.size, p.creep_per_decade),
            pi_r=r,
            pi_p=np.concatenate(([p0], pw)),
            buf_len=D + 2,
            M=M,
        )
        self._cache[fs] = cfg
        return cfg

    def _fresh_state(self, cfg: dict[str, Any]) -> dict[str, np.ndarray]:
        """States at rest at 0 V, in equilibrium with the initial hysteresis output Γ₀ = initial_state_um."""
        st = dict(
            sc=np.zeros(K.N_SCAL),
            z=np.zeros(K.NZ),
            xc=np.zeros(max(1, cfg["cr_a"].size)),
            play=np.zeros(max(1, cfg["pi_r"].size)),
            buf=np.zeros(cfg["buf_len"]),
            vsub=np.zeros(cfg["M"] + 1),
        )
        g0 = float(self.params.initial_state_um)
        if g0 != 0.0:
            if self.params.hysteresis == "bouc-wen":
                st["sc"][K.S_H] = -g0
            else:  # plays F_i = κ r_i, |κ| ≤ 1 (the state left by a partial excursion), Σ p_i F_i = Γ₀
                r, pw = cfg["pi_r"], cfg["pi_p"][1:]
                kappa = float(np.clip(g0 / float(np.sum(pw * r)), -1.0, 1.0))
                st["play"][: r.size] = kappa * r
                g0 = float(np.sum(pw * st["play"][: r.size]))
            A, B, _ = self.linear_system()
            st["z"][:] = np.linalg.solve(A, -B * g0)  # equilibrium of the linear part for f = Γ₀
            st["sc"][K.S_FPREV] = g0
        return st

    # ------------------------------------------------------------------ simulation
    def simulate(self, u: np.ndarray, fs: float) -> np.ndarray:
        """Displacement y [µm] for the voltage samples ``u`` [V] at ``fs`` [Hz]; the twin starts at rest at 0 V."""
        u = check_array(u, "u", "cantilever input")
        if u.ndim != 1:
            raise DataError(f"cantilever input: u must be 1-D (single voltage), got shape {u.shape}")
        try:
            fs = float(fs)
        except (TypeError, ValueError):
            raise DataError(f"cantilever: fs is not a number ({fs!r})") from None
        if not math.isfinite(fs) or fs <= 0:
            raise DataError(f"cantilever: sampling rate fs must be positive and finite, got {fs}")
        cfg = self._config(fs)
        st = self._fresh_state(cfg)
        u = np.ascontiguousarray(u, dtype=np.float64)
        if self.has("measurement_noise") and self.params.noise_um > 0:
            noise = self.params.noise_um * np.random.default_rng(self.seed).standard_normal(u.size)
        else:
            noise = np.zeros(u.size)
        out = np.empty(u.size)
        if cfg["icfg"][K.I_DRIFT]:
            cache.add_drift(self._base_output(u, fs, noise, cfg, st), cfg["fcfg"], bool(cfg["icfg"][K.I_QUANT]), out)
            return out
        _run(u, noise, out, cfg, st)
        return out

    def _base_output(
        self, u: np.ndarray, fs: float, noise: np.ndarray, cfg: dict[str, Any], st: dict[str, np.ndarray]
    ) -> np.ndarray:
        """The kernel's reading without the drift and the quantiser (:mod:`.cache`): computed once for an input and
        a configuration that differ only in drift parameters (the drift is added after the sensor)."""
        p = self.params
        conf = tuple((f.name, getattr(p, f.name)) for f in dataclasses.fields(p) if f.name not in _DRIFT_FIELDS)
        key = (cache.input_key(u), fs, conf, tuple(sorted(self.effects - _DRIFT_EFFECTS)), self.seed)
        base = cache.BASE_OUTPUTS.get(key)
        if base is None:
            icfg = cfg["icfg"].copy()
            icfg[K.I_DRIFT] = icfg[K.I_QUANT] = 0
            base = np.empty(u.size)
            _run(u, noise, base, {**cfg, "icfg": icfg}, st)
            cache.BASE_OUTPUTS.put(key, base)
        return base

    def make_stepper(self, fs: float) -> CantileverStepper:
        """Sample-by-sample simulator for FMU export: ``reset()``, ``step(u) -> y`` (same kernel as simulate)."""
        return CantileverStepper(self, fs)

    def noise_free(self) -> CantileverTwin:
        """The same twin without measurement noise and quantisation (for fitting and loop analysis)."""
        return self.with_effects(self.effects - {"measurement_noise", "sensor_quantization"})

    # ------------------------------------------------------------------ protocols
    def generate(self, protocol: str, **options: Any) -> Record:
        """Run a protocol of :data:`PROTOCOLS` (options: fs, amplitude_v, … see :mod:`.protocols`)."""
        self.check_protocol(protocol)
        opts = dict(options)
        u, fs, meta = BUILDERS[protocol](opts)
        if opts:
            raise ConfigError(f"protocol {protocol}: unknown option(s) {', '.join(sorted(opts))}")
        y = self.simulate(u, fs)
        meta = {**meta, **self.config(), "protocol": protocol}
        return Record(u=u, y=y, fs=fs, units=dict(self.units), meta=meta, source=f"cantilever:{protocol}")

    # ------------------------------------------------------------------ calibration
    def calibrate(self, data: Record, val: Record | None = None, names: Iterable[str] | None = None, **options: Any):
        from twins.cantilever.calibration import calibrate_cantilever

        return calibrate_cantilever(self, data, val=val, names=names, **options)


def _first_order_foh(tau: float, h: float) -> tuple[float, float, float]:
    """x_{n+1} = a x_n + b0 u_n + b1 u_{n+1}: exact for τẋ = u − x with u linear over the step h."""
    a = math.exp(-h / tau)
    one_minus_a = -math.expm1(-h / tau)
    r = tau / h * one_minus_a
    return a, r - a, 1.0 - r


def _run_args(u, noise, out, cfg, st) -> tuple:
    """The arguments of the kernel ``run_block`` (the state arrays are updated in place)."""
    return (
        u,
        noise,
        out,
        cfg["icfg"],
        cfg["fcfg"],
        st["sc"],
        st["z"],
        st["xc"],
        st["play"],
        st["buf"],
        st["vsub"],
        cfg["Phi"],
        cfg["G0"],
        cfg["G1"],
        cfg["Cout"],
        cfg["cr_a"],
        cfg["cr_b0"],
        cfg["cr_b1"],
        cfg["cr_g"],
        cfg["pi_r"],
        cfg["pi_p"],
    )


def _run(u, noise, out, cfg, st) -> None:
    K.run_block(*_run_args(u, noise, out, cfg, st))


class CantileverStepper:
    """One sample at a time with the discretisation of :meth:`CantileverTwin.simulate` (bit-identical output).

    The measurement noise is drawn from ``numpy.random.default_rng(seed)`` one value per step, the same
    sequence simulate() draws at once.
    """

    def __init__(self, twin: CantileverTwin, fs: float):
        fs = float(fs)
        if not math.isfinite(fs) or fs <= 0:
            raise DataError(f"cantilever stepper: fs must be positive and finite, got {fs}")
        self.twin = twin
        self.fs = fs
        self._cfg = twin._config(fs)
        self._noise_on = twin.has("measurement_noise") and twin.params.noise_um > 0
        self._u = np.zeros(1)
        self._n = np.zeros(1)
        self._y = np.zeros(1)
        self.reset()

    def reset(self) -> None:
        """Back to rest at 0 V, time 0, noise sequence restarted."""
        self._st = self.twin._fresh_state(self._cfg)
        self._rng = np.random.default_rng(self.twin.seed)
        self._bind()

    def _bind(self) -> None:
        """Bind the kernel's arguments once (a step then costs one kernel call, no look-ups)."""
        self._noise_um = self.twin.params.noise_um
        self._n[0] = 0.0
        self._args = _run_args(self._u, self._n, self._y, self._cfg, self._st)
        self._native: tuple[int, np.ndarray] | None = None

    def retune(self, twin: CantileverTwin) -> None:
        """Continue with the parameters of ``twin`` from the next :meth:`step` on, keeping the dynamic state.

        The hysteresis, creep, modal, sensor, delay-buffer and drift states and the noise generator carry
        over unchanged (the new seed is not applied); only the discretisation (``_config``) is rebuilt.
        Refused with a ConfigError when the new configuration would change the state layout or the
        integer configuration (sub-step count, delay samples, hysteresis operator, number of play
        operators or creep elements, effect flags of the kernel).
        """
        if not isinstance(twin, CantileverTwin):
            raise ConfigError(f"cantilever stepper: retune needs a CantileverTwin, got {type(twin).__name__}")
        cfg = twin._config(self.fs)
        old = self._cfg
        changed = [
            name
            for name, i in (
                ("substeps", K.I_M),
                ("delay samples", K.I_DELAY),
                ("hysteresis", K.I_HYST),
                ("pi_operators", K.I_NPI),
                ("creep elements", K.I_NCR),
                ("saturation", K.I_SAT),
                ("amplifier_bandwidth", K.I_AMPLP),
                ("rate_dependent_hysteresis", K.I_RATE),
                ("asymmetric_hysteresis", K.I_ASYM),
                ("thermal_drift", K.I_DRIFT),
                ("sensor_quantization", K.I_QUANT),
            )
            if cfg["icfg"][i] != old["icfg"][i]
        ]
        fresh = twin._fresh_state(cfg)
        changed += [f"state {k} shape" for k in fresh if fresh[k].shape != self._st[k].shape]
        for key in ("cr_a", "pi_r", "pi_p"):
            if cfg[key].shape != old[key].shape:
                changed.append(f"{key} shape")
        if changed:
            raise ConfigError(
                "cantilever stepper: cannot retune while running, the state layout would change "
                f"({', '.join(dict.fromkeys(changed))}); set it before the start"
            )
        self.twin, self._cfg = twin, cfg
        self._noise_on = twin.has("measurement_noise") and twin.params.noise_um > 0
        self._bind()

    def native_step(self) -> tuple[int, np.ndarray] | None:
        """(address of a C function ``double f(int64_t *ctx, double u)``, ``ctx``) that does what :meth:`step` does
        for a finite ``u``, for the FMU's loader (:mod:`twins.cantilever.native`); None while the measurement noise
        is on (drawn in Python). Valid until the next :meth:`reset` or :meth:`retune`."""
        if self._noise_on:
            return None
        if self._native is None:
            from twins.cantilever.native import native_step

            self._native = native_step(self._args)
        return self._native

    def step(self, u: float) -> float:
        """Apply the voltage sample ``u`` [V]; returns the displacement reading y [µm] at this sample."""
        if not math.isfinite(u):
            raise DataError(f"cantilever stepper: input sample is not finite ({u!r})")
        self._u[0] = u
        if self._noise_on:  # else it stays 0.0 (set by _bind)
            self._n[0] = self._noise_um * self._rng.standard_normal()
        K.run_block(*self._args)
        return float(self._y[0])
