"""Torch model files (``.pt``) for the neural identifiers.

The file holds the same payload as the JSON format of :meth:`sysid.base.Identifier.save` —
``{"format": "piezotwin-model/1", "identifier", "params", "state"}`` — written with :func:`torch.save`
and read back with ``torch.load(weights_only=True)`` (plain containers, numbers, strings and tensors
only: no pickled code is executed on load). Weights are stored as float64 tensors, so a loaded model
predicts bit-identically. Registered in ``sysid.registry.BINARY_LOADERS`` for the suffix ``.pt``.

The portable format is the npz container of :mod:`sysid.data.modelfile` (no torch needed to read it); ``.pt`` stays
for compatibility. The payload also carries ``estimation`` (fs, units, hash of the estimation data) and is
checked by the same code as every other model file (:func:`sysid.data.modelfile.build_model`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from sysid.errors import DataError

__all__ = ["save_torch", "load", "TorchFileSave", "saved_array"]

FORMAT = "piezotwin-model/1"


class TorchFileSave:
    """Mixin for the neural identifiers: ``save(path)`` writes a torch file for ``.pt`` (read back by
    :func:`sysid.base.load_model` through :func:`load`), and the base class's JSON otherwise."""

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        if path.suffix.lower() == ".pt":
            return save_torch(self, path)
        return super().save(path)  # type: ignore[misc]


def _to_torch(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _to_torch(v) for k, v in obj.items()}
    if isinstance(obj, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(obj))
    if isinstance(obj, (list, tuple)) and obj and all(isinstance(v, float) for v in obj) and len(obj) > 16:
        return torch.tensor(obj, dtype=torch.float64)
    if isinstance(obj, (list, tuple)):
        return [_to_torch(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _from_torch(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _from_torch(v) for k, v in obj.items()}
    if isinstance(obj, torch.Tensor):
        return obj.numpy()
    if isinstance(obj, list):
        return [_from_torch(v) for v in obj]
    return obj


def save_torch(model, path: str | Path) -> Path:
    path = Path(path)
    from sysid.data.safeio import atomic_path

    payload = {
        "format": FORMAT,
        "identifier": model.name,
        "params": model.get_params(),
        "state": _to_torch(model._state()),
        "estimation": getattr(model, "estimation_", None),
    }
    with atomic_path(path) as tmp:
        torch.save(payload, tmp)
    return path


def load(path: str | Path):
    """Read a ``.pt`` model file written by :func:`save_torch` and return the fitted identifier."""
    from sysid.data.modelfile import build_model

    path = Path(path)
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a corrupt or foreign file
        raise DataError(f"{path}: not a readable torch model file, or truncated ({type(exc).__name__})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise DataError(f"{path}: not a piezotwin model file")
    payload = dict(payload)
    payload["state"] = _from_torch(payload.get("state", {}))
    return build_model(path, payload, legacy=True)


def saved_array(name: str, saved: dict[str, Any], key: str, shape: tuple[int, ...]) -> np.ndarray:
    """The saved weight array ``saved[key]`` as float64 of ``shape`` (the model the options build); a missing key
    or another number of values is a one-line :class:`DataError` of identifier ``name``."""
    if key not in saved:
        raise DataError(f"{name}: saved state lacks {key}")
    arr = np.asarray(saved[key], dtype=np.float64)
    size = int(np.prod(shape))
    if arr.size != size:
        raise DataError(f"{name}: saved {key} has {arr.size} values, the options give {size}")
    return arr.reshape(shape)
