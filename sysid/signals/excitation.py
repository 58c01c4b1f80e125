"""Excitation signals (dissertation §2.2), in the manner of :mod:`scipy.signal`: arrays out, ``fs`` explicit.

- :func:`multisine` — eq. (2-1), built in the frequency domain with one inverse real FFT per period;
  random (seeded) or Schroeder phases, full / odd / odd-odd grids, randomly removed detection lines,
  several periods, amplitude as peak or RMS, crest factor reported.
- :func:`chirp` — eq. (2-2), linear or logarithmic sweep, periodic or not.
- :func:`sine` — eq. (2-3); :func:`stepped_sine` — one sine after the other with a settling time.
- :func:`prbs` — maximum-length binary sequence from a linear feedback shift register
  (:mod:`sysid.signals.pseudorandom`);
  :func:`aprbs` — amplitude-modulated PRBS (random levels held for random times).
- The dissertation's own signals, one call each: :func:`thesis_cantilever_multisine`,
  :func:`thesis_acoustic_multisine`, :func:`thesis_chirp`.

Every bad argument raises :class:`~sysid.errors.ConfigError` with one line naming it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sysid.config import make_rng, positive
from sysid.errors import ConfigError
from sysid.signals.checks import _integer_ratio, _n_samples
from sysid.signals.pseudorandom import PRBS_TAPS, aprbs, prbs

__all__ = [
    "multisine",
    "chirp",
    "sine",
    "stepped_sine",
    "prbs",
    "aprbs",
    "crest_factor",
    "thesis_cantilever_multisine",
    "thesis_acoustic_multisine",
    "thesis_chirp",
    "PRBS_TAPS",
]

GRIDS = ("full", "odd", "odd-odd")
PHASES = ("random", "schroeder")


# ---------------------------------------------------------------------------------------------- helpers
def crest_factor(u: np.ndarray) -> float:
    """Crest factor ``max|u| / rms(u)`` (1 for a square wave, sqrt(2) for a sine)."""
    u = np.asarray(u, dtype=float)
    rms = float(np.sqrt(np.mean(u * u)))
    if rms == 0.0:
        raise ConfigError("crest_factor: signal is identically zero")
    return float(np.max(np.abs(u))) / rms


# ---------------------------------------------------------------------------------------------- multisine
def multisine(
    fs: float,
    duration: float | None = None,
    band: tuple[float, float] = (0.0, None),  # type: ignore[assignment]
    components: int | None = None,
    resolution: float | None = None,
    amplitude: float = 1.0,
    rms: bool = False,
    phase: str = "random",
    grid: str = "full",
    detection_fraction: float = 0.0,
    periods: int = 1,
    seed: int | None = None,
    return_info: bool = False,
):
    r"""Multisine of eq. (2-1), :math:`u(t) = \sum_{k=1}^{n_f} A\cos(2\pi f_k t + \phi_k)`, built by inverse FFT.

    The lines lie on the DFT grid of one period :math:`T_0` and one inverse real FFT gives the time signal, so a
    whole number of periods has an exactly line spectrum (dissertation §2.2).

    Parameters
    ----------
    fs, duration, periods, resolution : float, float, int, float
        Sampling rate [Hz], length [s], periods in it, line spacing :math:`1/T_0` [Hz] (``fs/resolution`` an
        integer). The period is ``duration / periods``, or ``1/resolution`` repeated and cut to ``duration``
        (``info['periodic']`` says whether that is whole periods); without ``duration``, ``periods/resolution``.
    band : (fmin, fmax)
        Excited band [Hz], ends included, ``fmax`` below ``fs/2`` (None: just below it). DC is never excited.
    components : int, optional
        Lines taken evenly from the candidates in the band, first and last included (default all of them).
    amplitude : float
        Peak value ``max|u|``, or the RMS value when ``rms=True``.
    phase : {"random", "schroeder"}
        Uniform phases from ``seed``, or Schroeder's :math:`\phi_k = -k(k-1)\pi/n_f` (§2.2, [67]).
    grid : {"full", "odd", "odd-odd"}
        Candidate lines :math:`m = f/\Delta f`: all, odd (even distortion falls on empty lines), or
        :math:`m = 1 \bmod 4` (odd third-order distortion falls on :math:`m = 3 \bmod 4`).
    detection_fraction, seed : float, int
        Share in [0, 0.5] of the lines left out, one at random per block, to detect odd distortion; the seed of
        the phases and of those lines.
    return_info : bool
        Also return a dict: crest factor, excited frequencies and bins, detection bins, period, ``periodic``, phases.
    """
    fs = positive("fs", fs)
    if phase not in PHASES:
        raise ConfigError(f"phase must be one of {', '.join(PHASES)}, got {phase!r}")
    if grid not in GRIDS:
        raise ConfigError(f"grid must be one of {', '.join(GRIDS)}, got {grid!r}")
    amplitude = positive("amplitude", amplitude)
    periods = int(positive("periods", periods, integer=True))
    try:
        detection_fraction = float(detection_fraction)
    except (TypeError, ValueError):
        raise ConfigError(f"detection_fraction must be a number, got {detection_fraction!r}") from None
    if not 0.0 <= detection_fraction <= 0.5:
        raise ConfigError(f"detection_fraction must lie in [0, 0.5], got {detection_fraction}")

    # ---- period and total length
    if resolution is not None:
        resolution = positive("resolution", resolution)
        n0 = _integer_ratio(fs, resolution, "resolution must divide fs (samples per period fs/resolution)")
        if duration is not None:
            n_total = _n_samples(fs, positive("duration", duration))
            if periods != 1 and n_total != periods * n0:
                raise ConfigError(
                    f"periods={periods} disagrees with duration {duration} s and resolution {resolution:g} Hz;"
                    " give two of the three"
                )
        else:
            n_total = periods * n0
    elif duration is not None:
        n_total = _n_samples(fs, positive("duration", duration))
        if n_total % periods:
            raise ConfigError(f"duration {duration} s ({n_total} samples) is not divisible into {periods} periods")
        n0 = n_total // periods
    else:
        raise ConfigError("multisine needs duration or resolution (to fix the period)")
    if n0 < 4:
        raise ConfigError(f"multisine period of {n0} samples is too short")
    df = fs / n0

    # ---- band and candidate lines
    try:
        fmin, fmax = band
    except (TypeError, ValueError):
        raise ConfigError(f"band must be (fmin, fmax), got {band!r}") from None
    nyq = fs / 2.0
    fmin = 0.0 if fmin is None else float(fmin)
    fmax = (nyq - df / 2) if fmax is None else float(fmax)
    if not (math.isfinite(fmin) and math.isfinite(fmax)) or fmin < 0:
        raise ConfigError(f"band must be finite with fmin >= 0, got ({fmin:g}, {fmax:g}) Hz")
    if fmin >= fmax:
        raise ConfigError(f"band: fmin ({fmin:g} Hz) must be below fmax ({fmax:g} Hz)")
    if fmax >= nyq:
        raise ConfigError(f"band: fmax ({fmax:g} Hz) must be below the Nyquist frequency fs/2 = {nyq:g} Hz")
    eps = 1e-9
    m_lo = max(1, int(math.ceil(fmin / df - eps)))
    m_hi = int(math.floor(fmax / df + eps))
    m_hi = min(m_hi, (n0 - 1) // 2)  # strictly below Nyquist
    cand = np.arange(m_lo, m_hi + 1, dtype=np.int64)
    if grid == "odd":
        cand = cand[cand % 2 == 1]
    elif grid == "odd-odd":
        cand = cand[cand % 4 == 1]
    if cand.size == 0:
        raise ConfigError(f"no {grid} grid line of spacing {df:g} Hz lies in the band [{fmin:g}, {fmax:g}] Hz")
    if components is not None:
        nf = int(positive("components", components, integer=True))
        if nf > cand.size:
            raise ConfigError(
                f"components={nf} do not fit the resolution: the band [{fmin:g}, {fmax:g}] Hz holds {cand.size}"
                f" {grid}-grid lines of spacing {df:g} Hz (period {n0} samples); "
                "use a finer resolution or a longer period"
            )
        if nf < cand.size:
            pick = np.unique(np.round(np.linspace(0, cand.size - 1, nf)).astype(np.int64))
            cand = cand[pick]
    lines = cand

    rng = make_rng(seed)
    detection = np.empty(0, dtype=np.int64)
    if detection_fraction > 0:
        block = max(2, int(round(1.0 / detection_fraction)))
        nblocks = lines.size // block
        if nblocks == 0:
            raise ConfigError(
                f"detection_fraction={detection_fraction} needs at least {block} lines, have {lines.size}"
            )
        drop = np.arange(nblocks) * block + rng.integers(0, block, size=nblocks)
        detection = lines[drop]
        lines = np.delete(lines, drop)
    nf = lines.size

    if phase == "random":
        phi = rng.uniform(0.0, 2.0 * np.pi, size=nf)
    else:
        k = np.arange(1, nf + 1, dtype=np.float64)
        phi = np.mod(-k * (k - 1) * np.pi / nf, 2.0 * np.pi)

    # ---- one period by inverse real FFT: X[m] = (N0/2) e^{j phi} gives cos(2 pi m n / N0 + phi) of unit amplitude
    spec = np.zeros(n0 // 2 + 1, dtype=np.complex128)
    spec[lines] = (n0 / 2.0) * np.exp(1j * phi)
    import scipy.fft  # here, not at the top: every CLI start (the parser lists this module's choices) would pay it

    one = scipy.fft.irfft(spec, n=n0, workers=-1)
    if n_total == n0:
        u = one
    else:
        reps = -(-n_total // n0)
        u = np.tile(one, reps)[:n_total]
    peak = float(np.max(np.abs(u)))
    rms_val = float(np.sqrt(np.dot(u, u) / u.size))
    scale = amplitude / (rms_val if rms else peak)
    u *= scale
    if not return_info:
        return u
    info = {
        "crest_factor": peak / rms_val,
        "frequencies_hz": lines * df,
        "excited_bins": lines,
        "detection_bins": detection,
        "period_samples": n0,
        "resolution_hz": df,
        "periods": n_total / n0,
        "periodic": n_total % n0 == 0,
        "n_components": int(nf),
        "phases_rad": phi,
        "line_amplitude": scale,
        "grid": grid,
        "phase": phase,
    }
    return u, info


# ---------------------------------------------------------------------------------------------- chirp / sine
def chirp(
    fs: float,
    duration: float,
    f0: float,
    f1: float,
    amplitude: float = 1.0,
    method: str = "linear",
    periodic: bool = False,
    phase: float = 0.0,
    periods: int = 1,
) -> np.ndarray:
    r"""Swept sine of eq. (2-2), :math:`u(t) = A\cos(\theta(t) + \phi_0)`, sweeping ``f0`` -> ``f1`` over one
    period :math:`T_0` = ``duration / periods``.

    ``method="linear"``: instantaneous frequency :math:`f(t) = f_0 + (f_1 - f_0)t/T_0`, i.e. eq. (2-2)'s
    :math:`(at + b)t` with :math:`a = \pi(f_1 - f_0)/T_0` and :math:`b = 2\pi f_0` (the dissertation writes
    :math:`f_0 = k_1/T_0`, :math:`f_1 = k_2/T_0`). ``method="log"``: :math:`f(t) = f_0 (f_1/f_0)^{t/T_0}`
    (both frequencies > 0).

    ``periodic=True`` asks for eq. (2-2) proper: :math:`k_1 = f_0 T_0` and :math:`k_2 = f_1 T_0` must be
    integers (linear method only), so the sweep is repeated ``periods`` times with every period identical and
    its spectrum on the DFT grid of :math:`T_0`. Without ``periodic`` the sweep is repeated ``periods`` times
    as well, but no condition is imposed. ``amplitude`` is the peak value (half the peak-to-peak value).
    Frequencies must lie below ``fs/2``. The phase is evaluated in cycles from the sample index, so 10^7
    samples keep ~1e-9 rad accuracy.
    """
    fs = positive("fs", fs)
    duration = positive("duration", duration)
    amplitude = positive("amplitude", amplitude)
    periods = int(positive("periods", periods, integer=True))
    if method not in ("linear", "log"):
        raise ConfigError(f"chirp method must be 'linear' or 'log', got {method!r}")
    for name, f in (("f0", f0), ("f1", f1)):
        try:
            f = float(f)
        except (TypeError, ValueError):
            raise ConfigError(f"chirp {name} must be a number, got {f!r}") from None
        if not math.isfinite(f) or f < 0:
            raise ConfigError(f"chirp {name} must be >= 0 and finite, got {f}")
        if f >= fs / 2:
            raise ConfigError(f"chirp {name} ({f:g} Hz) must be below the Nyquist frequency fs/2 = {fs / 2:g} Hz")
    f0, f1 = float(f0), float(f1)
    if f0 == f1:
        raise ConfigError(f"chirp needs f0 != f1 (got {f0:g} Hz twice); use sine() for one frequency")
    n_total = _n_samples(fs, duration)
    if n_total % periods:
        raise ConfigError(f"duration {duration} s ({n_total} samples) is not divisible into {periods} periods")
    n0 = n_total // periods
    T0 = n0 / fs
    if periodic:
        if method != "linear":
            raise ConfigError("a periodic chirp (eq. 2-2) is linear; use method='linear'")
        for name, f in (("f0", f0), ("f1", f1)):
            k = f * T0
            if abs(k - round(k)) > 1e-6:
                raise ConfigError(
                    f"periodic chirp: {name}*T0 = {k:.6g} must be an integer (eq. 2-2: k1, k2 in N);"
                    f" use a multiple of 1/T0 = {1 / T0:g} Hz"
                )
    n = np.arange(n0, dtype=np.float64)
    if method == "linear":
        # cycles(n) = f0 t + (f1 - f0) t^2 / (2 T0), t = n/fs
        cycles = n * (f0 / fs) + (n * n) * ((f1 - f0) / (2.0 * T0 * fs * fs))
    else:
        if f0 <= 0 or f1 <= 0:
            raise ConfigError("a logarithmic chirp needs f0 > 0 and f1 > 0")
        r = math.log(f1 / f0)
        cycles = (f0 * T0 / r) * np.expm1(r * n / n0)
    cycles -= np.floor(cycles)
    u = amplitude * np.cos(2.0 * np.pi * cycles + phase)
    if periods > 1:
        u = np.tile(u, periods)
    return u


def sine(fs: float, duration: float, freq: float, amplitude: float = 1.0, phase: float = 0.0) -> np.ndarray:
    r"""Single sine of eq. (2-3): :math:`u(t) = A\cos(2\pi f t + k_0)` (the dissertation's :math:`f_0` is
    an angular frequency there); ``phase`` = :math:`k_0` [rad]; use ``phase=-pi/2`` for a sine starting at 0."""
    fs = positive("fs", fs)
    amplitude = positive("amplitude", amplitude)
    freq = positive("freq", freq)
    if freq >= fs / 2:
        raise ConfigError(f"sine freq ({freq:g} Hz) must be below the Nyquist frequency fs/2 = {fs / 2:g} Hz")
    n = _n_samples(fs, positive("duration", duration))
    k = np.arange(n, dtype=np.float64)
    cycles = k * (freq / fs)
    cycles -= np.floor(cycles)
    return amplitude * np.cos(2.0 * np.pi * cycles + phase)


def stepped_sine(
    fs: float,
    freqs: Sequence[float],
    amplitude: float = 1.0,
    settle: float = 0.0,
    cycles: int = 10,
    dwell: float | None = None,
    return_info: bool = False,
):
    """Stepped sine (dissertation §2.2): one frequency after the other, each held for a settling time
    ``settle`` [s] (transients die out; discard it) followed by a measurement window of a whole number of
    periods — ``cycles`` periods, or more when ``dwell`` [s] asks for a longer window.

    The phase is continuous across steps (no jump in the waveform; only the frequency changes).
    ``info['steps']`` lists, per frequency, ``freq_hz``, ``start`` (first sample of the step), ``measure_start``
    and ``stop`` (sample indices of the measurement window, stop exclusive) and ``cycles``; a Record can use
    them as ``meta['segments']``.
    """
    fs = positive("fs", fs)
    amplitude = positive("amplitude", amplitude)
    try:
        freqs = [float(f) for f in np.atleast_1d(freqs)]
    except (TypeError, ValueError):
        raise ConfigError(f"stepped_sine freqs must be numbers, got {freqs!r}") from None
    if not freqs:
        raise ConfigError("stepped_sine needs at least one frequency")
    if float(settle) < 0 or not math.isfinite(float(settle)):
        raise ConfigError(f"settle must be >= 0 s, got {settle}")
    cycles = int(positive("cycles", cycles, integer=True))
    parts, steps = [], []
    acc = 0.0  # phase in cycles at the start of the step
    pos = 0
    for f in freqs:
        if not math.isfinite(f) or f <= 0 or f >= fs / 2:
            raise ConfigError(f"stepped_sine frequency {f:g} Hz must lie in (0, fs/2 = {fs / 2:g}) Hz")
        n_set = int(round(float(settle) * fs))
        n_cyc = cycles
        if dwell is not None:
            n_cyc = max(n_cyc, int(math.ceil(positive("dwell", dwell) * f - 1e-9)))
        n_meas = int(round(n_cyc * fs / f))
        n = n_set + n_meas
        k = np.arange(n, dtype=np.float64)
        c = acc + k * (f / fs)
        c -= np.floor(c)
        parts.append(amplitude * np.cos(2.0 * np.pi * c))
        acc = (acc + n * f / fs) % 1.0
        steps.append({"freq_hz": f, "start": pos, "measure_start": pos + n_set, "stop": pos + n, "cycles": n_cyc})
        pos += n
    u = np.concatenate(parts)
    if return_info:
        return u, {"steps": steps}
    return u


# ------------------------------------------------------------------------------------ the dissertation's signals
def thesis_cantilever_multisine(seed: int = 0, return_info: bool = False):
    """The cantilever estimation multisine, dissertation §3.1: "up to 0.5 kHz frequency and maximum amplitude
    of 100 V ... constructed with n_f = 5000 sinusoidal signals and uniformly distributed with random phases",
    recorded for 8 s at 10 kHz (Figure 3.3: 8 x 10^4 samples).

    5000 uniformly spaced lines up to 500 Hz means a spacing of 0.1 Hz, i.e. a 10 s period; the 8 s record
    is therefore 80 % of one period (not periodic — ``info['periodic']`` is False). This is our reading of
    the text: no other uniform grid puts 5000 lines in (0, 500] Hz. Peak ±100 V, random phases from ``seed``.
    """
    return multisine(
        fs=10e3,
        duration=8.0,
        band=(0.1, 500.0),
        components=5000,
        resolution=0.1,
        amplitude=100.0,
        phase="random",
        seed=seed,
        return_info=return_info,
    )


def thesis_acoustic_multisine(seed: int = 0, truncate: int | None = None, return_info: bool = False):
    """The acoustic estimation multisine, dissertation §3.2: "randomly sampled phase in the range [0, 2π] with
    uniform distribution ... n_f = 45,000 ... frequency range of 900kHz to 1350kHz, and 400mV amplitude".

    Built at the acquisition rate 100 MHz with a 10 Hz line spacing (45 000 lines at 900 000, 900 010, ...,
    1 349 990 Hz — 45 000 lines of a 10 Hz grid fill the 450 kHz band exactly), so one period is 0.1 s =
    10^7 samples, the length of the dissertation's recordings. 0.4 V peak. The dissertation's generator file
    had 10^6 points (the same 0.1 s period at 10 MHz) and, for lack of generator memory, was "truncated to 5
    thousand points" before it was played; ``truncate=N`` keeps the first N samples of our 100 MHz version
    to mimic that (the result no longer has a line spectrum). The signal is returned at 100 MHz.
    """
    out = multisine(
        fs=100e6,
        band=(900e3, 1349.99e3),
        components=45000,
        resolution=10.0,
        amplitude=0.4,
        phase="random",
        seed=seed,
        return_info=True,
    )
    u, info = out
    if truncate is not None:
        t = int(positive("truncate", truncate, integer=True))
        if t > u.size:
            raise ConfigError(f"truncate={t} exceeds the signal length {u.size}")
        u = u[:t].copy()
        info = dict(info, periodic=False, periods=t / info["period_samples"], truncated_to=t)
    return (u, info) if return_info else u


THESIS_CHIRP_VPP = {0.1: 0.080, 0.001: 0.150}  # V peak-to-peak: §3.2 "80mVpp" (100 ms), "150mVpp" (1 ms)


def thesis_chirp(duration: float = 0.1, fs: float = 100e6) -> np.ndarray:
    """The acoustic chirps of dissertation §3.2: linear up-sweep 900 kHz -> 1350 kHz at 100 MHz sampling.

    ``duration=0.1`` (100 ms): first dataset, "amplitude before amplification equal to 80mVpp" (peak 0.04 V,
    10^7 samples). ``duration=0.001`` (1 ms): validation of the second dataset, "sweep time of 1 ms ...
    amplitude was set to 150mVpp" (peak 0.075 V, 10^5 samples). Other durations are refused.
    """
    key = None
    for d in THESIS_CHIRP_VPP:
        if abs(float(duration) - d) < 1e-12:
            key = d
    if key is None:
        raise ConfigError(f"thesis_chirp duration must be 0.1 s or 0.001 s (dissertation §3.2), got {duration}")
    return chirp(fs, key, 900e3, 1350e3, amplitude=THESIS_CHIRP_VPP[key] / 2.0, method="linear")
