"""The per-sample forms the FMU core uses (no array, no thread launch per sample) give bit-identical results
to the twin's block functions: ``AcousticTwin.sample_amplifier``/``sample_measure`` against
``amplifier``/``measure``, for the default configuration and the variants of their effects."""

import numpy as np
import pytest

from twins.acoustic import AcousticTwin


def _same_bits(a, b):
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    assert a.shape == b.shape and a.tobytes() == b.tobytes()


def _inputs(twin):
    rng = np.random.default_rng(3)
    lsb = 2.0 * twin.params.adc_range_v / 2**twin.params.adc_bits
    ties = (np.arange(-300, 300) + 0.5) * lsb  # halfway between two ADC levels: round half to even
    return np.concatenate(
        [
            [0.0, -0.0, 1e-300, -1e-300, 1e6, -1e6],
            ties,
            rng.standard_normal(3000),
            5 * rng.standard_normal(1000),
            0.3 * lsb * rng.standard_normal(200),
        ]
    )


CONFIGS = [
    {},
    {"without": {"measurement_noise"}},
    {"without": {"adc_quantization"}},
    {"without": {"amplifier_compression"}},
    {"add": {"amplifier_even_distortion"}},
    {"add": {"amplifier_even_distortion"}, "without": {"amplifier_compression"}},
    {"set": {"amp_smoothness": 1.7}},
]


@pytest.mark.parametrize("cfg", CONFIGS, ids=str)
def test_acoustic_sample_forms_equal_block_functions(cfg):
    twin = AcousticTwin()
    if cfg.get("set"):
        twin = twin.with_params(**cfg["set"])
    effects = (set(twin.effects) | cfg.get("add", set())) - cfg.get("without", set())
    twin = twin.with_effects(effects)
    y = _inputs(twin)
    measure = twin.sample_measure(100e6)
    rng = np.random.default_rng(11)
    _same_bits([measure(v, rng) for v in y], twin.measure(y, 100e6, np.random.default_rng(11)))
    amp = twin.sample_amplifier()
    x = np.concatenate([y, np.linspace(-20, 20, 4001)])
    _same_bits([amp(v) for v in x], twin.amplifier(x))
    # one sample at a time through the block function: what the FMU core did before
    _same_bits([amp(v) for v in x[:50]], [twin.amplifier(np.array([v]))[0] for v in x[:50]])


def test_cubic_compression_has_no_sample_form():
    twin = AcousticTwin().with_params(amp_compression="cubic")
    assert twin.sample_amplifier() is None
