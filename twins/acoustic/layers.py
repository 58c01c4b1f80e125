"""Transfer matrices of passive layers for plane longitudinal waves, vectorised over frequency (notes B.2).

Convention: time factor e^{jωt}, forward wave e^{−jkz}; state s = [F, u] = [force (pressure·A, compressive
positive), particle velocity (+z, Tx → Rx)], both continuous across interfaces. For a layer of thickness d:

    k = ω/c − jα(f),   Z = ρcA,   θ = kd
    s(z_in) = M s(z_out),   M = [[cos θ, jZ sin θ], [j sin θ / Z, cos θ]],   det M = 1
    M⁻¹ = [[cos θ, −jZ sin θ], [−j sin θ / Z, cos θ]]

Input impedance (looking into the layer toward its load Z_L): Z_in = (M11 Z_L + M12)/(M21 Z_L + M22).
Matrices are returned as 4-tuples ``(m11, m12, m21, m22)`` of arrays shaped like ``f`` — cheaper than
stacking (…, 2, 2) arrays and multiplying with einsum.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Layer", "layer_matrix", "chain", "input_impedance", "propagate_forward", "slab_coefficients"]

Mat = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


@dataclass(frozen=True)
class Layer:
    """A passive layer: density [kg/m³], sound speed [m/s], thickness [m], attenuation law α₀ (f/1 MHz)^y."""

    density: float
    speed: float
    thickness: float
    alpha0_np_m: float = 0.0
    alpha_power: float = 1.0

    def wavenumber(self, f_hz: np.ndarray) -> np.ndarray:
        f = np.asarray(f_hz, dtype=float)
        alpha = self.alpha0_np_m * (np.abs(f) / 1e6) ** self.alpha_power
        return 2 * np.pi * f / self.speed - 1j * alpha

    def impedance(self, area: float) -> float:
        """Z = ρcA [kg/s] (force / velocity)."""
        return self.density * self.speed * area


def layer_matrix(f_hz: np.ndarray, layer: Layer, area: float) -> Mat:
    """Transfer matrix M(f) of one layer (s_in = M s_out); a zero-thickness layer is the identity."""
    f = np.asarray(f_hz, dtype=float)
    theta = layer.wavenumber(f) * layer.thickness
    z = layer.impedance(area)
    c, s = np.cos(theta), np.sin(theta)
    return c, 1j * z * s, 1j * s / z, c


def chain(mats: Sequence[Mat]) -> Mat:
    """Product M_1 M_2 … M_n (first layer first, as the wave meets them)."""
    a11, a12, a21, a22 = mats[0]
    for b11, b12, b21, b22 in mats[1:]:
        a11, a12, a21, a22 = (
            a11 * b11 + a12 * b21,
            a11 * b12 + a12 * b22,
            a21 * b11 + a22 * b21,
            a21 * b12 + a22 * b22,
        )
    return a11, a12, a21, a22


def input_impedance(m: Mat, z_load: np.ndarray | complex) -> np.ndarray:
    """Z_in = (M11 Z_L + M12)/(M21 Z_L + M22): impedance at the input of ``m`` terminated by ``z_load``."""
    m11, m12, m21, m22 = m
    return (m11 * z_load + m12) / (m21 * z_load + m22)


def propagate_forward(m: Mat, force: np.ndarray, velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """State at the output of ``m`` from the state at its input: s_out = M⁻¹ s_in (det M = 1)."""
    m11, m12, m21, m22 = m
    return m22 * force - m12 * velocity, -m21 * force + m11 * velocity


def slab_coefficients(
    f_hz: np.ndarray, layers: Sequence[Layer], z1_rayl: float, z2_rayl: float, area: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Pressure reflection R and transmission T of a stack between half-spaces of impedance z1 (incident) and z2.

    A wave p_i = 1 arrives from medium 1; medium 2 is semi-infinite (only a forward wave). Energy balance for
    lossless layers: |R|² + (z1/z2)|T|² = 1.
    """
    f = np.asarray(f_hz, dtype=float)
    m = (
        chain([layer_matrix(f, lay, area) for lay in layers])
        if layers
        else (np.ones_like(f, complex), np.zeros_like(f, complex), np.zeros_like(f, complex), np.ones_like(f, complex))
    )
    zl = z2_rayl * area
    zin = input_impedance(m, zl)
    z1 = z1_rayl * area
    r = (zin - z1) / (zin + z1)
    # total force at the input face is A p_i (1 + R); velocity u = A p_i (1 + R)/Z_in; propagate to the output.
    force_in = area * (1.0 + r)
    force_out, _ = propagate_forward(m, force_in, force_in / zin)
    return r, force_out / area
