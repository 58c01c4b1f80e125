"""Twins from simulators the user brings: a small Python model (:mod:`.pymodel`) or an FMU (:mod:`.fmu`), each
wrapped in the model-agnostic effects of :mod:`twins.generic_effects` (:mod:`.twin`)."""

from .twin import ExternalTwin, external_twin_class

__all__ = ["ExternalTwin", "external_twin_class", "load_model", "fmu_twin_class"]


def load_model(spec: str):
    """The twin class of a Python model (:func:`.pymodel.load_model`)."""
    from .pymodel import load_model as _load

    return _load(spec)


def fmu_twin_class(path, names=None, input_name=None, output_name=None, effects=None):
    """The twin class of an FMU (:func:`.fmu.fmu_twin_class`; needs FMPy)."""
    from .fmu import fmu_twin_class as _fmu

    return _fmu(path, names, input_name, output_name, effects)
