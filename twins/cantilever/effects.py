"""Effect catalog of the cantilever twin: each effect is switched on or off by name, its parameters are fields
of the twin's parameter dataclass.

Each effect names its own parameters (fields of :class:`CantileverParams`) and the one-line residual
signature that reveals it when a twin without the effect is compared with data that has it. The effects are
chosen to be physically distinct: input-independent additive (thermal drift, noise, quantisation), linear
dynamic (second mode, sensor low-pass, amplifier bandwidth, input delay, creep) and nonlinear (saturation,
rate-dependent and asymmetric hysteresis).

The effects that sit between the physics and the measurement (input delay, saturation of the drive, sensor
low-pass, thermal drift) are the model-agnostic entries of :mod:`twins.generic_effects` specialised to this
twin's fields and wording (the compiled kernel applies the same laws inside its sub-steps).
"""

from __future__ import annotations

import dataclasses

from twins.base import EffectSpec
from twins.generic_effects import specialise

__all__ = ["EFFECTS", "DEFAULT_ON"]

_T = "cantilever"

EFFECTS: dict[str, EffectSpec] = {
    "creep": EffectSpec(
        "creep",
        _T,
        "logarithmic creep: Kelvin–Voigt chain Σ γ_c·d/(τ_i s + 1), one element per decade from τ_1",
        "slow exponential/log-time tail after every voltage change, residual ∝ low-pass of u (τ ≥ 0.1 s); "
        "no effect at u = 0",
        {"rate": "creep_per_decade", "tau_min": "creep_tau_min_s", "elements": "creep_elements"},
        default_on=True,
    ),
    "second_mode": EffectSpec(
        "second_mode",
        _T,
        "second bending mode of D(s) at f₂ = mode_ratio·f₁ carrying mode2_share of the static deflection",
        "residual spectrum peak near 6.27·f₁ (≈4.4 kHz), ringing after fast edges; nothing at low frequency",
        {"ratio": "mode_ratio", "share": "mode2_share", "zeta": "zeta2"},
        default_on=True,
    ),
    "sensor_lowpass": specialise(
        "sensor_lowpass",
        _T,
        {"bandwidth": "sensor_bandwidth_hz"},
        description="2nd-order Butterworth low-pass of the optical sensor",
        signature="residual grows with frequency near the sensor corner: phase lag ≈ √2·f/f_c rad and roll-off "
        "above; nothing below ≈ 100 Hz",
        default_on=True,
    ),
    "sensor_quantization": EffectSpec(
        "sensor_quantization",
        _T,
        "sensor/ADC quantiser with step quant_um",
        "residual uniformly distributed in ±q/2, white, independent of u; output takes values on a q grid",
        {"step": "quant_um"},
        default_on=True,
    ),
    "measurement_noise": EffectSpec(
        "measurement_noise",
        _T,
        "white Gaussian sensor noise σ = noise_um, seeded by the twin's seed",
        "white residual (flat spectrum, r_ee = δ) uncorrelated with u, Gaussian",
        {"sigma": "noise_um"},
        default_on=True,
    ),
    "input_delay": specialise(
        "input_delay",
        _T,
        {"delay": "input_delay_s"},
        description="pure delay of the input in seconds (fractional samples by linear interpolation)",
        signature="residual ∝ τ·dy/dt: phase lag growing linearly with frequency (2π f τ), cross-correlation "
        "r_ue peaks at lag τ·fs; gain unchanged",
    ),
    "thermal_drift": dataclasses.replace(
        specialise(
            "offset_drift",
            _T,
            {"amplitude": "thermal_drift_um", "tau": "thermal_tau_s"},
            description="additive thermal drift D·(1 − e^(−t/τ)) of the reading, independent of the input",
            signature="slow monotone trend in the residual present even at u = 0; no correlation with u",
        ),
        id="thermal_drift",
    ),
    "slow_drift": specialise(
        "slow_drift",
        _T,
        {"rate": "drift_rate_um_per_s", "sine": "drift_sin_um", "cosine": "drift_cos_um", "period": "drift_period_s"},
        description="additive thermal drift that has not settled: a ramp and a slow cycle of any phase, "
        "r·t + a·sin(2πt/P) + b·(1 − cos(2πt/P)) (zero at t = 0), independent of the input",
        signature="slow trend in the residual (ramp, slow swing or turn) present even at u = 0; no correlation with u",
    ),
    "saturation": dataclasses.replace(
        specialise(
            "drive_compression",
            _T,
            {"knee": "sat_voltage_v", "sharpness": "sat_sharpness"},
            description="soft amplifier/actuator limit v = u/(1 + |u/V_s|^p)^(1/p) before the hard clip",
            signature="output compressed at large |u| only (flattened loop tips, odd harmonics growing with "
            "amplitude); residual ∝ −u|u|^p near the peaks, none at small u",
        ),
        id="saturation",
    ),
    "rate_dependent_hysteresis": EffectSpec(
        "rate_dependent_hysteresis",
        _T,
        "hysteretic share grows with the input rate: α (Bouc–Wen) or the play weights (PI, p_0 lowered to keep "
        "the large-loop slope d) × (1 + ρ/rate_ref), ρ = low-pass (rate_tau) of |v̇|",
        "loop width and phase lag grow with frequency already far below f₁ (10–200 Hz), where D(s) is flat; "
        "residual ∝ |u̇|·loop width",
        {"rate_ref": "rate_ref_v_per_s", "tau": "rate_tau_s"},
    ),
    "asymmetric_hysteresis": EffectSpec(
        "asymmetric_hysteresis",
        _T,
        "stronger hysteresis against the poling direction: α or the PI play weights (p_0 lowered to keep d) "
        "× (1 + a·max(0, −v)/amp_limit)",
        "loop wider and flatter for negative voltages than positive; even harmonics in the residual, "
        "residual mean shifts with the sign of u",
        {"factor": "asym_factor"},
    ),
    "amplifier_bandwidth": EffectSpec(
        "amplifier_bandwidth",
        _T,
        "first-order low-pass of the power amplifier",
        "extra phase lag ≈ f/f_amp growing linearly at low frequency plus gain roll-off near f_amp; "
        "looks like a delay below f_amp (same ambiguity group)",
        {"bandwidth": "amp_bandwidth_hz"},
        group="lag",
    ),
}
# input_delay and amplifier_bandwidth share the ambiguity group "lag": both are a phase lag ∝ f well below
# f_amp; a sweep to frequencies near f_amp (gain roll-off only for the low-pass) separates them.
# thermal_drift and slow_drift are the drift family (group "drift"): the settling exponential alone (2 parameters,
# precise when the drift settles) and the ramp + slow cycle (4 parameters, a drift that has not settled); both
# can be on at once (their sum).

DEFAULT_ON = tuple(k for k, e in EFFECTS.items() if e.default_on)
