"""Calibration of the cantilever twin (placeholder: generic free-run output error)."""
from __future__ import annotations

from twins.calibration import calibrate


def calibrate_cantilever(twin, data, val=None, names=None, **options):
    names = list(names) if names is not None else list(twin.CALIBRATION_PARAMS)
    return calibrate(twin, data, names, val=val, **options)
