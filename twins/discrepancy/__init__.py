"""Discrepancy analysis (issue 8): what a twin's simulation gets wrong, the cause, the extension, the gain.

``diagnose(twin, data, val=None, max_rounds=3, ...) -> dict`` runs the loop (:mod:`.diagnose`); the residual
numbers come from :mod:`.features`, the per-effect signatures from :mod:`.evidence`, the figures from
:mod:`.report`.
"""

from .diagnose import NOISE_EFFECTS, diagnose, significance

__all__ = ["diagnose", "significance", "NOISE_EFFECTS"]
