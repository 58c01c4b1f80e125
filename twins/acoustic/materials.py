"""Solid materials of the piezoacoustic stack: piezoceramics, epoxy bond, stainless steels.

Room-temperature values (physics notes B.4). Units: SI (kg/m³, m/s, Pa, C/m², F/m). Attenuation is a
power law α(f) = α₀·(f / 1 MHz)^y in Np/m (notes B.2). Temperature dependence of the solids is neglected
(a few 0.1 m/s/K for steel, i.e. < 0.1 % of the plate transit time over ±10 K): only the fluid depends on T.

Sources are tagged as in the notes: [S] checked against a source, [K] standard literature value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Solid", "Piezo", "PIEZOS", "SOLIDS", "EPS0", "F_REF_HZ", "power_law_attenuation"]

#: vacuum permittivity [F/m] (CODATA 2018)
EPS0 = 8.8541878128e-12
#: reference frequency of the attenuation power laws [Hz]
F_REF_HZ = 1.0e6


def power_law_attenuation(f_hz: np.ndarray, alpha0_np_m: float, power: float) -> np.ndarray:
    """α(f) = α₀·(|f|/1 MHz)^y  [Np/m] (notes B.2)."""
    return alpha0_np_m * (np.abs(np.asarray(f_hz, dtype=float)) / F_REF_HZ) ** power


@dataclass(frozen=True)
class Solid:
    """A passive isotropic layer for longitudinal waves: density, sound speed, attenuation law."""

    name: str
    density: float  # kg/m³
    speed: float  # m/s, longitudinal
    alpha0_np_m: float  # Np/m at 1 MHz
    alpha_power: float  # exponent y of α ∝ f^y
    source: str = ""

    @property
    def impedance_rayl(self) -> float:
        """Specific acoustic impedance ρc [Rayl = kg/(m² s)]."""
        return self.density * self.speed

    def alpha(self, f_hz: np.ndarray) -> np.ndarray:
        return power_law_attenuation(f_hz, self.alpha0_np_m, self.alpha_power)


@dataclass(frozen=True)
class Piezo:
    """Thickness-mode constants of a poled ceramic plate (IEEE Std 176 notation)."""

    name: str
    density: float  # kg/m³
    c33d: float  # stiffened elastic constant c33^D [Pa]
    e33: float  # piezoelectric stress constant [C/m²]
    eps33s_rel: float  # clamped relative permittivity ε33^S/ε0
    q_m: float  # mechanical quality factor
    tan_delta: float  # dielectric loss tangent
    source: str = ""

    @property
    def eps33s(self) -> float:
        return self.eps33s_rel * EPS0

    @property
    def speed(self) -> float:
        """v^D = √(c33^D/ρ) [m/s]."""
        return float(np.sqrt(self.c33d / self.density))

    @property
    def h33(self) -> float:
        """h33 = e33/ε33^S [V/m]."""
        return self.e33 / self.eps33s

    @property
    def kt(self) -> float:
        """Thickness coupling k_t = e33/√(c33^D ε33^S)."""
        return float(self.e33 / np.sqrt(self.c33d * self.eps33s))


PIEZOS: dict[str, Piezo] = {
    # [K] Berlincourt, Curran & Jaffe 1964 / Morgan Electro Ceramics data (notes B.4): v^D = 4604 m/s, k_t ≈ 0.51
    "pzt4": Piezo(
        "PZT-4 (Navy I)", 7500.0, 15.9e10, 15.1, 635.0, 500.0, 0.004, "notes B.4 [K: Berlincourt/Morgan data]"
    ),
    # [K] same sources: v^D = 4355 m/s, k_t ≈ 0.49
    "pzt5a": Piezo(
        "PZT-5A (Navy II)", 7750.0, 14.7e10, 15.8, 830.0, 75.0, 0.02, "notes B.4 [K: Berlincourt/Morgan data]"
    ),
}

SOLIDS: dict[str, Solid] = {
    # [K] Selfridge 1985 (IEEE T-SU 32:381) range 1100-1250 kg/m³, 2400-2800 m/s; ≈10 Np/m at 1 MHz, α ∝ f
    "epoxy": Solid("epoxy bond (Epotek/Araldite class)", 1150.0, 2600.0, 10.0, 1.0, "notes B.4 [K: Selfridge 1985]"),
    # [S] vendor sound-speed tables (Instrumart 304L 5790, 304 5920 m/s); grain scattering ≈1 Np/m at 1 MHz [K]
    "ss304": Solid("stainless steel 304", 7900.0, 5790.0, 1.0, 1.0, "notes B.4 [S: vendor tables; α K]"),
    # [S] Instrumart/Olympus 5720-5800 m/s
    "ss316": Solid("stainless steel 316", 7990.0, 5750.0, 1.0, 1.0, "notes B.4 [S: vendor tables; α K]"),
}
