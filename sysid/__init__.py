"""Black-box identification of (piezoelectric) systems.

Depends on nothing else of this project. Main entry points:

- :class:`sysid.record.Record` and :func:`sysid.io.read_record` / :func:`sysid.io.write_record`
- :mod:`sysid.signals` (excitation design), :mod:`sysid.preprocess` (cleaning, resampling)
- identifiers registered in :mod:`sysid.registry`, all following :class:`sysid.base.Identifier`
- :mod:`sysid.metrics` (R², NRMSE, ...) and :mod:`sysid.residuals` (correlation tests)
"""

from sysid.errors import ConfigError, DataError, InputError
from sysid.record import Record

__all__ = ["Record", "InputError", "DataError", "ConfigError"]
