"""Parameters of the piezoacoustic twin (dataclass with units, ranges and sources; twins.base.pfield).

Default stack (see README section "acoustic" and :mod:`twins.acoustic.calibration`):
PZT-4 2.16 mm | epoxy 100 µm | SS316 6.25 mm | water 100 mm at 24 °C | SS316 | epoxy | PZT-4, plates
70 × 25 mm, air backing, Tx driven through 50 Ω, Rx into 1 MΩ ∥ 15 pF. Its direct-path transmission peaks
at ≈ 940 and ≈ 1162 kHz (dissertation Figure 3.9).
"""

from __future__ import annotations

from dataclasses import dataclass

from twins.acoustic.fluids import FLUID_NAMES
from twins.acoustic.materials import PIEZOS
from twins.base import pfield

__all__ = ["AcousticParams"]

_PIEZO_NAMES = tuple(PIEZOS)
_STEELS = ("ss304", "ss316")


@dataclass
class AcousticParams:
    # ---------------------------------------------------------------- medium and geometry
    distance_m: float = pfield(
        0.100, "m", 0.0, 2.0, "fluid gap between the Tx and Rx steel plates", source="dissertation §3.2: 10 cm"
    )
    temperature_c: float = pfield(
        24.0,
        "°C",
        0.0,
        60.0,
        "fluid temperature (water density formula valid 5–40 °C)",
        source="dissertation §3.2: room temperature 24 °C",
    )
    fluid: str = pfield("water", "", doc="coupling fluid", choices=FLUID_NAMES, source="notes B.5/B.6")
    salinity_psu: float = pfield(35.0, "‰", 0.0, 45.0, "salinity (seawater only)", source="notes B.6")
    # ---------------------------------------------------------------- transducers (identical Tx and Rx)
    piezo: str = pfield("pzt4", "", doc="piezoceramic", choices=_PIEZO_NAMES, source="notes B.4")
    pzt_thickness_m: float = pfield(
        2.16e-3,
        "m",
        0.2e-3,
        10e-3,
        "PZT plate thickness",
        source="notes B.7 candidate 1 (2.15 mm) retuned to 2.16 mm: peaks 939.4 / 1162.4 kHz",
    )
    pzt_qm: float = pfield(0.0, "", 0.0, 5000.0, "mechanical Q of the PZT (0 = material value)", source="notes B.4")
    epoxy_thickness_m: float = pfield(100e-6, "m", 0.0, 1e-3, "epoxy bond PZT–steel", source="notes B.7")
    steel: str = pfield("ss316", "", doc="plate steel", choices=_STEELS, source="notes B.4")
    steel_thickness_m: float = pfield(
        6.25e-3, "m", 0.0, 30e-3, "steel plate thickness (0 = no plate)", source="notes B.7 candidate 1"
    )
    aperture: str = pfield(
        "rectangular",
        "",
        doc="transducer face shape",
        choices=("rectangular", "circular"),
        source="dissertation §3.2: 70 × 25 mm plates",
    )
    plate_width_m: float = pfield(0.070, "m", 1e-3, 0.5, "face width (rectangular)", source="dissertation §3.2")
    plate_height_m: float = pfield(0.025, "m", 1e-3, 0.5, "face height (rectangular)", source="dissertation §3.2")
    aperture_radius_m: float = pfield(
        2.5e-3,
        "m",
        0.2e-3,
        0.1,
        "face radius (circular aperture)",
        source="fitted to the USbodyComm water FIRs (lab-data comparison)",
    )
    backing_rayl: float = pfield(
        415.0, "Rayl", 0.0, 40e6, "acoustic impedance of the PZT backing (air 415)", source="notes B.3"
    )
    # ---------------------------------------------------------------- electrical
    source_resistance_ohm: float = pfield(50.0, "ohm", 0.1, 1e4, "amplifier output resistance", source="notes B.9")
    rx_load_ohm: float = pfield(
        1e6, "ohm", 1.0, 1e9, "receiver load resistance (scope 1 MΩ or 50 Ω)", source="notes B.7"
    )
    rx_load_capacitance_f: float = pfield(
        15e-12, "F", 0.0, 1e-8, "receiver load + cable capacitance", source="notes B.7: scope 1 MΩ ∥ 15 pF"
    )
    output_gain: float = pfield(1.0, "", 1e-6, 1e6, "gain of the receive electronics (1 = none)")
    # ---------------------------------------------------------------- amplifier
    amp_gain_db: float = pfield(50.0, "dB", 0.0, 80.0, "amplifier gain into a matched load", source="notes B.9")
    amp_f_low_hz: float = pfield(10e3, "Hz", 0.0, 1e6, "amplifier lower −3 dB frequency", source="notes B.9")
    amp_f_high_hz: float = pfield(12e6, "Hz", 1e6, 1e9, "amplifier upper −3 dB frequency", source="notes B.9")
    amp_compression: str = pfield(
        "rapp",
        "",
        doc="compression model (effect amplifier_compression)",
        choices=("rapp", "cubic"),
        source="notes B.9",
    )
    amp_sat_v: float = pfield(
        105.0, "V", 1.0, 1e3, "saturated output amplitude into 50 Ω (100 W ≈ 100 V peak)", source="notes B.9"
    )
    amp_smoothness: float = pfield(
        2.5,
        "",
        0.5,
        64.0,
        "Rapp smoothness p (≈ 1.3 tanh-like, ≈ 1.7 a cubic soft clip, 64 a hard clip)",
        source="notes B.9: p ≈ 2–3",
    )
    amp_asymmetry: float = pfield(
        0.0,
        "",
        -0.5,
        0.5,
        "compression asymmetry a: saturation A_sat·(1 ± a) for positive / negative output (0 = odd)",
        source="effect amplifier_compression",
    )
    amp_even_ratio: float = pfield(
        0.02, "", -1.0, 1.0, "even-order term k2 (HD2 = k2·a/(2 A_sat))", source="effect amplifier_even_distortion"
    )
    # ---------------------------------------------------------------- propagation details
    reverb_orders: int = pfield(
        30,
        "",
        -1,
        400,
        "inter-plate round trips summed (0 = gated direct path, −1 = exact 1-D closed form, needs diffraction off)",
        source="notes B.8",
    )
    model_max_hz: float = pfield(
        15e6,
        "Hz",
        1e5,
        1e9,
        "H(f) is computed up to this frequency and set to 0 above "
        "(amplifier LP at 12 MHz: |H| < −74 dB re its peak above 15 MHz for the default "
        "stack, below an 8-bit ADC's ≈ −50 dB floor)",
    )
    diffraction: bool = pfield(
        True, "", doc="aperture-dependent spreading (Gaussian-mode pair coupling)", source="notes B.8"
    )
    # ---------------------------------------------------------------- effects
    wall_distance_m: float = pfield(
        0.03,
        "m",
        1e-3,
        2.0,
        "lateral distance of the tank side wall from the axis",
        source="dissertation §3.2: Tx close to the wall",
    )
    wall_reflection: float = pfield(
        0.94, "", -1.0, 1.0, "wall pressure reflection coefficient (stainless 0.94)", source="notes B.8"
    )
    wall_coupling: float = pfield(
        0.05,
        "",
        0.0,
        1.0,
        "fraction of the beam reaching the wall path (edge waves)",
        source="notes B.8: a_k to be fitted",
    )
    wall_echo_path: str = pfield(
        "image",
        "",
        doc="wall echo variant: the single-bounce image path, or a delayed "
        "copy of the whole received signal (reverberations included)",
        choices=("image", "copy"),
        source="effect wall_echo",
    )
    wall_echo_cutoff_hz: float = pfield(
        0.0,
        "Hz",
        0.0,
        2e7,
        "first-order low-pass on the echo path (0 = none): the loss of a rough or absorbing wall",
        source="effect wall_echo",
    )
    crosstalk_capacitance_f: float = pfield(2e-12, "F", 0.0, 1e-9, "stray capacitance Tx terminal → Rx node")
    crosstalk_resistive: float = pfield(
        0.0,
        "",
        -0.5,
        0.5,
        "in-phase coupling V_rx/V_oc of a resistive or common-ground path from the drive (effect crosstalk)",
    )
    crosstalk_derivative_s: float = pfield(
        0.0,
        "s",
        -1e-7,
        1e-7,
        "derivative coupling τ_d: V_rx = τ_d·dV_oc/dt "
        "(capacitance into a resistive node, τ_d = R·C; or a mutual "
        "inductance, either sign; effect crosstalk)",
    )
    temperature_offset_k: float = pfield(0.5, "K", -20.0, 20.0, "true − assumed fluid temperature")
    distance_offset_m: float = pfield(0.5e-3, "m", -0.05, 0.05, "true − assumed distance")
    mismatch_fluid: str = pfield(
        "seawater", "", doc="fluid actually in the tank (effect fluid_mismatch)", choices=FLUID_NAMES
    )
    misalignment_offset_m: float = pfield(2e-3, "m", 0.0, 0.05, "lateral offset of the Rx (along the plate height)")
    misalignment_tilt_deg: float = pfield(0.3, "deg", 0.0, 10.0, "tilt of the Rx about the plate-width axis")
    # ---------------------------------------------------------------- acquisition
    noise_v: float = pfield(
        0.02, "V", 0.0, 10.0, "white measurement noise std at the Rx", source="effect measurement_noise"
    )
    adc_bits: int = pfield(8, "bit", 2, 24, "ADC resolution (Tektronix MDO3024: 8 bit)", source="dissertation §3.2")
    adc_range_v: float = pfield(50.0, "V", 1e-3, 1e3, "ADC full scale ±range (Rx open-circuit voltage reaches ≈ 40 V)")
