"""Piezoacoustic transmission twin: layered 1-D acoustics, Mason/Kino transducers, RF amplifier,
reverberation, tank-wall echoes, crosstalk, noise and ADC; fluid/temperature/distance studies."""

from twins.acoustic.params import AcousticParams
from twins.acoustic.twin import EFFECTS, AcousticTwin

__all__ = ["AcousticTwin", "AcousticParams", "EFFECTS"]
