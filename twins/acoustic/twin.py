"""AcousticTwin: the piezoacoustic transmission channel of dissertation §3.2 / ch. 5 as a grey-box twin.

    x [V, generator] → amplifier (memoryless NL, V_oc = 2·G_v·NL(x), R_s = 50 Ω)
      → linear chain H(f) = V_rx/V_oc (Mason/Kino Tx, epoxy, steel, fluid with reverberation and spreading,
        steel, epoxy, Mason/Kino Rx into its load; wall echo, crosstalk, amplifier bandwidth)
      → measurement (noise, ADC) → y [V]

The linear chain is applied by FFT convolution with its impulse response h (from H on a grid long enough
for every summed reverberation and echo, so nothing wraps around); the amplifier nonlinearity acts sample
by sample before it. :meth:`frequency_response`, :meth:`amplifier` and :meth:`measure` expose the three
stages separately for the FMU export (interfaces.md): simulate(u) = measure(h ∗ amplifier(u)).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import scipy.fft
from scipy import signal as sps

from sysid.config import coerce
from sysid.data.record import Record
from sysid.errors import ConfigError
from twins.acoustic import chaincache as cc
from twins.acoustic.amplifier import amplifier_voltage, sample_amplifier
from twins.acoustic.channel import frequency_response, geometry, wall_path_length
from twins.acoustic.params import AcousticParams
from twins.acoustic.protocols import BAND_HZ, FS_ACQ, PROTOCOLS, RECIPE_KEEP, apply_recipe, excitation
from twins.base import EffectSpec, Twin

__all__ = ["AcousticTwin", "EFFECTS"]

_T = "acoustic"
_TOF_GROUP = "time_of_flight"

EFFECTS: dict[str, EffectSpec] = {
    "measurement_noise": EffectSpec(
        "measurement_noise",
        _T,
        "white Gaussian noise of the receiver/scope front end",
        "white residual, flat spectrum, uncorrelated with u at every lag",
        {"std": "noise_v"},
        default_on=True,
    ),
    "adc_quantization": EffectSpec(
        "adc_quantization",
        _T,
        "scope ADC: uniform quantisation to adc_bits over ±adc_range_v, clipping beyond",
        "uniform residual within ±LSB/2 (LSB = 2·range/2^bits); flat-topped output where |y| reaches the range",
        {"bits": "adc_bits", "range": "adc_range_v"},
        default_on=True,
    ),
    "amplifier_compression": EffectSpec(
        "amplifier_compression",
        _T,
        "AM/AM compression of the RF power amplifier: a monotone limiter family "
        "(Rapp curve whose smoothness spans tanh-like to a hard clip, or a cubic soft clip; optionally asymmetric)",
        "residual at 3f, 5f (odd harmonics) growing faster than the drive; gain loss at large amplitude; "
        "r_u²'e² correlation test fails",
        {"model": "amp_compression", "sat": "amp_sat_v", "p": "amp_smoothness", "asymmetry": "amp_asymmetry"},
        default_on=True,
    ),
    "amplifier_even_distortion": EffectSpec(
        "amplifier_even_distortion",
        _T,
        "even-order term k2·v²/A_sat of the amplifier (push-pull imbalance)",
        "residual at 2f (and near DC, removed by the AC-coupled chain); r_u²'e correlation test fails",
        {"k2": "amp_even_ratio"},
    ),
    "wall_echo": EffectSpec(
        "wall_echo",
        _T,
        "tank side-wall echo, delayed by (√(L²+4w²) − L)/c after the direct arrival: the image "
        "path or a delayed copy of the received signal, through a fitted first-order low-pass",
        "residual is a delayed, scaled copy of the direct arrival: cross-correlation of e with the "
        "simulated output peaks at the geometric extra delay",
        {
            "distance": "wall_distance_m",
            "reflection": "wall_reflection",
            "coupling": "wall_coupling",
            "path": "wall_echo_path",
            "cutoff": "wall_echo_cutoff_hz",
        },
    ),
    "crosstalk": EffectSpec(
        "crosstalk",
        _T,
        "electrical coupling paths from the drive into the Rx node: a stray capacitance from "
        "the Tx terminal, an in-phase (resistive / common-ground) tap and a derivative (capacitive into a "
        "resistive node, or inductive) tap of the drive",
        "residual with no acoustic delay: correlated with u at lag 0 (before the time of flight)",
        {
            "capacitance": "crosstalk_capacitance_f",
            "resistive": "crosstalk_resistive",
            "derivative": "crosstalk_derivative_s",
        },
    ),
    "temperature_offset": EffectSpec(
        "temperature_offset",
        _T,
        "fluid temperature differs from the assumed one (sound speed c(T))",
        "time-of-flight shift (≈ −123 ns/K at 100 mm of water): residual ∝ dy/dt, cross-correlation peak off 0; "
        "reverberation comb spacing c/2L changes",
        {"dT": "temperature_offset_k"},
        group=_TOF_GROUP,
    ),
    "distance_offset": EffectSpec(
        "distance_offset",
        _T,
        "plate gap differs from the assumed one",
        "time-of-flight shift (L/c): residual ∝ dy/dt; comb spacing c/2L changes",
        {"dd": "distance_offset_m"},
        group=_TOF_GROUP,
    ),
    "fluid_mismatch": EffectSpec(
        "fluid_mismatch",
        _T,
        "the tank holds another fluid (e.g. seawater instead of distilled water)",
        "time-of-flight shift and a small gain change (fluid impedance); residual ∝ dy/dt",
        {"fluid": "mismatch_fluid"},
        group=_TOF_GROUP,
    ),
    "misalignment": EffectSpec(
        "misalignment",
        _T,
        "lateral offset (overlap loss) and tilt (phase averaging across the Rx face)",
        "frequency-dependent gain loss growing with f (tilt) plus a flat loss (offset); reverberations decay "
        "faster than the aligned model predicts",
        {"offset": "misalignment_offset_m", "tilt": "misalignment_tilt_deg"},
    ),
}

_SINGLE_PRECISION_FROM = 1 << 21  # samples
_OLS_MIN_BLOCK = 1 << 20  # smallest overlap-save transform
_TAIL_TOL = 1e-6  # energy fraction allowed in the last eighth of h (wrap-around below ≈ −60 dB)
_RING_S = 1.0e-3  # margin after the last summed arrival for the transducers' ringing [s] (tail < −60 dB)


class AcousticTwin(Twin):
    """Piezoacoustic transmission: amplifier → PZT|epoxy|steel|fluid|steel|epoxy|PZT → scope (dissertation §3.2)."""

    name = _T
    Params = AcousticParams
    EFFECTS = EFFECTS
    PROTOCOLS = PROTOCOLS
    units = {"u": "V", "y": "V"}
    CALIBRATION_PARAMS = ("pzt_thickness_m", "steel_thickness_m", "epoxy_thickness_m", "output_gain")

    def __init__(self, params: Any = None, effects=None, seed: int | None = 0):
        super().__init__(params, effects, seed)
        self.impulse_tail_energy_: float | None = None

    # ------------------------------------------------------------------ the three stages (interfaces.md)
    def frequency_response(self, f_hz, direct_only: bool = False, include_amplifier: bool = True) -> np.ndarray:
        """Complex H(f) = V_rx/V_oc of the linear chain as configured (echoes, crosstalk, misalignment, …).

        Multiply ``amplifier(x)`` by it (in the frequency domain) to get the noise-free output; H(0) = 0.
        (:meth:`simulate` additionally sets H = 0 above ``model_max_hz``, where |H| < −74 dB re its peak.)
        """
        return frequency_response(
            np.asarray(f_hz, dtype=float),
            self.params,
            self.effects,
            direct_only=direct_only,
            include_amplifier=include_amplifier,
        )

    def amplifier(self, x) -> np.ndarray:
        """Open-circuit amplifier voltage V_oc [V] for the generator signal ``x`` [V] (memoryless)."""
        p = self.params
        return amplifier_voltage(
            x,
            p.amp_gain_db,
            p.amp_compression if self.has("amplifier_compression") else None,
            p.amp_sat_v,
            p.amp_smoothness,
            p.amp_even_ratio if self.has("amplifier_even_distortion") else 0.0,
            p.amp_asymmetry,
        )

    def sample_amplifier(self):
        """:meth:`amplifier` as a ``float -> float`` function for one sample at a time (same arithmetic), or
        None where the compression has no per-sample form (the FMU core then calls :meth:`amplifier`)."""
        p = self.params
        return sample_amplifier(
            p.amp_gain_db,
            p.amp_compression if self.has("amplifier_compression") else None,
            p.amp_sat_v,
            p.amp_smoothness,
            p.amp_even_ratio if self.has("amplifier_even_distortion") else 0.0,
            p.amp_asymmetry,
        )

    def sample_measure(self, fs: float):
        """:meth:`measure` as ``(y: float, rng) -> float`` for one sample at a time: the same float32 noise
        draw from ``rng``, the same arithmetic (noise scaled in float32, added in float64; clip; round half to
        even, the sign of zero kept; times the LSB), so a run of samples equals :meth:`measure` of the block."""
        p = self.params
        noise = np.float32(p.noise_v) if self.has("measurement_noise") and p.noise_v > 0 else None
        adc = self.has("adc_quantization")
        lsb = 2.0 * p.adc_range_v / 2**p.adc_bits
        lo, hi = -p.adc_range_v, p.adc_range_v - lsb
        f32 = np.float32

        def measure(y: float, rng: np.random.Generator) -> float:
            y = float(y)
            if noise is not None:
                y += float(noise * rng.standard_normal(dtype=f32))
            if adc:
                y = lo if y < lo else hi if y > hi else y
                if y == y:  # NaN passes through, as in numpy
                    q = round(y / lsb)
                    y = q * lsb if q else math.copysign(0.0, y) * lsb
            return y

        return measure

    def measure(self, y, fs: float, rng: np.random.Generator | None = None) -> np.ndarray:
        """Scope: add white noise (``measurement_noise``) then quantise/clip (``adc_quantization``)."""
        p = self.params
        y = np.array(y, dtype=float, copy=True)
        if self.has("measurement_noise") and p.noise_v > 0:
            rng = rng if rng is not None else np.random.default_rng(self.seed)
            # single-precision draws (half the time for 10^7 samples; noise needs no 53-bit mantissa)
            y += p.noise_v * rng.standard_normal(y.shape, dtype=np.float32)
        if self.has("adc_quantization"):
            lsb = 2.0 * p.adc_range_v / 2**p.adc_bits
            np.clip(y, -p.adc_range_v, p.adc_range_v - lsb, out=y)
            np.round(y / lsb, out=y)
            y *= lsb
        return y

    def make_stepper(self, fs: float):
        """Not provided: the chain is an FFT convolution with a ≈ 5 ms impulse response (reverberation), which
        has no compact sample-by-sample form here. The FMU export builds its own core from
        :meth:`frequency_response`, :meth:`amplifier` and :meth:`measure` (interfaces.md)."""
        raise NotImplementedError(
            "acoustic twin: no stepper; build the FMU core from frequency_response(), amplifier() and measure()"
        )

    # ------------------------------------------------------------------ linear chain in the time domain
    def response_duration(self) -> float:
        """Time [s] after which every summed arrival (reverberation orders, wall path) has passed, plus ringing."""
        p = self.params
        g = geometry(p, self.effects)
        orders = max(int(p.reverb_orders), 0)
        path = (2 * orders + 1) * g.distance_m
        if g.wall_echo:
            extra = wall_path_length(g.distance_m, p.wall_distance_m)
            path = max(path, path + extra - g.distance_m if p.wall_echo_path == "copy" else extra)
        slow = 2 * (p.steel_thickness_m / 5000.0 + p.epoxy_thickness_m / 2000.0)
        if p.reverb_orders < 0:  # closed form: all orders; stop where |R_tx R_rx|^n < 1e-4
            path = 80 * 2 * g.distance_m
        return path / g.fluid.speed + slow + _RING_S

    def impulse_response(self, fs: float, n: int | None = None) -> np.ndarray:
        """h[k] of the linear chain at rate ``fs`` (its first ``n`` samples when given).

        H is evaluated on the rfft grid of a length covering :meth:`response_duration`, so the circular
        inverse transform does not wrap any summed arrival back onto the start; if the last eighth of h still
        holds more than ``_TAIL_TOL`` of its energy (slow ringing), the grid is doubled (at most 3 times).
        ``impulse_tail_energy_`` keeps the fraction reached.
        """
        entry = self._linear_entry(float(fs))
        self.impulse_tail_energy_ = entry["tail"]
        h = entry["h"]
        return h if n is None else h[:n]

    def within(self, window_s: float, margin: int = 2) -> AcousticTwin:
        """This twin summing only the reverberation orders that arrive within ``window_s`` [s], plus ``margin``
        more (a gap or sound speed the diagnosis moves shifts the arrivals; a band-limited arrival has an onset).

        By causality the others add nothing to the first ``window_s`` of the response but their band-limited
        precursors (at most a few 1e-4 of the signal when H is cut at ``model_max_hz`` below ``fs/2``, 1e-6 or
        less otherwise), and summing them lengthens the grid H is evaluated on (a 0.4 ms record of a 5 ms
        response): :meth:`follow_records` applies it for a diagnosis."""
        p = self.params
        if p.reverb_orders <= 0:  # gated, or the closed form of every order
            return self
        g = geometry(p, self.effects)
        arriving = int(np.floor((window_s * g.fluid.speed / g.distance_m - 1.0) / 2.0)) + 1
        keep = max(arriving + margin, 0)
        return self if keep >= p.reverb_orders else self.with_params(reverb_orders=keep)

    def follow_records(self, est: Record, val: Record) -> tuple[AcousticTwin, list[str]]:
        """The diagnosis's range rule (:func:`twins.discrepancy.ranges.follow_record`): sum only the
        reverberation orders that can reach the longer record (:meth:`within`)."""
        window = max(len(est) / est.fs, len(val) / val.fs)
        tw = self.within(window)
        if tw is self:
            return self, []
        note = (
            f"reverberation orders summed: {tw.params.reverb_orders} of {self.params.reverb_orders} (the others arrive "
            f"after the {1e3 * window:.3g} ms records)"
        )
        return tw, [note]

    def _linear_entry(self, fs: float) -> dict[str, Any]:
        """h at ``fs`` with its tail energy and spectra, shared by every twin whose linear chain is the same
        (:mod:`twins.acoustic.chaincache`: a diagnosis's amplifier trials reuse it)."""
        n_grid = scipy.fft.next_fast_len(max(int(np.ceil(self.response_duration() * fs)), 256), real=True)
        key = (fs, n_grid, cc.linear_key(self.params, self.effects))
        return cc.LINEAR.get_or(key, lambda: self._compute_h(fs, n_grid))

    def _compute_h(self, fs: float, n_grid: int) -> dict[str, Any]:
        for _ in range(4):
            f = np.fft.rfftfreq(n_grid, 1.0 / fs)
            H = np.zeros(f.size, dtype=complex)
            keep = f <= self.params.model_max_hz
            H[keep] = self.frequency_response(f[keep])
            h = scipy.fft.irfft(H, n_grid)
            e = h * h
            total = float(e.sum())
            tail = float(e[-n_grid // 8 :].sum()) / total if total > 0 else 0.0
            if tail <= _TAIL_TOL:
                break
            n_grid = scipy.fft.next_fast_len(2 * n_grid, real=True)
        return {"h": h, "tail": tail, "spectra": {}}

    def _h_spectrum(self, fs: float, m: int, nfft: int, dtype) -> np.ndarray:
        """rfft of the first ``m`` samples of h zero-padded to ``nfft`` (kept with h in the cache)."""
        entry = self._linear_entry(fs)
        key = (m, nfft, np.dtype(dtype).str)
        spec = entry["spectra"].get(key) if cc.enabled() else None
        if spec is None:
            spec = scipy.fft.rfft(entry["h"][:m].astype(dtype), nfft)
            spec.flags.writeable = False
            if cc.enabled():
                if len(entry["spectra"]) > 4:
                    entry["spectra"].clear()
                entry["spectra"][key] = spec
        return spec

    def linear(self, v, fs: float) -> np.ndarray:
        """Noise-free output of the linear chain for the open-circuit amplifier voltage ``v`` (linear convolution).

        Overlap-save: blocks of ``nfft`` ≥ 2·len(h) points, each one rfft/irfft pair, with the spectrum of h
        computed once — for 10⁷ samples about 3× faster than one transform of the whole record (the blocks
        stay in cache). Long records use single-precision transforms (relative error ~1e-7, far below an
        8-bit ADC's 2⁻⁷).
        """
        v = np.asarray(v, dtype=float)
        n = v.shape[0]
        h = self.impulse_response(fs, n)
        m = h.size
        dtype = np.float32 if n >= _SINGLE_PRECISION_FROM else np.float64
        single = scipy.fft.next_fast_len(n + m - 1, real=True)
        nfft = scipy.fft.next_fast_len(max(2 * m, _OLS_MIN_BLOCK), real=True)
        if single <= nfft:  # short record: one block
            spec = scipy.fft.rfft(v.astype(dtype, copy=False), single)
            spec *= self._h_spectrum(float(fs), m, single, dtype)
            return scipy.fft.irfft(spec, single)[:n].astype(float)
        hspec = self._h_spectrum(float(fs), m, nfft, dtype)
        step = nfft - m + 1  # new output samples per block
        out = np.empty(n)
        buf = np.zeros(nfft, dtype=dtype)
        for start in range(0, n, step):
            stop = min(start + step, n)
            lo = max(start - (m - 1), 0)  # input needed: [start − m + 1, stop)
            buf.fill(0.0)
            offset = (m - 1) - (start - lo)
            buf[offset : offset + (stop - lo)] = v[lo:stop]
            spec = scipy.fft.rfft(buf)
            spec *= hspec
            out[start:stop] = scipy.fft.irfft(spec, nfft)[m - 1 : m - 1 + (stop - start)]
        return out

    def simulate(self, u, fs: float) -> np.ndarray:
        """Output y [V] at the Rx for the generator signal ``u`` [V] sampled at ``fs`` [Hz]."""
        u = np.asarray(u, dtype=float)
        if u.ndim != 1:
            raise ConfigError(f"acoustic twin is SISO: u must be 1-D, got shape {u.shape}")
        rng = np.random.default_rng(self.seed)
        return self.measure(self.linear(self.amplifier(u), fs), fs, rng)

    # ------------------------------------------------------------------ derived figures
    def time_of_flight(self, fs: float = FS_ACQ, band=BAND_HZ) -> float:
        """Arrival time [s] of the direct path, measured on the simulated response: envelope peak of the
        band-limited (Hann window over ``band``) direct-path impulse response, parabolic interpolation.
        Includes the group delay of transducers and plates, not only L/c."""
        n = scipy.fft.next_fast_len(int(np.ceil(max(4 * self.response_duration_direct(), 2e-4) * fs)), real=True)
        f = np.fft.rfftfreq(n, 1.0 / fs)
        H = self.frequency_response(f, direct_only=True, include_amplifier=False)
        win = np.zeros_like(f)
        inb = (f >= band[0]) & (f <= band[1])
        win[inb] = np.hanning(inb.sum() + 2)[1:-1]
        spec = np.zeros(n, dtype=complex)  # analytic signal: positive frequencies doubled
        spec[: f.size] = 2.0 * H * win
        env = np.abs(np.fft.ifft(spec))
        i = int(np.argmax(env))
        peak = float(i)
        if 0 < i < n - 1:  # parabolic interpolation of the peak
            a, b, c = env[i - 1], env[i], env[i + 1]
            den = a - 2 * b + c
            peak = i + (0.5 * (a - c) / den if den != 0 else 0.0)
        return float(peak / fs)

    def response_duration_direct(self) -> float:
        g = geometry(self.params, self.effects)
        return g.distance_m / g.fluid.speed + 50e-6

    def spectrum_metrics(self, band=BAND_HZ, points: int = 2000) -> dict[str, float]:
        """Figures of the channel in ``band`` (the quantities of ``piezotwin sweep``).

        From the direct-path (gated) |V_rx/V_oc|: ``peak_frequency_hz`` (parabolic interpolation of the dB
        peak), ``peak_gain_db``, ``bandwidth_hz`` (−3 dB, crossings interpolated linearly;
        ``bandwidth_limited_by_band`` when a crossing lies outside ``band``). From the full chain (reverberation
        comb and effects included): ``peak_frequency_full_hz`` and ``peak_gain_full_db``, the best single
        frequency for a continuous-wave link in this tank. Plus :meth:`time_of_flight`, L/c and c.
        """
        f = np.linspace(band[0], band[1], points)
        df = f[1] - f[0]
        g_db = 20 * np.log10(np.abs(self.frequency_response(f, direct_only=True, include_amplifier=False)) + 1e-300)
        i = int(np.argmax(g_db))
        f_pk, g_pk = _parabolic_peak(f, g_db, i)
        lo = i
        while lo > 0 and g_db[lo - 1] >= g_pk - 3.0:
            lo -= 1
        hi = i
        while hi < f.size - 1 and g_db[hi + 1] >= g_pk - 3.0:
            hi += 1
        limited = lo == 0 or hi == f.size - 1
        f_lo = f[lo] if lo == 0 else f[lo] - df * (g_db[lo] - (g_pk - 3.0)) / (g_db[lo] - g_db[lo - 1])
        f_hi = f[hi] if hi == f.size - 1 else f[hi] + df * (g_db[hi] - (g_pk - 3.0)) / (g_db[hi] - g_db[hi + 1])
        ff = np.linspace(band[0], band[1], 10 * points)  # the reverberation comb needs a finer grid (7.5 kHz teeth)
        full_db = 20 * np.log10(np.abs(self.frequency_response(ff, include_amplifier=False)) + 1e-300)
        j = int(np.argmax(full_db))
        f_full, g_full = _parabolic_peak(ff, full_db, j)
        geo = geometry(self.params, self.effects)
        return {
            "peak_frequency_hz": f_pk,
            "peak_gain_db": g_pk,
            "bandwidth_hz": float(f_hi - f_lo),
            "bandwidth_limited_by_band": bool(limited),
            "peak_frequency_full_hz": f_full,
            "peak_gain_full_db": g_full,
            "time_of_flight_s": self.time_of_flight(),
            "fluid_delay_s": geo.distance_m / geo.fluid.speed,
            "sound_speed_m_s": geo.fluid.speed,
        }

    def sweep_metrics(self, protocol: str | None = None, identify: bool = True) -> dict[str, Any]:
        """Figures of ``piezotwin sweep`` (see :func:`twins.acoustic.studies.sweep_metrics`)."""
        from twins.acoustic.studies import sweep_metrics

        return sweep_metrics(self, protocol, identify)

    def sweep_spectrum(self, band=(0.5e6, 2.0e6), points: int = 2000):
        """(f, {"direct": dB, "full": dB}) of |V_rx/V_oc| for the sweep report's spectrum plot."""
        from twins.acoustic.studies import sweep_spectrum

        return sweep_spectrum(self, band, points)

    # ------------------------------------------------------------------ protocols
    def generate(self, protocol: str, **options: Any) -> Record:
        """Run a protocol (``PROTOCOLS``). Options (strings from the CLI are coerced): see PROTOCOLS."""
        self.check_protocol(protocol)
        if protocol == "vna-sweep":
            return self._vna(**options)
        # warm-up of the periodic protocols: the whole impulse response (all summed reverberations), so the
        # record starts in the steady state the looping generator had reached before the scope triggered
        opts = {
            "duration": 0.1,
            "fs": FS_ACQ,
            "warmup_s": self.response_duration(),
            "awg_rate_hz": 10e6,
            "preprocess": False,
            "start": 0,
            "keep": RECIPE_KEEP[protocol],
        }
        unknown = set(options) - set(opts)
        if unknown:
            raise ConfigError(
                f"protocol {protocol}: unknown option(s) {', '.join(sorted(unknown))}; valid: {', '.join(opts)}"
            )
        for k, v in options.items():
            opts[k] = coerce(v, opts[k], k)
        fs, duration = float(opts["fs"]), float(opts["duration"])
        if not (fs > 0 and duration > 0 and float(opts["awg_rate_hz"]) > 0 and float(opts["warmup_s"]) >= 0):
            raise ConfigError(f"protocol {protocol}: fs, duration and awg_rate_hz must be positive, warmup_s >= 0")
        if not opts["preprocess"] and {"start", "keep"} & set(options):
            raise ConfigError(
                f"protocol {protocol}: options start/keep cut the preprocessed record; give preprocess=true"
            )
        n = int(round(duration * fs))
        periodic = protocol != "thesis-chirp-100ms"
        warm = int(round(float(opts["warmup_s"]) * fs)) if periodic else 0
        u_all, _, info = excitation(protocol, fs, (n + warm) / fs, self.seed, float(opts["awg_rate_hz"]))
        if periodic and warm:
            # the generator ran before the trigger: simulate the warm-up and discard it (steady-state record)
            y_all = self.simulate(u_all, fs)
            u, y = u_all[warm:], y_all[warm:]
        else:
            u, y = u_all, self.simulate(u_all, fs)
        meta = {
            "protocol": protocol,
            "protocol_options": {k: opts[k] for k in opts},
            "excitation": info,
            **self.config(),
        }
        rec = Record(u=u, y=y, fs=fs, units=dict(self.units), meta=meta, source=f"acoustic:{protocol}")
        if opts["preprocess"]:
            rec = apply_recipe(rec, int(opts["keep"]), int(opts["start"]))
        return rec

    def _vna(self, **options: Any) -> Record:
        opts = {"f_start": 100e3, "f_stop": 2.0e6, "points": 2000, "gated": False, "preprocess": False}
        unknown = set(options) - set(opts)
        if unknown:
            raise ConfigError(
                f"protocol vna-sweep: unknown option(s) {', '.join(sorted(unknown))}; valid: {', '.join(opts)}"
            )
        for k, v in options.items():
            opts[k] = coerce(v, opts[k], k)
        f0, f1, npts = float(opts["f_start"]), float(opts["f_stop"]), int(opts["points"])
        if not (0 < f0 < f1) or npts < 2:
            raise ConfigError("vna-sweep: need 0 < f_start < f_stop and points >= 2")
        f = np.linspace(f0, f1, npts)
        H = self.frequency_response(f, direct_only=bool(opts["gated"]), include_amplifier=False)
        if opts["preprocess"]:
            H = H * recipe_filter_response(f)
        mag_db = 20 * np.log10(np.abs(H) + 1e-300)
        meta = {
            "protocol": "vna-sweep",
            "kind": "frequency_response",
            "protocol_options": opts,
            "quantity": "20*log10|V_rx/V_oc| (u = frequency in Hz, fs = 1/df)",
            "phase_rad": np.angle(H).tolist(),
            **self.config(),
        }
        return Record(
            u=f, y=mag_db, fs=1.0 / (f[1] - f[0]), units={"u": "Hz", "y": "dB"}, meta=meta, source="acoustic:vna-sweep"
        )

    # ------------------------------------------------------------------ calibration
    def calibrate(self, data: Record, val: Record | None = None, names=None, **options: Any):
        """Fit stack parameters (default ``CALIBRATION_PARAMS``) to a measured record.

        A ``vna-sweep`` record (u = frequency, y = dB) is fitted in the frequency domain (log magnitude);
        a time record by free-run output error against the noise-free simulation.
        """
        from twins.acoustic.calibration import calibrate_acoustic

        return calibrate_acoustic(self, data, val=val, names=names, **options)


def _parabolic_peak(f: np.ndarray, y: np.ndarray, i: int) -> tuple[float, float]:
    """Vertex of the parabola through (f[i−1..i+1], y[i−1..i+1]) on a uniform grid; the sample at the ends."""
    if 0 < i < f.size - 1:
        a, b, c = y[i - 1], y[i], y[i + 1]
        den = a - 2 * b + c
        if den < 0:
            d = 0.5 * (a - c) / den
            return float(f[i] + d * (f[1] - f[0])), float(b - 0.25 * (a - c) * d)
    return float(f[i]), float(y[i])


def recipe_filter_response(f_hz) -> np.ndarray:
    """Magnitude the §3.2 recipe imposes on a spectrum: 100-point moving average at 100 MHz × the zero-phase
    fifth-order Butterworth band-pass (|H|²). The resampling to 6.75 MHz is flat in band (Kaiser design)."""
    from sysid.signals.preprocess import bandpass_design
    from twins.acoustic.protocols import FS_RECIPE, MA_SPAN

    f = np.asarray(f_hz, dtype=float)
    x = np.pi * f / FS_ACQ
    with np.errstate(invalid="ignore", divide="ignore"):
        ma = np.where(x == 0, 1.0, np.sin(MA_SPAN * x) / (MA_SPAN * np.sin(x)))
    sos = bandpass_design(FS_RECIPE, BAND_HZ[0], BAND_HZ[1], 5)
    _, hb = sps.sosfreqz(sos, worN=np.minimum(f, FS_RECIPE / 2 * 0.999), fs=FS_RECIPE)
    return np.abs(ma) * np.abs(hb) ** 2
