"""Per-sample core for twins simulated in the frequency domain (the 100 MHz acoustic channel).

The twin's block simulation is ``y = measure(h * amplifier(u))``: a memoryless amplifier, a linear chain
with impulse response ``h`` (from ``H(f) = twin.frequency_response(f)``, echoes and reverberation included as
configured) and the measurement (noise, ADC). An FMU advances one sample per communication step. The
acoustic ``h`` is *dense*: 30 plate-to-plate reverberations ring for ~4.6 ms, i.e. ~460 000 taps at
100 MHz with its energy spread over all of them, so neither a truncated FIR (each 1e-6 of dropped energy
costs ~400 000 taps) nor a low-order rational fit (a 13 500-sample round-trip delay inside the loop)
gives a cheap *and* accurate per-sample core. What makes it cheap is the time of flight:

**Latency-free block convolution.** ``h`` is split at ``B`` samples, a power of two (64 <= B <= 8192) chosen
for the lowest cost per sample (:func:`plan`; for the acoustic twin ``B = 4096``, within the time of flight
of ~6900 samples for 100 mm of water):

- head ``h[:B]``: applied per sample as a FIR (one ``numpy.dot`` per segment on a mirrored ring buffer).
  It holds what arrives before the sound: for the acoustic twin ~5e-9 of the energy (the precursor of its
  frequency-domain attenuation model) and, with the ``crosstalk`` effect, the electrical path. Only
  32-sample pieces holding together <= ``energy_tol`` (1e-14) of the energy are dropped;
- tail ``h[B:]``: cut into ``P`` partitions of ``B`` taps, whose spectra (``2B`` points) are computed once. Every
  ``B`` input samples the finished block's spectrum joins a delay line of the last ``P`` block spectra, and the
  next ``B`` outputs receive ``sum_p X_{m-p} H_p`` (one inverse FFT, overlap-add into the next two blocks): the
  uniformly partitioned convolution. Partition ``p`` of block ``m`` reaches the output only from sample
  ``(m+1+p)B`` on, so each is added just in time: the output is exact at every sample with no delay. Per block
  that is two FFTs of ``2B`` points and ``P(B+1)`` complex products (measured in docs/fmu.md).

Nothing else of ``h`` is dropped, so the core equals the native ``simulate`` up to that and FFT round-off; the
export measures it on a chirp and stores the figure in the FMU. The measurement is applied per sample with
the twin's seeded generator, which reproduces the native noise: numpy Generators give the same stream
drawn one value at a time or all at once.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.fft

__all__ = ["impulse_response", "sparse_segments", "plan", "ResponseCore", "prepare_response_core", "check_accuracy"]

DEFAULTS: dict[str, Any] = {"energy_tol": 1e-14, "block_min": 64, "block_max": 8192, "merge_gap": 1024}


def impulse_response(twin, fs: float, tail_tol: float = 1e-12, n_min: int = 2**15, n_max: int = 2**22) -> np.ndarray:
    """Real impulse response of the twin's linear chain sampled at ``fs`` [Hz].

    A twin that exposes ``impulse_response(fs)`` (the h its own ``simulate`` convolves with: the acoustic
    twin) gives it directly; otherwise ``h = irfft(H)`` of ``frequency_response`` on a power-of-2 grid
    long enough that its last eighth holds less than ``tail_tol`` of the energy.
    """
    own = getattr(twin, "impulse_response", None)
    if own is not None:
        return np.array(own(fs), dtype=float)
    n = n_min
    while True:
        f = np.fft.rfftfreq(n, 1.0 / fs)
        h = np.fft.irfft(np.asarray(twin.frequency_response(f), dtype=complex), n)
        e = h * h
        total = float(e.sum())
        if total == 0.0 or float(e[-n // 8 :].sum()) <= tail_tol * total or n >= n_max:
            return h
        n *= 2


def sparse_segments(
    h: np.ndarray,
    energy_tol: float,
    block: int = 32,
    merge_gap: int = DEFAULTS["merge_gap"],
    total: float | None = None,
) -> tuple[list[tuple[int, np.ndarray]], float]:
    """Segments ``[(start, taps), ...]`` of ``h`` dropping its weakest ``block``-sample pieces while the
    dropped energy stays <= ``energy_tol * total`` (``total`` defaults to the energy of ``h``).

    Returns the segments and the dropped energy as a fraction of ``total``.
    """
    h = np.asarray(h, dtype=float)
    n_blocks = -(-len(h) // block)
    padded = np.zeros(n_blocks * block)
    padded[: len(h)] = h
    be = (padded.reshape(n_blocks, block) ** 2).sum(axis=1)
    total = float(be.sum()) if total is None else float(total)
    if total == 0.0 or n_blocks == 0:
        return [], 0.0
    order = np.argsort(be, kind="stable")
    dropped = np.cumsum(be[order]) / total
    n_drop = int(np.searchsorted(dropped, energy_tol, side="right"))
    keep = np.ones(n_blocks, dtype=bool)
    keep[order[:n_drop]] = False
    segments: list[tuple[int, int]] = []
    for b in np.flatnonzero(keep):
        s, e = int(b) * block, (int(b) + 1) * block
        if segments and s - segments[-1][1] <= merge_gap:
            segments[-1] = (segments[-1][0], e)
        else:
            segments.append((s, e))
    out = [(s, padded[s:e].copy()) for s, e in segments]
    return out, float(dropped[n_drop - 1]) if n_drop else 0.0


#: rough costs on x86-64 (numpy/pocketfft) used only to choose the block size: a numpy.dot call on a slice, a
#: tap, one real FFT pair per ``n log2 n``, one complex product of the partitioned tail (einsum)
_NS_PER_DOT, _NS_PER_TAP, _NS_PER_FFT_NLOGN, _NS_PER_MAC = 1500.0, 0.25, 0.9, 2.7


def plan(
    h: np.ndarray,
    energy_tol: float = DEFAULTS["energy_tol"],
    block_min: int = DEFAULTS["block_min"],
    block_max: int = DEFAULTS["block_max"],
) -> dict[str, Any]:
    """Block size, head segments and tail of ``h`` (see the module docstring).

    For every power of two ``B`` in [block_min, block_max] the head is ``h[:B]`` without its weakest
    32-sample pieces (together <= ``energy_tol`` of the total energy); the block with the lowest estimated
    cost per sample (head dots + per block an FFT pair of ``2B`` points and the partitioned tail's products) is
    chosen. For a response whose energy
    arrives after a flight time the head is (nearly) empty up to that time, so ``B`` grows to it.
    """
    h = np.asarray(h, dtype=float)
    e = h * h
    total = float(e.sum())
    if total == 0.0:
        return {"block": block_min, "head": [], "tail": np.zeros(0), "arrival": len(h), "head_dropped": 0.0}
    arrival = int(np.searchsorted(np.cumsum(e), 1e-6 * total, side="right"))
    nz = np.flatnonzero(h)
    last = int(nz[-1]) + 1
    best: tuple[float, int, list, float] | None = None
    B = block_min
    while B <= block_max:
        head, dropped = sparse_segments(h[:B], energy_tol, total=total)
        partitions = -(-max(last - B, 0) // B)
        cost = (
            len(head) * _NS_PER_DOT
            + sum(len(t) for _, t in head) * _NS_PER_TAP
            + (_NS_PER_FFT_NLOGN * 2 * B * np.log2(2 * B) + _NS_PER_MAC * partitions * (B + 1)) / B * (partitions > 0)
        )
        if best is None or cost < best[0]:
            best = (cost, B, head, dropped)
        B *= 2
    if best is None:
        raise ValueError(f"no block size between {block_min} and {block_max}")
    cost, B, head, dropped = best
    tail = h[B:last]  # trailing exact zeros cost FFT length and nothing else
    return {
        "block": B,
        "head": head,
        "tail": tail,
        "arrival": arrival,
        "head_dropped": dropped,
        "est_ns_per_sample": float(cost),
    }


class ResponseCore:
    """``step(u) -> y``: amplifier, linear chain ``h`` (head FIR + block-FFT tail), measurement."""

    def __init__(
        self,
        h: np.ndarray,
        amplifier,
        measure=None,
        fs: float = 1.0,
        seed: int | None = 0,
        energy_tol: float = DEFAULTS["energy_tol"],
        block_min: int = DEFAULTS["block_min"],
        block_max: int = DEFAULTS["block_max"],
    ):
        p = plan(h, energy_tol, block_min, block_max)
        self.block = B = p["block"]
        self.arrival = p["arrival"]
        self.head_dropped = p["head_dropped"]
        self.head = [(int(s), np.ascontiguousarray(t)) for s, t in p["head"]]
        self.head_len = max([s + len(t) for s, t in self.head] or [1])
        tail = p["tail"]
        self.tail_len = len(tail)
        self.partitions = -(-len(tail) // B)
        padded = np.zeros(self.partitions * B)
        padded[: len(tail)] = tail
        # spectra of the tail's B-tap partitions on 2B points (linear convolution of a block with a partition)
        self.tail_spec = scipy.fft.rfft(padded.reshape(self.partitions, B), 2 * B, axis=1) if len(tail) else None
        self.n_acc = 2 * B  # the outputs of this block and the next
        self.amplifier = amplifier
        self.measure = measure
        self.fs = float(fs)
        self.seed = seed
        self.reset()

    @classmethod
    def for_twin(cls, twin, fs: float, core: dict[str, Any] | None = None, resources=None) -> ResponseCore:
        core = core or {}
        opts = {k: core.get(k, v) for k, v in DEFAULTS.items() if k != "merge_gap"}
        return cls(impulse_response(twin, fs), amplifier_of(twin), measure_of(twin, fs), fs, twin.seed, **opts)

    def reset(self) -> None:
        self.hist = np.zeros(2 * self.head_len)
        self.hpos = 0
        self.blockbuf = np.zeros(self.block)
        self.bpos = 0
        self.acc = np.zeros(self.n_acc)
        self.apos = 0
        # the delay line of block spectra, twice: rows s .. s+P-1 are the newest block first, then the older ones
        self.spectra = np.zeros((2 * self.partitions, self.block + 1), dtype=complex)
        self.newest = 0
        self.rng = np.random.default_rng(self.seed)
        self._u: float | None = None
        self._a = 0.0

    def step(self, u: float) -> float:
        if u != self._u:  # the amplifier is memoryless; inputs are held over a communication step
            self._u = u
            self._a = float(self.amplifier(u))
        x = self._a
        y = 0.0
        if self.head:
            L = self.head_len
            p = self.hpos - 1
            if p < 0:
                p += L
            self.hpos = p
            hist = self.hist
            hist[p] = x
            hist[p + L] = x
            for start, taps in self.head:
                a = p + start
                y += float(np.dot(taps, hist[a : a + len(taps)]))
        acc = self.acc
        apos = self.apos
        y += float(acc[apos])
        acc[apos] = 0.0
        apos += 1
        if apos == self.n_acc:
            apos = 0
        self.apos = apos
        self.blockbuf[self.bpos] = x
        self.bpos += 1
        if self.bpos == self.block:
            self._flush()
        if self.measure is not None:
            y = float(self.measure(y, self.rng))
        return y

    def _flush(self) -> None:
        """Block ``m`` is complete: add ``sum_p x_{m-p} * h_p`` to the next two blocks' outputs (module docstring)."""
        self.bpos = 0
        if self.tail_spec is None:
            return
        B, P = self.block, self.partitions
        s = (self.newest - 1) % P
        self.spectra[s] = self.spectra[s + P] = scipy.fft.rfft(self.blockbuf, 2 * B)
        self.newest = s
        z = scipy.fft.irfft(np.einsum("pk,pk->k", self.spectra[s : s + P], self.tail_spec), 2 * B)
        a = self.apos  # the start of the next block: 0 or B
        self.acc[a : a + B] += z[:B]
        b = B - a
        self.acc[b : b + B - 1] += z[B : 2 * B - 1]

    def run(self, u: np.ndarray) -> np.ndarray:
        """``step`` over an array (for checks)."""
        return np.array([self.step(float(v)) for v in u])


def amplifier_of(twin):
    """``twin.amplifier`` as a float -> float function (identity when the twin has none): the twin's
    ``sample_amplifier()`` where it gives one, else ``amplifier`` itself, which it calls on a Python float when that
    gives the same value as on a one-element array (numpy ufunc code does, ~1 us), else on a one-element array."""
    own = getattr(twin, "sample_amplifier", None)
    fn = own() if own is not None else None
    if fn is not None:  # the twin's own per-sample form (same arithmetic, no array per call)
        return fn
    amp = getattr(twin, "amplifier", None)
    if amp is None:
        return lambda x: x
    probe = np.array([-1e3, -3.0, -0.1, 0.0, 0.2, 4.0, 1e3])
    try:
        ref = np.asarray(amp(probe), dtype=float)
        scalar = np.array([float(np.asarray(amp(float(v)), dtype=float).reshape(-1)[0]) for v in probe])
        if np.array_equal(ref, scalar):
            if np.ndim(amp(0.5)) == 0:
                return amp

            def first(x: float) -> float:
                return np.asarray(amp(x), dtype=float).reshape(-1)[0]

            return first
    except Exception:  # the twin's amplifier wants arrays
        pass
    one = np.zeros(1)

    def on_array(x: float) -> float:
        one[0] = x
        return np.asarray(amp(one), dtype=float)[0]

    return on_array


def measure_of(twin, fs: float):
    """Per-sample ``(y, rng) -> y`` from ``twin.sample_measure(fs)`` if the twin has it, else from
    ``twin.measure(y, fs, rng)`` (noise + ADC), or None.

    ``measure`` is called on one-element arrays with the core's generator, so a twin whose ``measure``
    draws one value per sample in order (``rng.standard_normal(y.shape)``) gets exactly the noise of its
    block ``simulate``.
    """
    own = getattr(twin, "sample_measure", None)
    if own is not None:  # the twin's own per-sample form (same draws and arithmetic, no array per call)
        return own(fs)
    fn = getattr(twin, "measure", None)
    if fn is None:
        return None
    one = np.zeros(1)

    def measure(y: float, rng) -> float:
        one[0] = y
        return np.asarray(fn(one, fs, rng), dtype=float).reshape(-1)[0]

    return measure


def check_chirp(fs: float, h: np.ndarray, n: int) -> tuple[np.ndarray, str]:
    """A linear chirp of ``n`` samples, 1 V, over 0.3 .. 3 times the peak of ``|H|``."""
    H = np.abs(np.fft.rfft(h))
    f_peak = float(np.fft.rfftfreq(len(h), 1.0 / fs)[int(np.argmax(H))]) or fs / 100
    f0, f1 = 0.3 * f_peak, min(3.0 * f_peak, 0.45 * fs)
    t = np.arange(n) / fs
    u = np.sin(2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / (n / fs) * t * t))
    return u, f"linear chirp 1 V {f0:.4g}-{f1:.4g} Hz, {n} samples"


