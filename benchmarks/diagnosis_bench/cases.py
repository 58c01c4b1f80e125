"""The cases of the diagnosis benchmark: each a seed, drawn over the records users have, and its two records.

A case draws (from ``numpy.random.default_rng([seed, 46])``, so a seed reproduces it exactly): a model (the
cantilever and acoustic twins, two example user models), a hidden mechanism (:mod:`.mechanisms`, about one case
in ten none) and its size (log-uniform over the mechanism's range), the sampling rate (log-uniform: acoustic
5–100 MHz, cantilever 1–50 kHz, the user models over their own), the length, the estimation and the validation
excitation independently (multisine, chirp, steps with holds — tone bursts with gaps for the acoustic channel —,
band-limited noise, a set of sines), the drive's peak, and the noise (0.3–3 % of the output RMS, white or
coloured). :func:`make_records` builds the two records: the model as the user configured it (``start``), the
mechanism by the generator's own code, the noise last (and a quantiser after it, as in an ADC).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from scipy import signal

from sysid.signals.excitation import chirp, multisine

from . import mechanisms as mech

__all__ = ["Case", "FAMILIES", "MODELS", "draw_case", "excitation", "start_twin"]

#: model → its family (which catalog it has) and the share of the cases it gets
MODELS: dict[str, tuple[str, float]] = {
    "cantilever": ("cantilever", 0.35),
    "acoustic": ("acoustic", 0.35),
    "piezo-stage": ("user", 0.2),
    "cascaded-tanks": ("user", 0.1),
}
FAMILIES = ("cantilever", "acoustic", "user")
KINDS = ("multisine", "chirp", "steps", "noise", "sines")
NONE_SHARE = 0.1
#: model → (fs range [Hz], samples range, drive peak range, drive centre, band ceiling [Hz] or None)
RECORDS: dict[str, dict[str, Any]] = {
    "cantilever": {"fs": (1e3, 50e3), "n": (2000, 16000), "peak": (20.0, 90.0), "centre": 0.0},
    "acoustic": {"fs": (5e6, 100e6), "n": (2000, 16000), "peak": (0.1, 0.45), "centre": 0.0},
    "piezo-stage": {"fs": (2e3, 50e3), "n": (1000, 12000), "peak": (10.0, 80.0), "centre": 0.0},
    "cascaded-tanks": {"fs": (0.1, 0.5), "n": (500, 1500), "peak": (1.0, 3.0), "centre": (3.5, 6.0)},
}
ACOUSTIC_BAND = (900e3, 1350e3)
ACOUSTIC_MIN_S = 2.2e-4  # the records reach past the first arrival (≈ 76 µs) and its first reverberation


@dataclasses.dataclass(frozen=True)
class Case:
    """One benchmark case: everything needed to build its records, drawn from ``seed``."""

    seed: int
    model: str
    family: str
    mechanism: str | None
    size: float | None
    fs: float
    n: int
    est_kind: str
    val_kind: str
    peak: float
    centre: float
    noise: float
    noise_ar: float  # 0: white; else the pole of an AR(1) colouring

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _loguniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi)))) if hi > lo else float(lo)


def draw_case(seed: int) -> Case:
    """The case of ``seed`` (the whole draw depends on the seed alone)."""
    rng = np.random.default_rng([int(seed), 46])
    names = list(MODELS)
    model = names[int(rng.choice(len(names), p=[MODELS[m][1] for m in names]))]
    family = MODELS[model][0]
    pool = [m for m in mech.TWIN_MECHANISMS[family] if not (model == "cascaded-tanks" and m == "hum")]
    mechanism = None if rng.uniform() < NONE_SHARE else str(rng.choice(pool))
    size = _loguniform(rng, *mech.MECHANISMS[mechanism].size_range) if mechanism else None
    spec = RECORDS[model]
    fs = _loguniform(rng, *spec["fs"])
    n = int(round(_loguniform(rng, *spec["n"])))
    if model == "acoustic":
        n = max(n, int(math.ceil(ACOUSTIC_MIN_S * fs)))
    est_kind, val_kind = str(rng.choice(KINDS)), str(rng.choice(KINDS))
    peak = float(rng.uniform(*spec["peak"]))
    centre = spec["centre"] if isinstance(spec["centre"], float) else float(rng.uniform(*spec["centre"]))
    noise = _loguniform(rng, 0.003, 0.03)
    noise_ar = 0.0 if rng.uniform() < 0.5 else float(rng.uniform(0.5, 0.95))
    return Case(seed, model, family, mechanism, size, fs, n, est_kind, val_kind, peak, centre, noise, noise_ar)


# ------------------------------------------------------------------------------------------------ excitations
def _band(case: Case) -> tuple[float, float]:
    if case.model == "acoustic":
        return ACOUSTIC_BAND
    T = case.n / case.fs
    ceiling = {"cantilever": 2000.0, "piezo-stage": 1500.0, "cascaded-tanks": 0.03}[case.model]
    hi = min(0.2 * case.fs, ceiling)
    return min(4.0 / T, 0.1 * hi), hi


def excitation(case: Case, kind: str, rng: np.random.Generator) -> np.ndarray:
    """A drive of ``kind`` for the case: ``n`` samples, peak ``peak`` around ``centre``."""
    n, fs = case.n, case.fs
    T = n / fs
    lo, hi = _band(case)
    t = np.arange(n) / fs
    if kind == "multisine":
        x = np.asarray(multisine(fs=fs, duration=T, band=(lo, hi), amplitude=1.0, seed=int(rng.integers(2**31))))
    elif kind == "chirp":
        x = np.asarray(chirp(fs=fs, duration=T, f0=lo, f1=hi, amplitude=1.0))
    elif kind == "steps":
        edges = np.sort(rng.uniform(0.05, 0.95, int(rng.integers(3, 8)))) * n
        levels = rng.uniform(-1.0, 1.0, edges.size + 1)
        x = levels[np.searchsorted(edges, np.arange(n))]
        if case.model == "acoustic":  # tone bursts with holds: the steps gate a carrier in the band
            f = rng.uniform(*ACOUSTIC_BAND)
            x = np.where(np.abs(x) > 0.4, np.sin(2 * math.pi * f * t) * np.sign(x), 0.0)
    elif kind == "noise":
        w = rng.standard_normal(n + 200)
        b, a = signal.butter(4, [lo, hi], btype="band", fs=fs) if lo > 0.02 * hi else signal.butter(4, hi, fs=fs)
        x = signal.lfilter(b, a, w)[200:]
    else:  # a set of sines, one after the other
        k = int(rng.integers(2, 5))
        freqs = np.exp(rng.uniform(math.log(max(lo, 1e-9)), math.log(hi), k))
        seg = np.minimum(np.arange(n) * k // n, k - 1)
        x = np.sin(2 * math.pi * freqs[seg] * t + rng.uniform(0, 2 * math.pi))
    x = x[:n] / (float(np.max(np.abs(x[:n]))) or 1.0)
    return case.centre + case.peak * x


# ------------------------------------------------------------------------------------------------ the models
def start_twin(case: Case):
    """The model as its user configured it (the truth without the hidden mechanism, and without noise: the
    generator adds its own)."""
    from twins.external import load_model
    from twins.registry import get_twin

    if case.model == "cantilever":
        off = {"measurement_noise", "sensor_quantization"}
        own = mech.EXPECTED["cantilever"].get(case.mechanism or "", ("",))[0]
        cls = get_twin("cantilever")
        return cls(effects=cls.default_effects() - off - {own}, seed=case.seed)
    if case.model == "acoustic":
        return get_twin("acoustic").from_options(effects="none", seed=case.seed)
    module = {"piezo-stage": "benchmarks.examples.piezo_stage", "cascaded-tanks": "benchmarks.examples.cascaded_tanks"}
    return load_model(module[case.model])(seed=case.seed)
