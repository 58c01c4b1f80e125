"""Parameters of the cantilever micromanipulator twin (physics notes part A, dissertation §3.1).

Every field carries its unit, documented range and source (see :func:`twins.base.pfield`). The ranges are
wide enough for both the dissertation's 15 × 2 × 0.3 mm PZT cantilever (±100 V, ≈0.3 µm/V, f₁ ≈ 700 Hz) and
the measured TU/e actuator of :mod:`twins.cantilever.lab` (±150 V, ±19.7 µm, a loop slope of ≈0.13 µm/V, a
step response ringing near 800 Hz).

Notation (physics notes A.1/A.3): u [V] command → amplifier → v [V] → Γ[v] (hysteresis, µm) + Cr(s)v (creep,
µm) → D(s) (normalised modal dynamics, D(0) = 1) → δ [µm] → sensor → y [µm].
"""

from __future__ import annotations

from dataclasses import dataclass

from twins.base import pfield

__all__ = ["CantileverParams", "HYSTERESIS_MODELS"]

HYSTERESIS_MODELS = ("bouc-wen", "prandtl-ishlinskii")

_NOTES = "physics-notes.md"


@dataclass
class CantileverParams:
    """Physical parameters of :class:`twins.cantilever.CantileverTwin` (SI units unless the name says otherwise)."""

    # ---------------------------------------------------------------- hysteresis (core)
    hysteresis: str = pfield(
        "bouc-wen",
        "",
        doc="rate-independent hysteresis operator Γ",
        choices=HYSTERESIS_MODELS,
        source=f"{_NOTES} A.3 (Bouc–Wen), A.4 (Prandtl–Ishlinskii)",
    )
    gain_um_per_v: float = pfield(
        0.30,
        "um/V",
        0.02,
        1.5,
        "piezo coefficient d of Γ = d·v − h (Bouc–Wen) or total PI weight Σp_i",
        source=f"{_NOTES} A.2 table (0.33–0.72 µm/V for 0.1–0.2 mm PZT on Cu), A.7 nominal",
    )
    bw_alpha: float = pfield(
        0.30,
        "1",
        0.01,
        0.95,
        "Bouc–Wen α (hysteresis share of d)",
        source=f"{_NOTES} A.3 recommended set (12.6 % loop at ±100 V)",
    )
    bw_beta: float = pfield(0.015, "1/V", 1e-4, 0.2, "Bouc–Wen β (n = 1)", source=f"{_NOTES} A.3")
    bw_gamma: float = pfield(
        0.004, "1/V", -0.1, 0.1, "Bouc–Wen γ (n = 1); β > |γ| gives the piezo loop", source=f"{_NOTES} A.3"
    )
    pi_operators: int = pfield(
        10, "1", 1, 50, "number n of play operators (thresholds r_i = i·r_max/n)", source=f"{_NOTES} A.4 (n = 8–12)"
    )
    pi_r_max_v: float = pfield(
        100.0, "V", 1.0, 1e4, "largest play threshold r_n", source=f"{_NOTES} A.4 (r_i = 10·i V for ±100 V)"
    )
    pi_p0_fraction: float = pfield(
        0.55,
        "1",
        0.05,
        1.0,
        "share p_0/d of the linear (r_0 = 0) operator",
        source=f"{_NOTES} A.4 check set p_0 = 0.2, p_i = 0.05e^(−0.25i) µm/V (p_0 share 0.55)",
    )
    pi_decay: float = pfield(
        0.25, "1", 0.0, 3.0, "weights p_i ∝ exp(−decay·i) for i ≥ 1", source=f"{_NOTES} A.4 check set"
    )

    # ---------------------------------------------------------------- amplifier (core clip)
    amp_limit_v: float = pfield(
        100.0,
        "V",
        1.0,
        1e4,
        "hard output limit of the power amplifier (±)",
        source="dissertation §3.1 (−100…+100 V); 150 V for the TU/e data; PZT stacks "
        "are driven to 1–1.5 kV (range widened for them)",
    )

    # ---------------------------------------------------------------- modal dynamics D(s) (core)
    f1_hz: float = pfield(
        700.0,
        "Hz",
        50.0,
        3000.0,
        "first bending-mode frequency",
        source=f"{_NOTES} A.2 (ideal clamp 680–840 Hz, prior 300–900 Hz), A.7",
    )
    zeta1: float = pfield(
        0.02, "1", 0.001, 0.5, "first-mode damping ratio", source=f"{_NOTES} A.2 (ζ ≈ 0.01–0.05 in air)"
    )
    mode_ratio: float = pfield(
        6.27, "1", 2.0, 10.0, "f₂/f₁ of the clamped-free beam", source=f"{_NOTES} A.2 (Euler–Bernoulli, β₂²/β₁² = 6.27)"
    )
    zeta2: float = pfield(0.02, "1", 0.001, 0.5, "second-mode damping ratio", source=f"{_NOTES} A.2 (as ζ₁)")
    mode2_share: float = pfield(
        0.08,
        "1",
        0.0,
        0.5,
        "static tip-deflection share of mode 2 (mode 1 gets 1 − share)",
        source=f"{_NOTES} A.2 (90.3 / 8.0 / 1.7 % → 0.92 / 0.08 with two modes)",
    )

    # ---------------------------------------------------------------- creep (effect `creep`)
    creep_per_decade: float = pfield(
        0.015,
        "1/decade",
        0.0,
        0.1,
        "logarithmic creep rate γ_c: weight of each Kelvin–Voigt element (× d)",
        source=f"{_NOTES} A.5 (PI tutorial: 1–2 %/decade; KV weights ≈ γ_c per decade)",
    )
    creep_tau_min_s: float = pfield(
        0.1,
        "s",
        1e-3,
        100.0,
        "shortest Kelvin–Voigt time constant τ_1; τ_i = τ_1·10^(i−1)",
        source=f"{_NOTES} A.5 (τ = 0.1, 1, 10, 100 … s)",
    )
    creep_elements: int = pfield(
        4,
        "1",
        1,
        8,
        "number of Kelvin–Voigt elements (one per decade)",
        source=f"{_NOTES} A.5 (3 elements suffice for records of a few seconds)",
    )

    initial_state_um: float = pfield(
        0.0,
        "um",
        -50.0,
        50.0,
        "hysteresis output Γ at t = 0 with v = 0 (remanent state left by the actuator's "
        "history; Bouc–Wen h₀ = −Γ₀, PI plays F_i = κ·r_i); the twin starts in equilibrium",
        source="TU/e data: 0-V reading before the first step differs from the loop centre",
    )

    # ---------------------------------------------------------------- sensor (core offset; effects)
    offset_um: float = pfield(
        0.0, "um", -100.0, 100.0, "sensor zero offset (reading at zero deflection)", source="TU/e data: −1.68 µm at 0 V"
    )
    sensor_bandwidth_hz: float = pfield(
        5000.0,
        "Hz",
        100.0,
        1e5,
        "2nd-order Butterworth sensor low-pass corner",
        source="dissertation §3.1 (Keyence LK-2420, 5 kHz); notes A.6",
    )
    noise_um: float = pfield(
        0.005,
        "um",
        0.0,
        1.0,
        "white measurement noise σ (seeded by the twin's seed)",
        source=f"{_NOTES} A.6 (σ ≈ 3–10 nm)",
    )
    quant_um: float = pfield(
        0.01, "um", 1e-5, 1.0, "sensor/ADC quantisation step", source="dissertation §3.1 (10 nm resolution)"
    )

    # ---------------------------------------------------------------- optional effects
    amp_bandwidth_hz: float = pfield(
        10000.0,
        "Hz",
        10.0,
        1e6,
        "first-order bandwidth of the power amplifier",
        source="HV amplifiers driving ≈2.3 nF (notes A.2): typically 1–50 kHz (assumed)",
    )
    sat_voltage_v: float = pfield(
        150.0,
        "V",
        1.0,
        2000.0,
        "soft-saturation knee V_s: v = u/(1+|u/V_s|^p)^(1/p)",
        source="amplifier/actuator compression (assumed); notes A.2 (coercive field)",
    )
    sat_sharpness: float = pfield(
        4.0, "1", 1.0, 20.0, "exponent p of the soft saturation (large p → hard knee)", source="assumed"
    )
    input_delay_s: float = pfield(
        1.5e-4,
        "s",
        0.0,
        0.05,
        "pure input (transport/DAC) delay, fractional samples allowed",
        source="dSPACE DS1104 I/O latency order 1–2 samples at 10 kHz (assumed)",
    )
    thermal_drift_um: float = pfield(
        1.0,
        "um",
        -50.0,
        50.0,
        "final value of the additive thermal drift",
        source="thermal expansion of the clamp/sensor mount (assumed order µm)",
    )
    thermal_tau_s: float = pfield(
        20.0, "s", 0.01, 1e5, "time constant of the thermal drift D·(1 − e^(−t/τ))", source="assumed"
    )
    drift_rate_um_per_s: float = pfield(
        0.0,
        "um/s",
        -10.0,
        10.0,
        "ramp r·t of the thermal drift (slow family)",
        source="a drift that has not settled within the record (assumed order 0.01 µm/s, the TU/e record's 0.015 µm/s)",
    )
    drift_sin_um: float = pfield(
        0.0,
        "um",
        -50.0,
        50.0,
        "amplitude a of the drift's slow sine a·sin(2πt/P)",
        source="room-temperature cycles of the mount (assumed)",
    )
    drift_cos_um: float = pfield(
        0.0,
        "um",
        -50.0,
        50.0,
        "amplitude b of the drift's slow b·(1 − cos(2πt/P))",
        source="with the sine: any phase of the slow oscillation, zero at t = 0",
    )
    drift_period_s: float = pfield(
        100.0,
        "s",
        20.0,
        1e5,
        "period P of the drift's slow oscillation",
        source="assumed (air-conditioning cycles 5–30 min); at least 20 s, slower than "
        "the drives and the creep of seconds: with 0.1 s the TU/e record's 1 Hz loop-shape "
        "error was taken for a 0.34 s 'drift', with 2–10 s creep + thermal drift on 5 s "
        "steps for a 4.3 s one",
    )
    rate_ref_v_per_s: float = pfield(
        2.0e5,
        "V/s",
        10.0,
        1e9,
        "rate envelope at which the hysteretic share doubles: α (BW, capped at 0.98) or the "
        "play weights p_i (PI, p_0 lowered to keep d) × (1 + ρ/rate_ref), ρ = low-pass of |v̇|",
        source=f"{_NOTES} A.4 (rate-dependent PI, Al Janaideh & Krejčí 2013, grow r_i "
        "with |u̇|; at full amplitude that parks the largest plays and barely widens the "
        "loop, so the weights are scaled here)",
    )
    rate_tau_s: float = pfield(
        0.01,
        "s",
        1e-5,
        10.0,
        "time constant of the rate envelope ρ (≈ mean |v̇| above 1/(2πτ))",
        source="assumed; keeps the loop shape smooth within a period",
    )
    asym_factor: float = pfield(
        1.0,
        "1",
        -0.9,
        5.0,
        "extra hysteretic share against the poling direction: α (BW) or play weights (PI, "
        "p_0 lowered to keep d) × (1 + a·max(0, −v)/amp_limit)",
        source=f"{_NOTES} A.2 (negative field against poling), A.3 asymmetric variants",
    )

    # ---------------------------------------------------------------- numerics
    max_substep_s: float = pfield(
        2e-5,
        "s",
        1e-7,
        1e-3,
        "largest integration sub-step (sub-steps per sample = ceil(1/(fs·h))); the linear "
        "parts and Bouc–Wen are exact, the error is O(h²) from the FOH of Γ inside a "
        "sub-step: 2·10⁻⁵ of the span at 20 µs, 5·10⁻⁶ at 10 µs (thesis multisine)",
        source=f"{_NOTES} A.1 (h = 5–10 µs for RK4); convergence measured here",
    )
