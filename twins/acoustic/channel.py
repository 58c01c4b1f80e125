"""The linear chain H(f) = V_rx/V_oc of the piezoacoustic channel (physics notes B.1–B.3, B.8), vectorised in f.

    V_oc ─R_s─ Tx PZT | epoxy | steel ║ fluid gap L ║ steel | epoxy | Rx PZT ─ Z_L → V_rx

The fluid gap is written as its Fabry–Pérot series, an identity of the 1-D chain for plane waves:

    H = T_tx · R_v · Σ_n (R_tx R_rx)^n · e^{−jk(2n+1)L} · D((2n+1)L) · M_n  +  wall-echo terms  +  crosstalk

- T_tx = p⁺/V_oc, the wave launched into the fluid; R_v = V_rx/p_inc, the receiver's response; R_tx, R_rx the
  stacks' reflection coefficients seen from the fluid (loaded by R_s, Z_L); n ≥ 1 the reverberations, 2L/c apart.
- D(z) = (jω/(jω + ω_c))^m, ω_c = z c / w0²: the coupling of two Gaussian modes z apart (m = 1/2 per transverse
  dimension of a rectangular face, w0 = a·√(2/π); m = 1 for a circular one, w0 = a/√2), matching the far-field
  on-axis amplitude of a strip / piston pair, → 1 in the near field; its phase is the Gouy phase. With D = 1 and
  every order (``reverb_orders = −1``) the series is the exact 1-D transfer-matrix chain (tests check it).
- M_n: misalignment (effect), lateral overlap × tilt phase averaging (:func:`misalignment_factor`).
- Wall echo (effect): the image path L_w = √(L² + (2w)²) off a side wall, a = R_wall · κ · D(L_w) · e^{−jkL_w}, κ
  (``wall_coupling``) fitted (notes B.8: the far-field directivity of a 70 × 25 mm piston puts it below −60 dB),
  or a delayed copy of the received signal, either through a first-order low-pass (:func:`wall_echo_path`).
- Crosstalk (effect): the Tx terminal voltage through a stray capacitance C_x into the Rx node, plus an in-phase
  tap g_r and a derivative tap τ_d·jω of V_oc (:func:`crosstalk_path`).
- Amplifier bandwidth (first-order HP/LP) and ``output_gain`` multiply the whole.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit, prange

from sysid.errors import ConfigError
from twins.acoustic import chaincache as cc
from twins.acoustic.amplifier import amplifier_bandwidth
from twins.acoustic.fluids import FluidState, fluid_state
from twins.acoustic.layers import Layer, chain, input_impedance, layer_matrix, propagate_forward
from twins.acoustic.materials import PIEZOS, SOLIDS, Piezo
from twins.acoustic.transducer import (
    electrical_impedance,
    face_impedance,
    parallel_rc,
    plate_two_port,
    receive_voltage,
    transmit,
)

__all__ = [
    "ChannelGeometry",
    "geometry",
    "channel_parts",
    "frequency_response",
    "spreading_factor",
    "misalignment_factor",
    "wall_path_length",
    "crosstalk_path",
    "wall_echo_path",
]


@dataclass(frozen=True)
class ChannelGeometry:
    """The effective medium and geometry after the effects are applied (what the 'true' tank is)."""

    distance_m: float
    fluid: FluidState
    piezo: Piezo
    area_m2: float
    misaligned: bool
    wall_echo: bool
    crosstalk: bool


def geometry(p, effects=frozenset()) -> ChannelGeometry:
    """Effective geometry and fluid for parameters ``p`` with the switched-on ``effects``."""
    d = p.distance_m + (p.distance_offset_m if "distance_offset" in effects else 0.0)
    if d < 0:
        raise ConfigError(f"distance_m + distance_offset_m = {d} m is negative")
    T = p.temperature_c + (p.temperature_offset_k if "temperature_offset" in effects else 0.0)
    fluid_name = p.mismatch_fluid if "fluid_mismatch" in effects else p.fluid
    fl = fluid_state(fluid_name, T, p.salinity_psu)
    pz = PIEZOS[p.piezo]
    if p.pzt_qm > 0:
        pz = Piezo(pz.name, pz.density, pz.c33d, pz.e33, pz.eps33s_rel, p.pzt_qm, pz.tan_delta, pz.source)
    area = p.plate_width_m * p.plate_height_m if p.aperture == "rectangular" else np.pi * p.aperture_radius_m**2
    return ChannelGeometry(d, fl, pz, area, "misalignment" in effects, "wall_echo" in effects, "crosstalk" in effects)


def spreading_factor(f_hz: np.ndarray, z_m: float, speed: float, p) -> np.ndarray:
    """D(z, f): coupling of identical Tx/Rx apertures a distance z apart (Gaussian-mode equivalent, see module)."""
    f = np.asarray(f_hz, dtype=float)
    jw = 2j * np.pi * f
    if not p.diffraction or z_m <= 0:
        return np.ones_like(jw)
    if p.aperture == "circular":
        w0sq = p.aperture_radius_m**2 / 2.0
        return jw / (jw + z_m * speed / w0sq)
    out = np.ones_like(jw)
    for size in (p.plate_width_m, p.plate_height_m):
        w0sq = (size / 2.0) ** 2 * 2.0 / np.pi
        out = out * np.sqrt(jw / (jw + z_m * speed / w0sq))
    return out


def misalignment_factor(f_hz: np.ndarray, speed: float, p, order: int = 0) -> np.ndarray:
    """Overlap × tilt factor of a misaligned receiver (documented approximation, plane-wave near field).

    Lateral offset δ: fraction of the Rx face inside the Tx beam footprint — rectangular 1 − δ/H (δ along the
    plate height H); circular: normalised overlap area of two discs. Tilt φ: a plane wave meeting the Rx face
    at angle φ has a linear phase k x sin φ across it; averaging over the face (height H) gives
    sinc(k (H/2) sin φ) with sinc(x) = sin x / x. Each round trip between the plates doubles the angle, so the
    reverberation of order n sees (2n + 1)φ.
    """
    f = np.asarray(f_hz, dtype=float)
    delta = p.misalignment_offset_m
    if p.aperture == "circular":
        s = min(delta / (2.0 * p.aperture_radius_m), 1.0)
        overlap = (2.0 / np.pi) * (np.arccos(s) - s * np.sqrt(1.0 - s * s))
        half = p.aperture_radius_m
    else:
        overlap = max(1.0 - delta / p.plate_height_m, 0.0)
        half = p.plate_height_m / 2.0
    phi = np.deg2rad(p.misalignment_tilt_deg) * (2 * order + 1)
    x = 2 * np.pi * f / speed * half * np.sin(phi)
    return overlap * np.sinc(x / np.pi)


def wall_path_length(distance_m: float, wall_distance_m: float) -> float:
    """Length of the single-bounce image path off a side wall parallel to the axis: √(L² + (2w)²)."""
    return float(np.hypot(distance_m, 2.0 * wall_distance_m))


def _layers(p, fl: FluidState) -> tuple[Layer, Layer]:
    ep, st = SOLIDS["epoxy"], SOLIDS[p.steel]
    return (
        Layer(ep.density, ep.speed, p.epoxy_thickness_m, ep.alpha0_np_m, ep.alpha_power),
        Layer(st.density, st.speed, p.steel_thickness_m, st.alpha0_np_m, st.alpha_power),
    )


def channel_parts(f_hz: np.ndarray, p, effects=frozenset()) -> dict[str, Any]:
    """All factors of H at positive frequencies ``f_hz`` (> 0): t_tx, r_tx, r_rx, r_v, v_tx, z_el, k, ..."""
    f = np.asarray(f_hz, dtype=float)
    if np.any(f <= 0):
        raise ValueError("channel_parts needs f > 0")
    g = geometry(p, effects)
    stack_key = (cc.grid_key(f), _stack_key(p, g))  # hashed once: the stacks' cache key and a part of the fluid's
    key = (*stack_key, dataclasses.astuple(g.fluid))
    return {**cc.FLUID.get_or(key, lambda: _fluid_side(f, p, g, stack_key)), "geometry": g}


def _fluid_side(f: np.ndarray, p, g: ChannelGeometry, stack_key: tuple) -> dict[str, Any]:
    """The factors of H that depend on the stacks and the fluid but not on the gap (:func:`channel_parts`)."""
    area = g.area_m2
    fl = g.fluid
    zf = fl.density * fl.speed * area
    st = _stack(f, p, g, stack_key)
    m_tx, m_rx, tp, z_load = st["m_tx"], st["m_rx"], st["tp"], st["z_load"]
    # transmitter
    z_front = input_impedance(m_tx, zf)
    force0, u0, v_tx = transmit(tp, z_front, p.source_resistance_ohm)
    force1, _ = propagate_forward(m_tx, force0, u0)
    t_tx = force1 / area  # p⁺ per volt of V_oc
    z_tx_back = st["z_tx_back"]
    r_tx = (z_tx_back - zf) / (z_tx_back + zf)
    # receiver
    z_rx_in = st["z_rx_in"]
    r_rx = (z_rx_in - zf) / (z_rx_in + zf)
    force_in = area * (1.0 + r_rx)
    _, u2 = propagate_forward(m_rx, force_in, force_in / z_rx_in)
    r_v = receive_voltage(tp, z_load) * u2  # V_rx per incident pressure [V/Pa]
    k = 2 * np.pi * f / fl.speed - 1j * fl.alpha(f)
    z_el = electrical_impedance(tp, z_front)
    return {
        "t_tx": t_tx,
        "r_tx": r_tx,
        "r_rx": r_rx,
        "r_v": r_v,
        "v_tx": v_tx,
        "z_el": z_el,
        "k": k,
        "z_load": z_load,
    }


def _stack_key(p, g: ChannelGeometry) -> tuple:
    """The values the stacks' parts depend on (besides the frequency grid)."""
    epoxy, steel = _layers(p, g.fluid)
    return (
        dataclasses.astuple(epoxy),
        dataclasses.astuple(steel),
        g.area_m2,
        dataclasses.astuple(g.piezo),
        p.pzt_thickness_m,
        p.backing_rayl,
        p.source_resistance_ohm,
        p.rx_load_ohm,
        p.rx_load_capacitance_f,
    )


