"""Thickness-mode piezoelectric plate: the Mason/Kino three-port (physics notes B.3), vectorised over frequency.

Plate of area A, thickness t: v^D = √(c33^D/ρ), Z0 = ρ v^D A, θ = ωt/v^D, C0 = ε33^S A/t, h = e33/ε33^S.
Losses: c33^D → c33^D (1 + j/Q_m), ε33^S → ε33^S (1 − j tanδ). With inward face velocities v_a (back),
v_b (front), compressive face forces F and terminal current I (Kino 1987, equivalent to Mason 1948 / KLM):

    [F_a]   [Z0/(j tanθ)  Z0/(j sinθ)  h/(jω)   ] [v_a]
    [F_b] = [Z0/(j sinθ)  Z0/(j tanθ)  h/(jω)   ] [v_b]
    [ V ]   [h/(jω)       h/(jω)       1/(jωC0) ] [ I ]

A backing of impedance Z_B on face a (F_a = −Z_B v_a) reduces it to a two-port on the front face:
[F_b; V] = [[Z11, Z12], [Z12, Z22]]·[v_b; I] with a = Z0/(j tanθ), b = Z0/(j sinθ), g = h/(jω), den = a + Z_B:
Z11 = a − b²/den, Z12 = g − bg/den, Z22 = 1/(jωC0) − g²/den.

- Transmitter driven by a Thevenin source (V_oc, R_s) into a front load Z_in (force/velocity of the
  structure in front): Z_el = Z22 − Z12²/(Z11 + Z_in), I = V_oc/(R_s + Z_el), u = Z12 I/(Z11 + Z_in)
  (u = outward front-face velocity, +z), F = Z_in u.
- Receiver (front face toward the fluid, v_b = u inward) with an electrical load Z_L: I = −Z12 u/(Z22 + Z_L),
  V = −Z_L I; its mechanical face impedance is Z11 − Z12²/(Z22 + Z_L). The same expression with Z_L = R_s is
  the face impedance of the (silent) transmitter seen by an arriving wave.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from twins.acoustic.materials import Piezo

__all__ = [
    "PlateTwoPort",
    "plate_two_port",
    "electrical_impedance",
    "face_impedance",
    "transmit",
    "receive_voltage",
    "parallel_rc",
]


@dataclass
class PlateTwoPort:
    """Front-face two-port [[Z11, Z12], [Z12, Z22]] of a backed plate (arrays over frequency) and its C0."""

    z11: np.ndarray
    z12: np.ndarray
    z22: np.ndarray
    c0: float


def plate_two_port(f_hz: np.ndarray, piezo: Piezo, thickness: float, area: float, z_backing: float) -> PlateTwoPort:
    """Kino three-port of the plate with its back face loaded by ``z_backing`` [kg/s], reduced to the front face.

    ``f_hz`` must be > 0 (the plate matrix is singular at DC).
    """
    f = np.asarray(f_hz, dtype=float)
    w = 2 * np.pi * f
    c33 = piezo.c33d * (1.0 + 1j / piezo.q_m)
    eps = piezo.eps33s * (1.0 - 1j * piezo.tan_delta)
    v = np.sqrt(c33 / piezo.density)
    z0 = piezo.density * v * area
    theta = w * thickness / v
    h = piezo.e33 / eps
    c0 = eps * area / thickness
    a = z0 / (1j * np.tan(theta))
    b = z0 / (1j * np.sin(theta))
    g = h / (1j * w)
    den = a + z_backing
    z11 = a - b * b / den
    z12 = g - b * g / den
    z22 = 1.0 / (1j * w * c0) - g * g / den
    return PlateTwoPort(z11, z12, z22, float(np.real(c0)))


def electrical_impedance(tp: PlateTwoPort, z_front: np.ndarray | complex) -> np.ndarray:
    """Electrical input impedance Z_el = Z22 − Z12²/(Z11 + Z_front) with the front face loaded by ``z_front``."""
    return tp.z22 - tp.z12 * tp.z12 / (tp.z11 + z_front)


def face_impedance(tp: PlateTwoPort, z_electrical: np.ndarray | complex) -> np.ndarray:
    """Mechanical impedance of the front face (F/v, v inward) with the terminals loaded by ``z_electrical``."""
    return tp.z11 - tp.z12 * tp.z12 / (tp.z22 + z_electrical)


def transmit(tp: PlateTwoPort, z_front: np.ndarray, r_source: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per volt of V_oc: (front force F, outward front velocity u, terminal voltage V_tx) of a driven plate."""
    z_el = electrical_impedance(tp, z_front)
    current = 1.0 / (r_source + z_el)
    u = tp.z12 * current / (tp.z11 + z_front)
    return z_front * u, u, z_el * current


def receive_voltage(tp: PlateTwoPort, z_load: np.ndarray | complex) -> np.ndarray:
    """Open-loop receiver voltage per unit inward front-face velocity: V/u = Z_L Z12/(Z22 + Z_L)."""
    if np.isscalar(z_load) and np.isinf(z_load):
        return tp.z12 * np.ones_like(tp.z22)  # open circuit: I = 0, V = Z12 u
    return z_load * tp.z12 / (tp.z22 + z_load)


def parallel_rc(f_hz: np.ndarray, r_ohm: float, c_farad: float) -> np.ndarray:
    """Impedance of R ∥ C [Ω]; ``r_ohm = inf`` gives a pure capacitance (and c = 0 a pure resistance)."""
    w = 2 * np.pi * np.asarray(f_hz, dtype=float)
    y = 1j * w * c_farad + (0.0 if np.isinf(r_ohm) else 1.0 / r_ohm)
    with np.errstate(divide="ignore"):
        return 1.0 / y
