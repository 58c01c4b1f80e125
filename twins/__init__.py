"""Grey-box digital twins of piezoelectric systems: the cantilever micromanipulator and the piezoacoustic
transmission channel, their effect catalogs and protocols, calibration, discrepancy analysis and FMU export.

May use :mod:`sysid` (records, signals, residual tests); nothing else of this project.
"""

from twins.registry import available_twins, get_twin

__all__ = ["get_twin", "available_twins"]