def _stack(f: np.ndarray, p, g: ChannelGeometry, key: tuple) -> dict[str, Any]:
    """The parts of the two transducer stacks that do not depend on the fluid or the gap (layer matrices, the
    plate's two-port, the impedances seen from the fluid side), cached by exactly what they depend on
    (:data:`twins.acoustic.chaincache.STACK`): a diagnosis that moves the temperature, the gap or the fluid
    recomputes only the fluid's part. ``key``: the grid's key and :func:`_stack_key`, as the caller computed them."""
    epoxy, steel = _layers(p, g.fluid)
    area = g.area_m2

    def make() -> dict[str, Any]:
        m_ep = layer_matrix(f, epoxy, area)
        m_st = layer_matrix(f, steel, area)
        tp = plate_two_port(f, g.piezo, p.pzt_thickness_m, area, p.backing_rayl * area)
        z_load = parallel_rc(f, p.rx_load_ohm, p.rx_load_capacitance_f)
        m_rx = chain([m_st, m_ep])  # fluid → PZT face
        return {
            "m_tx": chain([m_ep, m_st]),  # PZT face → fluid
            "m_rx": m_rx,
            "tp": tp,
            "z_load": z_load,
            "z_tx_back": input_impedance(m_st, input_impedance(m_ep, face_impedance(tp, p.source_resistance_ohm))),
            "z_rx_in": input_impedance(m_rx, face_impedance(tp, z_load)),
        }

    return cc.STACK.get_or(key, make)


