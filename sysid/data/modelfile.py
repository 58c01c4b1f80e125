"""Model files: how a fitted identifier is written and read back (format ``piezotwin-model`` version 2).

One file per model, in one of two containers holding the same content (``docs/models-in-use.md``):

- ``.npz`` (and any suffix other than ``.json`` / ``.pt``): a zip read with plain
  ``numpy.load(path, allow_pickle=False)``. Entry ``header`` is a 0-d string array holding the JSON header;
  entries ``a0, a1, ...`` are the numeric arrays the header refers to;
- ``.json``: the same header as one JSON document, with each array written inline
  (``"arrays": {"a0": {"dtype", "shape", "data"}}``; floats in shortest round-trip form, so bit-exact).

The JSON header::

    {"format": "piezotwin-model", "version": 2, "identifier": "narx-poly", "params": {...constructor...},
     "estimation": {"fs": Hz, "units": {"u", "y"}, "n_records", "n_samples", "n_inputs", "n_outputs",
                    "sha256": hash of the estimation data},
     "software": {"piezotwin": version}, "state": {...learned values, arrays as {"$array": "a0"}...},
     "arrays": {"a0": {"dtype": "<f8", "shape": [n]}}, "checksum": "sha256:..."}

``checksum`` covers the header (without itself) and every array's dtype, shape and bytes, so a truncated,
damaged or hand-edited file is refused instead of predicting something else. Nothing is unpickled:
neural weights are stored as plain float64 arrays (the torch ``state_dict`` as named arrays).

Still read: version 1 (``{"format": "piezotwin-model/1", ...}`` JSON of earlier releases) and the torch
``.pt`` files of the neural identifiers (:mod:`sysid.neural.persist`, read with ``weights_only=True``).
Every problem raises :class:`~sysid.errors.DataError` with one line naming the file and the problem.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sysid.data.jsonio import json_default
from sysid.data.safeio import atomic_path
from sysid.errors import ConfigError, DataError, InputError

__all__ = ["FORMAT", "VERSION", "LEGACY_FORMAT", "write_model", "read_model", "estimation_info", "data_sha256"]

FORMAT = "piezotwin-model"
VERSION = 2
LEGACY_FORMAT = "piezotwin-model/1"
#: float lists at least this long are stored as arrays (shorter ones stay readable in the JSON header)
ARRAY_MIN_LEN = 16


# ---------------------------------------------------------------------------------------------- helpers
def data_sha256(records: Sequence[Any]) -> str:
    """SHA-256 over the estimation data: per record fs (repr) and u, y as little-endian float64 bytes."""
    h = hashlib.sha256()
    for r in records:
        h.update(repr(float(r.fs)).encode())
        for a in (r.u, r.y):
            if a is not None:
                arr = np.ascontiguousarray(a, dtype="<f8")
                h.update(repr(arr.shape).encode())
                h.update(arr.tobytes())
    return h.hexdigest()


def estimation_info(records: Sequence[Any]) -> dict[str, Any]:
    """What a model file records about its estimation data (fs, units, sizes, hash)."""
    r0 = records[0]
    return {
        "fs": float(r0.fs),
        "units": {"u": r0.units.get("u", ""), "y": r0.units.get("y", "")},
        "n_records": len(records),
        "n_samples": int(sum(len(r) for r in records)),
        "n_inputs": int(r0.n_inputs),
        "n_outputs": int(r0.n_outputs),
        "sha256": data_sha256(records),
    }


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("piezotwin")
    except Exception:  # run from a checkout
        return "unknown"


def _pack(obj: Any, arrays: dict[str, np.ndarray]) -> Any:
    """State -> JSON-able, moving numeric arrays (and long float lists) into ``arrays``."""
    if isinstance(obj, dict):
        return {str(k): _pack(v, arrays) for k, v in obj.items()}
    if isinstance(obj, np.ndarray) and obj.dtype.kind in "biuf":
        name = f"a{len(arrays)}"
        arrays[name] = np.ascontiguousarray(obj)
        return {"$array": name}
    if isinstance(obj, (list, tuple)):
        if len(obj) >= ARRAY_MIN_LEN and all(type(v) is float for v in obj):
            name = f"a{len(arrays)}"
            arrays[name] = np.asarray(obj, dtype=np.float64)
            return {"$array": name, "list": True}
        return [_pack(v, arrays) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _unpack(obj: Any, arrays: dict[str, np.ndarray]) -> Any:
    if isinstance(obj, dict):
        if "$array" in obj and set(obj) <= {"$array", "list"}:
            arr = arrays[obj["$array"]]
            return arr.tolist() if obj.get("list") else arr
        return {k: _unpack(v, arrays) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_unpack(v, arrays) for v in obj]
    return obj


def _checksum(header: dict[str, Any], arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    body = {k: v for k, v in header.items() if k != "checksum"}
    body["arrays"] = {k: {kk: vv for kk, vv in v.items() if kk != "data"} for k, v in body.get("arrays", {}).items()}
    h.update(json.dumps(body, sort_keys=True, separators=(",", ":")).encode())
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return "sha256:" + h.hexdigest()


# ---------------------------------------------------------------------------------------------- write
def model_header(model) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The JSON header (without checksum) and the arrays of a fitted model."""
    arrays: dict[str, np.ndarray] = {}
    state = _pack(model._state(), arrays)
    header = {
        "format": FORMAT,
        "version": VERSION,
        "identifier": model.name,
        "params": model.get_params(),
        "estimation": getattr(model, "estimation_", None),
        "software": {"piezotwin": _version()},
        "state": state,
        "arrays": {k: {"dtype": v.dtype.str, "shape": list(v.shape)} for k, v in arrays.items()},
    }
    # through JSON once, so the checksum sees exactly what a reader will parse (tuples -> lists, numpy -> Python)
    header = json.loads(json.dumps(header, default=json_default))
    header["checksum"] = _checksum(header, arrays)
    return header, arrays


