"""FMU export of the twins (FMI 2.0 co-simulation via pythonfmu).

- :func:`export_fmu` (:mod:`twins.fmu.export`): configured twin -> ``.fmu`` with input ``u``, output ``y``,
  every physical parameter, effect switch, ``seed`` and ``fs`` as FMU parameters (:mod:`twins.fmu.spec`).
- :mod:`twins.fmu.slave`: the slave that runs inside the importing tool.
- :mod:`twins.fmu.cores`: per-sample cores (the twin's stepper, or the block-convolution response core of
  :mod:`twins.fmu.response` for the 100 MHz acoustic channel).
"""

from twins.fmu.export import DEFAULT_FS, default_fs, export_fmu
from twins.fmu.spec import fmu_variables

__all__ = ["DEFAULT_FS", "default_fs", "export_fmu", "fmu_variables"]