def frequency_response(
    f_hz: np.ndarray,
    p,
    effects=frozenset(),
    parts: dict | None = None,
    direct_only: bool = False,
    include_amplifier: bool = True,
) -> np.ndarray:
    """H(f) = V_rx/V_oc [V/V] of the linear chain as configured (effects included); H(0) = 0.

    ``direct_only`` keeps only the direct arrival (gated: no reverberation, no echo, no crosstalk).
    ``include_amplifier`` multiplies by the amplifier's bandwidth response (not its gain: the gain is in
    the amplifier, see :func:`twins.acoustic.amplifier.amplifier_voltage`).
    """
    f = np.abs(np.asarray(f_hz, dtype=float))
    out = np.zeros(f.shape, dtype=complex)
    pos = f > 0
    if not np.any(pos):
        return out
    fp = f[pos]
    g = geometry(p, effects)
    if parts is None:
        # the two-ports and the reverberation series depend on the core only: cached (:mod:`.chaincache`)
        key = (cc.grid_key(fp), cc.chain_key(p, effects), bool(direct_only))
        parts = cc.CHAIN.get_or(key, lambda: _chain(fp, p, effects, direct_only))
    else:
        parts = {**parts, "series_tr": _chain(fp, p, effects, direct_only, parts)["series_tr"]}
    L, c = g.distance_m, g.fluid.speed
    h = parts["series_tr"]
    if g.wall_echo and not direct_only:
        h = h + wall_echo_path(fp, p, parts, L, c)
    if g.crosstalk and not direct_only:
        h = h + crosstalk_path(fp, p, parts)
    if include_amplifier:
        key = (cc.grid_key(fp), p.amp_f_low_hz, p.amp_f_high_hz)
        h = h * cc.AMP_BANDWIDTH.get_or(key, lambda: amplifier_bandwidth(fp, p.amp_f_low_hz, p.amp_f_high_hz))
    out[pos] = h * p.output_gain
    return out