def write_model(model, path: str | os.PathLike) -> Path:
    """Write ``model`` (fitted) to ``path`` atomically: JSON for ``.json``, the npz container otherwise."""
    header, arrays = model_header(model)
    with atomic_path(path) as tmp:
        if tmp.suffix.lower() == ".json":
            doc = dict(header)
            doc["arrays"] = {k: {**header["arrays"][k], "data": arrays[k].tolist()} for k in arrays}
            tmp.write_text(json.dumps(doc, default=json_default))
        else:
            with open(tmp, "wb") as fh:  # a handle: np.savez would append ".npz" to other names
                named: dict[str, Any] = arrays  # names a0, a1, ... (never savez's allow_pickle)
                np.savez(fh, header=np.array(json.dumps(header)), **named)
    return Path(path)


# ---------------------------------------------------------------------------------------------- read
def read_model(path: str | os.PathLike):
    """Load a model file of any version/container (see the module docstring); return the fitted identifier."""
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: model file not found")
    if path.is_dir():
        raise DataError(f"{path}: is a directory, expected a model file")
    if path.stat().st_size == 0:
        raise DataError(f"{path}: model file is empty")
    with open(path, "rb") as fh:
        magic = fh.read(4)
    if magic == b"PK\x03\x04" or path.suffix.lower() == ".pt":
        if path.suffix.lower() == ".pt" or _is_torch_zip(path):
            from sysid.registry import binary_loader

            loader = binary_loader(Path("x.pt"))
            if loader is None:  # pragma: no cover - registry always has .pt
                raise DataError(f"{path}: torch model files cannot be read in this build")
            return loader(path)
        header, arrays = _read_npz(path)
    else:
        try:
            doc = json.loads(path.read_text())
        except UnicodeDecodeError:
            raise DataError(f"{path}: not a piezotwin model file (neither JSON nor npz)") from None
        except json.JSONDecodeError as exc:
            raise DataError(
                f"{path}: not a piezotwin model file, or truncated (invalid JSON: {exc.msg} at line {exc.lineno})"
            ) from None
        if isinstance(doc, dict) and doc.get("format") == LEGACY_FORMAT:
            return build_model(path, doc, legacy=True)
        header, arrays = _json_container(path, doc)
    return build_model(path, header, arrays=arrays)


def _is_torch_zip(path: Path) -> bool:
    try:
        with zipfile.ZipFile(path) as z:
            return any(n.endswith("/data.pkl") for n in z.namelist())
    except (zipfile.BadZipFile, OSError):
        return False