def check_accuracy(
    twin, fs: float, u: np.ndarray | None = None, n: int = 100_000, core: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Accuracy of the per-sample core on ``u`` (default: :func:`check_chirp` of ``n`` samples).

    ``relative_rms``: core output against the native ``simulate``, both without measurement noise (the ADC,
    if on, stays, so equal quantised samples count as equal); ``linear_relative_rms``: the core before
    ``measure`` against the twin's own linear stage (``twin.linear(amplifier(u), fs)`` where it has one,
    else a direct FFT convolution with ``h``), which the ADC cannot mask.
    """
    from scipy.signal import oaconvolve

    from twins.fmu.check import relative_rms

    quiet = twin.with_effects(set(twin.effects) - {"measurement_noise"})
    core_obj = ResponseCore.for_twin(quiet, fs, core)
    h = impulse_response(quiet, fs)
    if u is None:
        u, what = check_chirp(fs, h, n)
    else:
        what = f"given input, {len(u)} samples"
    ref = np.asarray(quiet.simulate(u, fs), dtype=float)
    y = core_obj.run(u)
    core_obj.measure = None
    core_obj.reset()
    lin = core_obj.run(u)
    v = np.asarray(quiet.amplifier(u), dtype=float) if hasattr(quiet, "amplifier") else np.asarray(u, float)
    lin_ref = np.asarray(quiet.linear(v, fs) if hasattr(quiet, "linear") else oaconvolve(v, h)[: len(v)], float)
    return {
        "signal": what,
        "relative_rms": relative_rms(y, ref),
        "max_abs_error": float(np.max(np.abs(y - ref))),
        "rms_ref": float(np.sqrt(np.mean(ref**2))),
        "linear_relative_rms": relative_rms(lin, lin_ref),
        "noise_free": True,
    }


def prepare_response_core(twin, fs: float, core: dict[str, Any], check_samples: int = 30_000) -> dict[str, Any]:
    """Describe the response core of ``twin`` at ``fs`` for the FMU (it is rebuilt from the twin at
    initialisation, so parameter changes act) and measure its accuracy against ``simulate``."""
    out = dict(core)
    opts = {k: core.get(k, v) for k, v in DEFAULTS.items() if k != "merge_gap"}
    out.update(opts)
    h = impulse_response(twin, fs)
    p = plan(h, **opts)
    out.update(
        {
            "impulse_length": len(h),
            "block": p["block"],
            "arrival_samples": p["arrival"],
            "estimated_core_ns_per_sample": round(p["est_ns_per_sample"]),
            "head_segments": [[int(s), len(t)] for s, t in p["head"]],
            "head_dropped_energy": p["head_dropped"],
            "tail_length": len(p["tail"]),
        }
    )
    out["accuracy"] = check_accuracy(twin, fs, n=check_samples, core=out)
    return out
