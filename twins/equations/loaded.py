"""Twin classes of model files, found by name: ``twins.equations.loaded:NAME`` is the twin class of ``NAME.py``
on ``sys.path``.

An FMU exported from a model file (``piezotwin export-fmu --model FILE.py``) carries the file in its
``resources/`` folder, which the FMU puts first on ``sys.path``; its slave resolves the twin class by this path
(:func:`twins.fmu.spec.twin_class_path`) and so builds it from the file again (module ``__getattr__``, PEP 562).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

__all__: list[str] = []

_LOADED: dict[str, Any] = {}


def __getattr__(name: str) -> Any:
    if name.startswith("__"):
        raise AttributeError(name)
    if name not in _LOADED:
        from twins.external import load_model

        for folder in sys.path:
            path = Path(folder or ".") / f"{name}.py"
            if path.is_file():
                _LOADED[name] = load_model(str(path))
                break
        else:
            raise AttributeError(f"no model file {name}.py on sys.path")
    return _LOADED[name]