def _read_npz(path: Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    try:
        with open(path, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            if "header" not in z.files:
                raise DataError(
                    f"{path}: not a piezotwin model file (an npz without a 'header' entry; "
                    f"entries: {', '.join(sorted(z.files)[:6]) or 'none'})"
                )
            text = str(z["header"])
            arrays = {k: z[k] for k in z.files if k != "header"}
    except DataError:
        raise
    except Exception as exc:  # BadZipFile (truncated), ValueError (pickled entries), OSError, zlib errors
        raise DataError(f"{path}: damaged or truncated model file ({type(exc).__name__}: {exc})") from None
    try:
        header = json.loads(text)
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: model header is not valid JSON ({exc.msg})") from None
    _check_header(path, header)
    return header, arrays


def _json_container(path: Path, doc: Any) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    _check_header(path, doc)
    arrays = {}
    spec = doc.get("arrays", {})
    if not isinstance(spec, dict):
        raise DataError(f"{path}: model file's 'arrays' is not an object")
    for name, a in spec.items():
        try:
            arrays[name] = np.asarray(a["data"], dtype=np.dtype(a["dtype"])).reshape(a["shape"])
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(
                f"{path}: array {name!r} of the model file is damaged ({type(exc).__name__}: {exc})"
            ) from None
    return doc, arrays


def _check_header(path: Path, header: Any) -> None:
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        found = header.get("format") if isinstance(header, dict) else type(header).__name__
        raise DataError(f"{path}: not a piezotwin model file (format {found!r}, expected {FORMAT!r})")
    version = header.get("version")
    if not isinstance(version, int) or isinstance(version, bool):
        raise DataError(f"{path}: model file has no valid format version ({version!r})")
    if version > VERSION:
        raise DataError(
            f"{path}: model file format version {version} is newer than this piezotwin reads "
            f"(up to {VERSION}); update piezotwin"
        )
    missing = [k for k in ("identifier", "params", "state", "checksum") if k not in header]
    if missing:
        raise DataError(f"{path}: model file lacks {', '.join(missing)}")


def build_model(path: Path, header: dict[str, Any], arrays: dict[str, np.ndarray] | None = None, legacy: bool = False):
    """The identifier described by a parsed header (shared by every container and by the torch loader)."""
    from sysid.registry import get_identifier

    if not legacy and arrays is not None:
        if set(header.get("arrays", {})) != set(arrays):
            raise DataError(f"{path}: model file's arrays do not match its header (damaged file)")
        if _checksum(header, arrays) != header["checksum"]:
            raise DataError(
                f"{path}: model file content does not match its checksum: edited or damaged "
                "(re-save the model instead of editing the file)"
            )
    missing = [k for k in ("identifier", "params", "state") if k not in header]
    if missing:
        raise DataError(f"{path}: model file lacks {', '.join(missing)}")
    try:
        cls = get_identifier(header["identifier"])
    except ConfigError as exc:
        raise DataError(f"{path}: {exc}") from None
    params = header["params"]
    if not isinstance(params, dict):
        raise DataError(f"{path}: model file has options {type(params).__name__}, expected an object")
    from sysid.config import resolve_aliases

    params = resolve_aliases(params, cls._param_names(), f"{path}")  # files written before an option was renamed
    unknown = sorted(set(params) - set(cls._param_names()))
    if unknown:
        raise DataError(f"{path}: model file has options {', '.join(unknown)} that {cls.name} does not take")
    state = _unpack(header["state"], arrays or {})
    try:
        model = cls(**params)
        model._load_state(state)
    except InputError as exc:
        raise DataError(f"{path}: not a valid {cls.name} model: {exc}") from None
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, RuntimeError) as exc:
        what = f"lacks {exc}" if isinstance(exc, KeyError) else f"{type(exc).__name__}: {exc}"
        raise DataError(f"{path}: not a valid {cls.name} model (its state {what})") from None
    est = header.get("estimation")
    if isinstance(est, dict):
        model.estimation_ = est
        if isinstance(est.get("fs"), (int, float)):
            model.fs_ = float(est["fs"])
    return model


def header_of(path: str | os.PathLike) -> dict[str, Any]:
    """The JSON header of a version-2 model file (for ``piezotwin predict --json`` / documentation tools)."""
    path = Path(path)
    with open(path, "rb") as fh:
        magic = fh.read(4)
    if magic == b"PK\x03\x04":
        return _read_npz(path)[0]
    doc = json.loads(path.read_text())
    return {k: v for k, v in doc.items() if k != "arrays"}
