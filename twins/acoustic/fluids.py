"""Coupling fluids: sound speed, density and absorption as functions of temperature (physics notes B.5, B.6).

Water (distilled):
- sound speed: Marczak (1997, JASA 102:2776), 0–95 °C, a fifth-order polynomial in T [°C].
  **The T² coefficient is −5.799136e-2.** k-Wave's ``waterSoundSpeed.m`` carries −5.779136e-2 (a typo:
  it gives 1482.46 m/s at 20 °C against the reference 1482.34 and +0.12 m/s at 24 °C); do not copy it.
- density: Jones & Harris (1992), 5–40 °C (as in k-Wave ``waterDensity.m``).
- absorption: Pinkerton (1949) fit α/f² (T) (as in k-Wave ``waterAbsorption.m``), α ∝ f².
Seawater: Mackenzie (1981, JASA 70:807) sound speed, UNESCO 1981 one-atmosphere density
(Millero & Poisson 1981), Francois–Garrison (1982, JASA 72) absorption (boric acid, MgSO₄, pure water).
Other liquids (ethanol, glycerol, silicone oil, olive oil, castor oil, kerosene): a reference sound speed at
a reference temperature with a linear dc/dT, a reference density with a volume expansion coefficient, and a
power-law absorption α₀(f/1 MHz)^y (notes B.6; values marked [K] are order-of-magnitude literature values).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid.errors import ConfigError
from twins.acoustic.materials import power_law_attenuation

__all__ = [
    "FLUIDS",
    "FluidState",
    "fluid_state",
    "water_sound_speed",
    "water_density",
    "water_absorption",
    "seawater_sound_speed",
    "seawater_density",
    "francois_garrison",
    "WATER_T2_TYPO_KWAVE",
]

NP_PER_DB = 1.0 / (20.0 * np.log10(np.e))  # 1 dB = 0.11513 Np

#: the erroneous T² coefficient of k-Wave's waterSoundSpeed.m (kept only to document and test the typo)
WATER_T2_TYPO_KWAVE = -5.779136e-2

# Marczak 1997 coefficients, c [m/s] = Σ a_i T^i, T in °C (notes B.5 [S: Sonar.m sound_speed_water_marczak.m])
_MARCZAK = (1402.385, 5.038813, -5.799136e-2, 3.287156e-4, -1.398845e-6, 2.787860e-9)
# Jones & Harris 1992, ρ [kg/m³] (notes B.5 [S: k-Wave waterDensity.m])
_JONES_HARRIS = (999.84847, 6.337563e-2, -8.523829e-3, 6.943248e-5, -3.821216e-7)
# Pinkerton 1949 fit of α/f² in 1e-17 Np s²/cm (notes B.5 [S: k-Wave waterAbsorption.m])
_PINKERTON = (56.7235, -2.89963, 0.0992534, -2.06740e-3, 2.18942e-5, -6.21086e-8, -6.40263e-10, 3.86939e-12)


def _poly(coeffs, t):
    t = np.asarray(t, dtype=float)
    out = np.zeros_like(t)
    for c in reversed(coeffs):
        out = out * t + c
    return out


def water_sound_speed(temperature_c, t2_coefficient: float = _MARCZAK[2]):
    """Sound speed of distilled water [m/s], Marczak (1997), valid 0–95 °C.

    ``t2_coefficient`` exists only to reproduce k-Wave's typo (:data:`WATER_T2_TYPO_KWAVE`) in a test.
    """
    coeffs = list(_MARCZAK)
    coeffs[2] = t2_coefficient
    return _poly(coeffs, temperature_c)


def water_density(temperature_c):
    """Density of distilled water [kg/m³], Jones & Harris (1992), valid 5–40 °C."""
    return _poly(_JONES_HARRIS, temperature_c)


def water_absorption(f_hz, temperature_c):
    """Absorption of pure water [Np/m], Pinkerton (1949) fit: α = (α/f²)(T)·f²."""
    a_over_f2 = _poly(_PINKERTON, temperature_c) * 1e-17 * 100.0  # Np s²/cm → Np s²/m
    return a_over_f2 * np.asarray(f_hz, dtype=float) ** 2


def seawater_sound_speed(temperature_c, salinity_psu=35.0, depth_m=0.0):
    """Mackenzie (1981) nine-term sound speed of seawater [m/s]; 2–30 °C, 25–40 ‰, 0–8000 m."""
    T, S, D = temperature_c, salinity_psu, depth_m
    return (
        1448.96
        + 4.591 * T
        - 5.304e-2 * T**2
        + 2.374e-4 * T**3
        + 1.340 * (S - 35.0)
        + 1.630e-2 * D
        + 1.675e-7 * D**2
        - 1.025e-2 * T * (S - 35.0)
        - 7.139e-13 * T * D**3
    )


def seawater_density(temperature_c, salinity_psu=35.0):
    """One-atmosphere density of seawater [kg/m³], UNESCO 1981 (Millero & Poisson 1981) [K]."""
    T, S = temperature_c, salinity_psu
    rho_w = (
        999.842594 + 6.793952e-2 * T - 9.095290e-3 * T**2 + 1.001685e-4 * T**3 - 1.120083e-6 * T**4 + 6.536332e-9 * T**5
    )
    a = 8.24493e-1 - 4.0899e-3 * T + 7.6438e-5 * T**2 - 8.2467e-7 * T**3 + 5.3875e-9 * T**4
    b = -5.72466e-3 + 1.0227e-4 * T - 1.6546e-6 * T**2
    c = 4.8314e-4
    return rho_w + a * S + b * S**1.5 + c * S**2


def francois_garrison(f_hz, temperature_c, salinity_psu=35.0, depth_m=0.0, ph=8.0):
    """Francois–Garrison (1982) absorption of seawater [Np/m] (boric acid + MgSO₄ + pure-water terms).

    The published formula gives dB/km with f in kHz (notes B.5 [S: oalib Acoustics-Toolbox franc_garr.m]).
    """
    T, S, z = temperature_c, salinity_psu, depth_m
    f = np.asarray(f_hz, dtype=float) / 1e3  # kHz
    c = 1412.0 + 3.21 * T + 1.19 * S + 0.0167 * z
    a1 = 8.86 / c * 10.0 ** (0.78 * ph - 5.0)
    p1 = 1.0
    f1 = 2.8 * np.sqrt(S / 35.0) * 10.0 ** (4.0 - 1245.0 / (T + 273.0))
    a2 = 21.44 * S / c * (1.0 + 0.025 * T)
    p2 = 1.0 - 1.37e-4 * z + 6.2e-9 * z**2
    f2 = 8.17 * 10.0 ** (8.0 - 1990.0 / (T + 273.0)) / (1.0 + 0.0018 * (S - 35.0))
    p3 = 1.0 - 3.83e-5 * z + 4.9e-10 * z**2
    if T < 20.0:
        a3 = 4.937e-4 - 2.59e-5 * T + 9.11e-7 * T**2 - 1.5e-8 * T**3
    else:
        a3 = 3.964e-4 - 1.146e-5 * T + 1.45e-7 * T**2 - 6.5e-10 * T**3
    f2sq = f * f
    db_per_km = a1 * p1 * f1 * f2sq / (f1**2 + f2sq) + a2 * p2 * f2 * f2sq / (f2**2 + f2sq) + a3 * p3 * f2sq
    return db_per_km * NP_PER_DB / 1e3


@dataclass(frozen=True)
class TabulatedFluid:
    """A liquid described by reference values and linear temperature laws (notes B.6)."""

    name: str
    density: float  # kg/m³ at t_ref
    speed: float  # m/s at t_ref
    t_ref_c: float
    dc_dt: float  # m/s/K
    expansion_per_k: float  # volume expansion coefficient β [1/K]: ρ(T) = ρ_ref / (1 + β (T − T_ref))
    alpha0_np_m: float  # Np/m at 1 MHz
    alpha_power: float
    source: str


FLUIDS: dict[str, TabulatedFluid | str] = {
    "water": "distilled water: Marczak c(T), Jones–Harris ρ(T), Pinkerton α(f, T) ∝ f²",
    "seawater": "seawater S = 35 ‰: Mackenzie c(T), UNESCO ρ(T), Francois–Garrison α(f, T)",
    # c 1162 m/s at 20 °C [S: Kaye & Laby via vendor table]; ρ 789; α/f² ≈ 50e-15 Np s²/m [K]; β 1.09e-3/K [K]
    "ethanol": TabulatedFluid(
        "ethanol", 789.0, 1162.0, 20.0, -3.6, 1.09e-3, 0.05, 2.0, "notes B.6: c [S Kaye & Laby], α [K]"
    ),
    # c 1920 m/s (Olympus) at 20 °C, 1904 (Aldred) [S]; α ≈ 2.8 Np/m classical viscous estimate [C]; β 0.50e-3 [K]
    "glycerol": TabulatedFluid(
        "glycerol", 1260.0, 1920.0, 20.0, -2.0, 0.50e-3, 2.8, 2.0, "notes B.6: c [S Olympus/Aldred], α [K/C]"
    ),
    # PDMS ~30 cSt: 990 m/s (Micronics) [S partial]; α grade dependent 1-10 Np/m [K]; β 0.96e-3 [K]
    "silicone_oil": TabulatedFluid(
        "silicone oil (PDMS ~30 cSt)", 970.0, 990.0, 25.0, -3.2, 0.96e-3, 3.0, 2.0, "notes B.6: c [S Micronics], α [K]"
    ),
    # c 1440 m/s at 22 °C [S]; α 0.3-1 dB/cm [K] → 5 Np/m; β 0.72e-3 [K]
    "olive_oil": TabulatedFluid("olive oil", 912.0, 1440.0, 22.0, -2.8, 0.72e-3, 5.0, 1.8, "notes B.6: c [S], α [K]"),
    # c 1500 m/s at 19 °C [S]; α ≈ 0.8-1.0 dB/cm ≈ 10 Np/m, y ≈ 1.6-1.7 [K]; β 0.70e-3 [K]
    "castor_oil": TabulatedFluid(
        "castor oil", 960.0, 1500.0, 19.0, -4.1, 0.70e-3, 10.0, 1.65, "notes B.6: c [S], α [K]"
    ),
    # c 1315-1324 m/s at 25 °C [S]; ρ 800-870 → 810; α low [K] ≈ 0.5 Np/m; β 0.99e-3 [K]
    "kerosene": TabulatedFluid("kerosene", 810.0, 1319.0, 25.0, -3.6, 0.99e-3, 0.5, 2.0, "notes B.6: c [S], α [K]"),
}

FLUID_NAMES = tuple(FLUIDS)


@dataclass(frozen=True)
class FluidState:
    """A fluid at one temperature: ρ [kg/m³], c [m/s], dc/dT [m/s/K] and its absorption law α(f) [Np/m]."""

    name: str
    temperature_c: float
    density: float
    speed: float
    dc_dt: float
    salinity_psu: float = 35.0
    alpha0_np_m: float = 0.0
    alpha_power: float = 2.0

    @property
    def impedance_rayl(self) -> float:
        return self.density * self.speed

    def alpha(self, f_hz):
        """Absorption [Np/m] at the frequencies ``f_hz``."""
        if self.name == "water":
            return water_absorption(np.abs(f_hz), self.temperature_c)
        if self.name == "seawater":
            return francois_garrison(np.abs(f_hz), self.temperature_c, self.salinity_psu)
        return power_law_attenuation(f_hz, self.alpha0_np_m, self.alpha_power)


def fluid_state(name: str, temperature_c: float, salinity_psu: float = 35.0) -> FluidState:
    """Properties of fluid ``name`` at ``temperature_c`` [°C]; unknown names are refused with the valid list."""
    if name not in FLUIDS:
        raise ConfigError(f"unknown fluid {name!r}; valid: {', '.join(FLUIDS)}")
    T = float(temperature_c)
    if name == "water":
        c = float(water_sound_speed(T))
        dcdt = float((water_sound_speed(T + 0.01) - water_sound_speed(T - 0.01)) / 0.02)
        return FluidState("water", T, float(water_density(T)), c, dcdt)
    if name == "seawater":
        c = float(seawater_sound_speed(T, salinity_psu))
        dcdt = float(
            (seawater_sound_speed(T + 0.01, salinity_psu) - seawater_sound_speed(T - 0.01, salinity_psu)) / 0.02
        )
        return FluidState("seawater", T, float(seawater_density(T, salinity_psu)), c, dcdt, salinity_psu)
    fl = FLUIDS[name]
    assert isinstance(fl, TabulatedFluid)
    c = fl.speed + fl.dc_dt * (T - fl.t_ref_c)
    rho = fl.density / (1.0 + fl.expansion_per_k * (T - fl.t_ref_c))
    return FluidState(name, T, rho, c, fl.dc_dt, salinity_psu, fl.alpha0_np_m, fl.alpha_power)