def _chain(fp: np.ndarray, p, effects, direct_only: bool, parts: dict | None = None) -> dict[str, Any]:
    """The parts of H at ``fp`` (> 0) that depend on the core only: :func:`channel_parts` and
    ``series_tr`` = T_tx·R_v·Σ_n (R_tx R_rx)^n e^{−jk(2n+1)L} D((2n+1)L) M_n (the direct path and the
    reverberations, before the wall echo, crosstalk, amplifier bandwidth and output gain)."""
    parts = dict(parts) if parts is not None else channel_parts(fp, p, effects)
    g: ChannelGeometry = parts["geometry"]
    L, c = g.distance_m, g.fluid.speed
    k = parts["k"]
    loop = parts["r_tx"] * parts["r_rx"] * np.exp(-2j * k * L)
    orders = 0 if direct_only else int(p.reverb_orders)
    if orders < 0:
        if p.diffraction or g.misaligned:
            raise ConfigError("reverb_orders=-1 (exact closed form) needs diffraction=false and no misalignment")
        series = np.exp(-1j * k * L) / (1.0 - loop)
    else:
        series = _series(2 * np.pi * fp, k, loop, L, c, orders, p, g.misaligned)
    parts["series_tr"] = parts["t_tx"] * parts["r_v"] * series
    parts["z_node"] = 1.0 / (1.0 / parts["z_load"] + 1.0 / parts["z_el"])
    parts.pop("geometry")
    return parts


def wall_echo_path(fp: np.ndarray, p, parts: dict[str, Any], L: float, c: float) -> np.ndarray:
    """The wall echo's term of H (effect ``wall_echo``), a delayed, filtered copy whose filter is fitted:

    * ``wall_echo_path = "image"``: the single-bounce image path of length L_w = √(L² + (2w)²),
      R_wall·κ·T_tx·R_v·D(L_w)·e^{−jkL_w} (its own spreading and absorption);
    * ``"copy"``: a copy of the whole received signal (direct arrival and its reverberations between the
      plates) delayed by (L_w − L)/c and scaled by R_wall·κ — an echo that reverberates like the direct wave;

    either one times a first-order low-pass 1/(1 + jf/f_e) (``wall_echo_cutoff_hz`` = f_e; 0 = none): the
    frequency-dependent loss of a rough or absorbing wall."""
    a = p.wall_reflection * p.wall_coupling
    lw = wall_path_length(L, p.wall_distance_m)
    if getattr(p, "wall_echo_path", "image") == "copy":
        e = a * parts["series_tr"] * np.exp(-2j * np.pi * fp * ((lw - L) / c))
    else:
        e = parts["t_tx"] * parts["r_v"] * (a * spreading_factor(fp, lw, c, p) * np.exp(-1j * parts["k"] * lw))
    fc = float(getattr(p, "wall_echo_cutoff_hz", 0.0))
    return e / (1.0 + 1j * fp / fc) if fc > 0 else e


