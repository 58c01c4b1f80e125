"""Binary and amplitude-modulated pseudo-random excitations: :func:`prbs`, a maximum-length sequence from a
linear feedback shift register, and :func:`aprbs`, random levels held for random times. Exposed with the other
excitations by :mod:`sysid.signals`."""

from __future__ import annotations

import math

import numpy as np

from sysid.config import make_rng, positive
from sysid.errors import ConfigError
from sysid.signals.checks import _n_samples

__all__ = ["prbs", "aprbs", "PRBS_TAPS"]


# Feedback taps of maximum-length Fibonacci LFSRs, x^n + ... + 1 (Xilinx XAPP052 table; primitive
# polynomials). The recurrence s[k] = XOR_{t in taps} s[k - t] has period 2^n - 1; tests verify the period
# and the two-valued autocorrelation of every order up to 20.
PRBS_TAPS: dict[int, tuple[int, ...]] = {
    2: (2, 1),
    3: (3, 2),
    4: (4, 3),
    5: (5, 3),
    6: (6, 5),
    7: (7, 6),
    8: (8, 6, 5, 4),
    9: (9, 5),
    10: (10, 7),
    11: (11, 9),
    12: (12, 6, 4, 1),
    13: (13, 4, 3, 1),
    14: (14, 5, 3, 1),
    15: (15, 14),
    16: (16, 15, 13, 4),
    17: (17, 14),
    18: (18, 11),
    19: (19, 6, 2, 1),
    20: (20, 17),
    21: (21, 19),
    22: (22, 21),
    23: (23, 18),
    24: (24, 23, 22, 17),
    25: (25, 22),
    26: (26, 6, 2, 1),
    27: (27, 5, 2, 1),
    28: (28, 25),
    29: (29, 27),
    30: (30, 6, 4, 1),
    31: (31, 28),
}


def _lfsr_bits(order: int, n: int, seed: int) -> np.ndarray:
    """First ``n`` bits of the m-sequence of ``order``; the initial register is ``seed`` (nonzero, < 2^order).

    Vectorised in blocks: with taps t_1 = order > ... > t_j, bits k .. k + t_j - 1 depend only on bits
    before k, so each block of ``min(taps)`` bits is one XOR of shifted slices.
    """
    taps = PRBS_TAPS[order]
    # The reciprocal polynomial is primitive too; use whichever tap set allows the longer blocks.
    recip = tuple(sorted({order} | {order - t for t in taps if t != order}, reverse=True))
    if min(recip) > min(taps):
        taps = recip
    s = np.zeros(order + n, dtype=np.uint8)
    s[:order] = [(seed >> i) & 1 for i in range(order)]
    block = min(taps)
    k = order
    end = order + n
    while k < end:
        stop = min(k + block, end)
        acc = s[k - taps[0] : stop - taps[0]].copy()
        for t in taps[1:]:
            acc ^= s[k - t : stop - t]
        s[k:stop] = acc
        k = stop
    return s[order:]


def prbs(
    fs: float,
    order: int = 10,
    duration: float | None = None,
    periods: int = 1,
    bit_samples: int = 1,
    amplitude: float = 1.0,
    offset: float = 0.0,
    seed: int = 1,
) -> np.ndarray:
    """Maximum-length pseudo-random binary sequence (m-sequence) from a linear feedback shift register.

    One period has ``2**order - 1`` bits, each held ``bit_samples`` samples (the clock divider; the power
    spectrum's first zero moves to ``fs / bit_samples``). Levels are ``offset ± amplitude``. Length: ``periods``
    periods, or ``duration`` seconds (the sequence repeated and cut). ``seed`` is the nonzero initial register
    state (it shifts the sequence). Orders 2..31.
    """
    fs = positive("fs", fs)
    order = int(positive("order", order, integer=True))
    if order not in PRBS_TAPS:
        raise ConfigError(f"prbs order must lie in 2..31, got {order}")
    bit_samples = int(positive("bit_samples", bit_samples, integer=True))
    amplitude = positive("amplitude", amplitude)
    periods = int(positive("periods", periods, integer=True))
    seed = int(seed)
    if not 0 < seed < 2**order:
        raise ConfigError(f"prbs seed (initial register) must lie in 1..{2**order - 1}, got {seed}")
    period_bits = 2**order - 1
    if duration is not None:
        n_total = _n_samples(fs, positive("duration", duration))
        n_bits = -(-n_total // bit_samples)
    else:
        n_bits = periods * period_bits
        n_total = n_bits * bit_samples
    n_gen = min(n_bits, period_bits)
    bits = _lfsr_bits(order, n_gen, seed)
    if n_bits > n_gen:
        bits = np.resize(bits, n_bits)
    levels = offset + amplitude * (2.0 * bits.astype(np.float64) - 1.0)
    if bit_samples > 1:
        levels = np.repeat(levels, bit_samples)
    return levels[:n_total]


def aprbs(
    fs: float,
    duration: float,
    low: float = -1.0,
    high: float = 1.0,
    min_hold: float | None = None,
    max_hold: float | None = None,
    levels: int | None = None,
    seed: int | None = None,
    return_info: bool = False,
):
    """Amplitude-modulated PRBS: a staircase whose levels are uniform in ``[low, high]`` (or one of
    ``levels`` equally spaced values) and whose hold times are uniform in ``[min_hold, max_hold]`` seconds
    (whole samples). ``min_hold`` should be about the dominant time constant of the system (defaults: 10 and
    100 samples). ``info['changes']`` gives the sample index of each new level.
    """
    fs = positive("fs", fs)
    n_total = _n_samples(fs, positive("duration", duration))
    low, high = float(low), float(high)
    if not (math.isfinite(low) and math.isfinite(high)) or low >= high:
        raise ConfigError(f"aprbs needs low < high, got low={low:g}, high={high:g}")
    h0 = 10 if min_hold is None else int(round(positive("min_hold", min_hold) * fs))
    h1 = 10 * h0 if max_hold is None else int(round(positive("max_hold", max_hold) * fs))
    if h0 < 1:
        raise ConfigError(f"aprbs min_hold {min_hold} s is shorter than one sample at fs={fs:g} Hz")
    if h1 < h0:
        raise ConfigError(f"aprbs max_hold ({h1} samples) must be >= min_hold ({h0} samples)")
    rng = make_rng(seed)
    holds = rng.integers(h0, h1 + 1, size=n_total // h0 + 2)
    starts = np.concatenate(([0], np.cumsum(holds)))
    starts = starts[starts < n_total]
    if levels is None:
        vals = rng.uniform(low, high, size=starts.size)
    else:
        nl = int(positive("levels", levels, integer=True))
        if nl < 2:
            raise ConfigError(f"aprbs levels must be >= 2, got {nl}")
        vals = low + (high - low) * rng.integers(0, nl, size=starts.size) / (nl - 1)
    counts = np.diff(np.concatenate((starts, [n_total])))
    u = np.repeat(vals, counts)
    if return_info:
        return u, {"changes": starts, "levels": vals}
    return u
