"""JSON for the whole project, in one place: the ``json.dumps(default=...)`` hook for numpy values and paths,
and the conversion of a result to strict JSON (numpy to Python, nan/inf to null) used by every ``--json``
output and every JSON file the project writes; :func:`read_json_file` reads such a file back with its checks."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from sysid.errors import DataError


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


def read_json_file(path: str | Path, fmt: str, what: str) -> dict[str, Any]:
    """The JSON object of a project file of format ``fmt`` (its ``"format"`` key), ``what`` naming the kind of file
    in the one-line refusals (:class:`sysid.errors.DataError`): missing, a directory, not JSON, another format."""
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: {what} not found")
    if p.is_dir():
        raise DataError(f"{p}: is a directory, expected a {what}")
    try:
        data = json.loads(p.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DataError(f"{p}: not a JSON {what} ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != fmt:
        raise DataError(f"{p}: not a piezotwin {what} (expected format {fmt!r})")
    return data
