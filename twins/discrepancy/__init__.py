"""Discrepancy analysis: what a twin's simulation gets wrong, the cause, the extension, the gain.

``diagnose(twin, data, val=None, max_rounds=3, ...) -> dict`` runs the loop (:mod:`.diagnose`;
:func:`run_diagnosis` returns the typed :class:`Diagnosis`, its settings are :class:`DiagnoseOptions`); the
residual numbers come from :mod:`.features`, the per-effect signatures from :mod:`.evidence`, the figures from
:mod:`.report`.
"""

from .diagnose import NOISE_EFFECTS, diagnose, run_diagnosis, significance
from .options import DiagnoseOptions
from .result import Diagnosis

__all__ = ["diagnose", "run_diagnosis", "Diagnosis", "DiagnoseOptions", "significance", "NOISE_EFFECTS"]