def crosstalk_path(fp: np.ndarray, p, parts: dict[str, Any]) -> np.ndarray:
    """H_x(f) of the electrical coupling paths from the drive into the Rx node (effect ``crosstalk``), per volt
    of V_oc: the stray capacitance C_x from the Tx terminal, V_tx·Z_node/(Z_node + 1/(jωC_x)), plus two
    short taps of the drive itself, g_r + τ_d·jω: an in-phase path g_r (a resistive divider or a common
    ground impedance, ``crosstalk_resistive``) and a derivative path τ_d (a capacitance into a resistive node,
    τ_d = R·C > 0, or a mutual inductance, either sign: ``crosstalk_derivative_s``)."""
    jw = 2j * np.pi * fp
    z_node = parts["z_node"]
    zc = 1.0 / (jw * p.crosstalk_capacitance_f) if p.crosstalk_capacitance_f > 0 else np.inf
    h = parts["v_tx"] * z_node / (z_node + zc)
    g_r = float(getattr(p, "crosstalk_resistive", 0.0))
    tau = float(getattr(p, "crosstalk_derivative_s", 0.0))
    if g_r or tau:
        h = h + (g_r + tau * jw)
    return h


def _spreading_constants(p) -> tuple[int, float, float]:
    """(mode, 1/w0x², 1/w0y²) for the compiled series: mode 0 none, 1 rectangular, 2 circular."""
    if not p.diffraction:
        return 0, 0.0, 0.0
    if p.aperture == "circular":
        return 2, 2.0 / p.aperture_radius_m**2, 0.0
    return (1, np.pi / (2.0 * (p.plate_width_m / 2.0) ** 2), np.pi / (2.0 * (p.plate_height_m / 2.0) ** 2))


def _series(
    w: np.ndarray, k: np.ndarray, loop: np.ndarray, L: float, c: float, orders: int, p, misaligned: bool
) -> np.ndarray:
    """Σ_{n=0..orders} e^{−jk(2n+1)L} (R_tx R_rx e^{−2jkL})^n D((2n+1)L) M_n, compiled (same maths as
    :func:`spreading_factor` and :func:`misalignment_factor`, checked against them in the tests)."""
    mode, ix, iy = _spreading_constants(p)
    if misaligned:
        if p.aperture == "circular":
            s = min(p.misalignment_offset_m / (2.0 * p.aperture_radius_m), 1.0)
            overlap = (2.0 / np.pi) * (np.arccos(s) - s * np.sqrt(1.0 - s * s))
            half = p.aperture_radius_m
        else:
            overlap = max(1.0 - p.misalignment_offset_m / p.plate_height_m, 0.0)
            half = p.plate_height_m / 2.0
        tilt = float(np.deg2rad(p.misalignment_tilt_deg))
    else:
        overlap, half, tilt = 1.0, 0.0, 0.0
    return _series_kernel(
        np.ascontiguousarray(w, dtype=np.float64),
        np.ascontiguousarray(k, dtype=np.complex128),
        np.ascontiguousarray(loop, dtype=np.complex128),
        float(L),
        float(c),
        int(orders),
        mode,
        float(ix),
        float(iy),
        bool(misaligned),
        float(overlap),
        float(half),
        tilt,
    )


@njit(cache=True, parallel=True)
def _series_kernel(w, k, loop, L, c, orders, mode, ix, iy, misaligned, overlap, half, tilt):  # pragma: no cover
    out = np.empty(w.shape[0], dtype=np.complex128)
    for i in prange(w.shape[0]):
        jw = 1j * w[i]
        term = np.exp(-1j * k[i] * L)
        acc = 0j
        kr = w[i] / c
        for n in range(orders + 1):
            z = (2 * n + 1) * L
            if mode == 1:
                fac = np.sqrt(jw * jw / ((jw + z * c * ix) * (jw + z * c * iy)))
            elif mode == 2:
                fac = jw / (jw + z * c * ix)
            else:
                fac = 1.0 + 0j
            if misaligned:
                x = kr * half * np.sin((2 * n + 1) * tilt)
                fac = fac * overlap * (np.sin(x) / x if x != 0.0 else 1.0)
            acc += term * fac
            term = term * loop[i]
        out[i] = acc
    return out
