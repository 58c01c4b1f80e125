"""JSON for the whole project, in one place: the ``json.dumps(default=...)`` hook for numpy values and paths,
and the conversion of a result to strict JSON (numpy to Python, nan/inf to null) used by every ``--json``
output and every JSON file the project writes."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np


def json_default(obj: Any) -> Any:
    """``json.dumps(default=...)`` hook for numpy arrays/scalars and paths (one place for the whole project)."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def clean_json(obj: Any) -> Any:
    """Make ``obj`` strict-JSON: numpy scalars/arrays to Python, nan/inf to null."""
    if isinstance(obj, dict):
        return {str(k): clean_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return clean_json(obj.tolist())
    if isinstance(obj, np.generic):
        return clean_json(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
