"""Excitation design and preprocessing (dissertation §2.2–2.3), in the manner of :mod:`scipy.signal`: arrays in,
arrays out, the sampling rate ``fs`` [Hz] explicit.

Multisines, chirps, sines, stepped sines, PRBS and APRBS (:mod:`~sysid.signals.excitation`,
:mod:`~sysid.signals.pseudorandom`); offset, trend, outliers, filters, decimation, resampling and segments
(:mod:`~sysid.signals.preprocess` gathers them; :mod:`~sysid.signals.cleaning`, :mod:`~sysid.signals.filters`,
:mod:`~sysid.signals.sampling` hold them). scipy.signal is imported only by the steps that filter.
May import: :mod:`sysid.errors`, :mod:`sysid.config`, :mod:`sysid.data`.
"""

from typing import TYPE_CHECKING

from sysid._exports import attach

if TYPE_CHECKING:
    from sysid.signals.excitation import (
        PRBS_TAPS,
        aprbs,
        chirp,
        crest_factor,
        multisine,
        prbs,
        sine,
        stepped_sine,
        thesis_acoustic_multisine,
        thesis_cantilever_multisine,
        thesis_chirp,
    )
    from sysid.signals.filters import ATTEN_DB_DEFAULT, PASSBAND_DEFAULT
    from sysid.signals.preprocess import (
        STEPS,
        antialias_filter,
        apply_steps,
        autocovariance,
        bandpass,
        bandpass_design,
        decimate,
        detrend,
        fill_missing,
        hampel,
        moving_average,
        remove_offset,
        resample,
        segment,
        segment_bounds,
        suggest_rate,
    )

__getattr__, __dir__, __all__ = attach(__name__, __file__)
