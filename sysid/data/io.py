"""Reading and writing :class:`~sysid.data.record.Record` files (the formats every command reads and writes).

- ``.npz``: arrays ``u``, ``y`` (absent for input-only records), scalar ``fs`` and ``meta``, a JSON string that
  also carries the units. Loadable with plain ``numpy.load(path, allow_pickle=False)``.
- ``.csv``: a header row names the columns (a file without a header has its columns named ``0, 1, 2 ...``).
  The sampling rate comes from a ``t`` column (uniform within 1 %) or from ``fs``. Columns are chosen with
  ``u_col`` / ``y_col`` (default ``u`` and ``y``; several channels as ``"u1,u2"``). Columns that are not
  selected may hold anything, including empty cells (an empty trailing column is common).
- ``.mat``: variables chosen by ``u_var`` / ``y_var`` (default ``u`` and ``y``), ``fs`` from ``fs_var`` (default
  ``fs``) or from ``fs``; MATLAB v7.3 files (HDF5) are read with h5py.

An explicit ``fs`` (the CLI's ``--fs``) supplies the rate of a file that has none; when the file has its own
(``t`` column, ``fs`` array/variable), the two must agree (to the 1 % the ``t`` column is held to, else to
1e-9 relative) and the explicit value is used; a conflict is an error, never silently resolved.

Every failure raises :class:`~sysid.errors.DataError` with one line naming the file and the problem.
Missing samples (NaN, empty cells) are refused unless ``fill_missing=True``, which interpolates them linearly
and records every filled index in ``meta['preprocessing']``.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from sysid.data.jsonio import json_default
from sysid.data.record import FS_MAX, FS_MIN, Record, check_array
from sysid.data.safeio import atomic_path, atomic_write_text, check_output_path, save_figure
from sysid.errors import DataError

__all__ = [
    "read_record",
    "write_record",
    "output_file",
    "atomic_path",
    "atomic_write_text",
    "check_output_path",
    "save_figure",
    "SUPPORTED_SUFFIXES",
    "FS_MIN",
    "FS_MAX",
    "check_fs",
]

SUPPORTED_SUFFIXES = (".npz", ".csv", ".mat")
_UNIFORM_TOL = 0.01  # relative jitter of the t column accepted as uniform sampling


def check_fs(fs: Any, what: str) -> float:
    """``fs`` as a float in [FS_MIN, FS_MAX] Hz, or a one-line DataError naming ``what``."""
    try:
        v = float(fs)
    except (TypeError, ValueError, OverflowError):
        raise DataError(f"{what}: sampling rate is not a number ({fs!r})") from None
    if not math.isfinite(v) or v <= 0:
        raise DataError(f"{what}: sampling rate fs must be positive and finite, got {v:g}")
    if not FS_MIN <= v <= FS_MAX:
        raise DataError(f"{what}: sampling rate {v:g} Hz outside the accepted range {FS_MIN:g}..{FS_MAX:g} Hz")
    return v


def write_record(record: Record, path: str | os.PathLike) -> Path:
    """Write ``record`` to ``path``: ``.npz`` (the native format, with metadata), or ``.csv`` / ``.mat`` for
    other tools (columns/variables ``t, u, y`` resp. ``u, y, fs``; the CSV keeps the metadata out).
    Every format reads back bit-exactly (CSV uses the shortest round-tripping decimal text).

    The write is atomic and non-destructive (:func:`sysid.data.safeio.atomic_path`): a temporary file beside
    ``path`` is renamed over it only when complete; an output that is the same file as a protected input is
    refused before anything is written."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise DataError(
            f"{path}: unknown format {suffix or '(no suffix)'!r}; supported: {', '.join(SUPPORTED_SUFFIXES)}"
        )
    with atomic_path(path) as tmp:
        if suffix == ".csv":
            _write_csv(record, tmp)
        elif suffix == ".mat":
            from scipy.io import savemat

            mdict = {"u": record.u, "fs": record.fs}
            if record.y is not None:
                mdict["y"] = record.y
            savemat(tmp, mdict)
        else:
            meta = dict(record.meta)
            meta["units"] = dict(record.units)
            arrays: dict[str, Any] = {
                "u": record.u,
                "fs": np.float64(record.fs),
                "meta": np.array(json.dumps(meta, default=json_default)),
            }
            if record.y is not None:
                arrays["y"] = record.y
            np.savez(tmp, **arrays)
    return path


# Every writer of the project uses this context (kept under its old name for the existing callers).
output_file = atomic_path


def _write_csv(record: Record, path: Path) -> None:
    def names(x: np.ndarray, base: str) -> list[str]:
        return [base] if x.ndim == 1 else [f"{base}{i + 1}" for i in range(x.shape[1])]

    cols = [record.u.reshape(len(record), -1)]
    header = names(record.u, "u")
    if record.y is not None:
        cols.append(record.y.reshape(len(record), -1))
        header += names(record.y, "y")
    data = np.hstack(cols)
    with open(path, "w", newline="") as fh:
        fh.write(",".join(["t"] + header) + "\n")
        for k, row in enumerate(data):
            fh.write(",".join([repr(k / record.fs)] + [repr(float(v)) for v in row]) + "\n")


def read_record(
    path: str | os.PathLike,
    *,
    fs: float | None = None,
    u_col: str = "u",
    y_col: str | None = "y",
    u_var: str = "u",
    y_var: str | None = "y",
    fs_var: str = "fs",
    require_y: bool = False,
    fill_missing: bool = False,
) -> Record:
    """Read a Record from ``.npz``, ``.csv`` or ``.mat``.

    ``fs`` overrides (or supplies) the sampling rate. ``y_col`` / ``y_var`` of ``None`` read an input-only
    record; otherwise a missing output column is an error only if ``require_y`` is true or the column was
    named explicitly (not the default ``y``).
    """
    p = Path(path)
    src = str(path)
    if not p.exists():
        raise DataError(f"{src}: file not found")
    if p.is_dir():
        raise DataError(f"{src}: is a directory, expected a data file")
    suffix = p.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise DataError(
            f"{src}: unknown format {suffix or '(no suffix)'!r}; supported: {', '.join(SUPPORTED_SUFFIXES)}"
        )
    if p.stat().st_size == 0:
        raise DataError(f"{src}: file is empty")
    if fs is not None:
        fs = check_fs(fs, f"{src}: --fs / fs=")
    if suffix == ".npz":
        u, y, file_fs, units, meta = _read_npz(p, src)
    elif suffix == ".csv":
        u, y, file_fs, units, meta = _read_csv(p, src, u_col, y_col, explicit_y=(y_col not in (None, "y")))
    else:
        u, y, file_fs, units, meta = _read_mat(p, src, u_var, y_var, fs_var, explicit_y=(y_var not in (None, "y")))
    if fs is None:
        if file_fs is None:
            raise DataError(f"{src}: no sampling rate in the file (no time column, fs or Ts); give --fs / fs=")
        fs = check_fs(file_fs, src)
    elif file_fs is not None:
        where, tol = meta.pop("_fs_from", "its fs"), 1e-9
        if "time" in where:
            tol = _UNIFORM_TOL
        if not math.isclose(float(fs), file_fs, rel_tol=tol):
            raise DataError(
                f"{src}: --fs / fs={float(fs):g} Hz contradicts the file's own sampling rate "
                f"{file_fs:.10g} Hz (from {where}); leave out --fs or correct the file"
            )
    if require_y and y is None:
        raise DataError(f"{src}: missing output column/variable y")
    meta.pop("_fs_from", None)
    meta.setdefault("provenance", {"file": os.path.basename(src)})
    filled: dict[str, list[int]] = {}
    u = check_array(u, "u", src, allow_nan=True)
    if y is not None:
        y = check_array(y, "y", src, allow_nan=True)
    if fill_missing:
        u, filled_u = _fill(u, "u", src)
        if filled_u:
            filled["u"] = filled_u
        if y is not None:
            y, filled_y = _fill(y, "y", src)
            if filled_y:
                filled["y"] = filled_y
        if filled:
            # same schema as sysid.signals.preprocess.apply_steps (step, params, changes); filled_indices kept at
            # top level too
            meta.setdefault("preprocessing", []).append(
                {
                    "step": "fill_missing",
                    "params": {"method": "linear", "at": "read"},
                    "changes": {"filled_indices": filled},
                    "filled_indices": filled,
                }
            )
    if y is not None and y.shape[0] != u.shape[0]:
        raise DataError(f"{src}: u and y have unequal lengths ({u.shape[0]} and {y.shape[0]} samples)")
    return Record(u=u, y=y, fs=fs, units=units, meta=meta, source=src)


def _fill(x: np.ndarray, name: str, src: str) -> tuple[np.ndarray, list[int]]:
    """Linear interpolation of non-finite samples (per channel); ends are held at the nearest good value."""
    if np.isinf(x).any():
        raise DataError(f"{src}: {name} has infinite samples; only missing (NaN/empty) samples can be interpolated")
    bad = np.isnan(x)
    if not bad.any():
        return x, []
    x2 = x.reshape(x.shape[0], -1).copy()
    idx = np.arange(x2.shape[0])
    for c in range(x2.shape[1]):
        b = np.isnan(x2[:, c])
        if b.all():
            raise DataError(f"{src}: {name} has no valid samples to interpolate from")
        if b.any():
            x2[b, c] = np.interp(idx[b], idx[~b], x2[~b, c])
    rows = np.flatnonzero(bad.reshape(x.shape[0], -1).any(axis=1)).tolist()
    return x2.reshape(x.shape), rows


# ---------------------------------------------------------------------------------------------- npz
def _read_npz(p: Path, src: str):
    try:
        # an open handle, not the path: numpy leaks the file it opened when the zip is corrupt
        with open(p, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            keys = set(z.files)
            if "u" not in keys:
                raise DataError(f"{src}: missing array 'u' (found: {', '.join(sorted(keys)) or 'none'})")
            u = z["u"]
            y = z["y"] if "y" in keys else None
            fs = _scalar_fs(z["fs"], src) if "fs" in keys else None
            meta: dict[str, Any] = {}
            if "meta" in keys:
                try:
                    meta = json.loads(str(z["meta"]))
                except json.JSONDecodeError as exc:
                    raise DataError(f"{src}: 'meta' is not valid JSON ({exc.msg})") from None
                if not isinstance(meta, dict):
                    raise DataError(f"{src}: 'meta' must be a JSON object, got {type(meta).__name__}")
    except DataError:
        raise
    except Exception as exc:  # zipfile.BadZipFile, ValueError (pickled object arrays), OSError
        raise DataError(f"{src}: not a readable .npz file ({type(exc).__name__}: {exc})") from None
    units = meta.pop("units", {"u": "", "y": ""})
    _check_meta(meta, units, src)
    u = _check_orientation(u, "u", src)
    y = None if y is None else _check_orientation(y, "y", src)
    return u, y, fs, units, meta


def _check_orientation(x: Any, name: str | None, src: str) -> np.ndarray:
    """Samples run along the first axis; a 2-D array with fewer rows than columns is refused, never
    transposed silently (a (1, N) array would be 1 sample of N channels)."""
    a = np.asarray(x)
    if a.ndim == 2 and a.shape[0] < a.shape[1]:
        raise DataError(
            f"{src}: {name} has shape {a.shape}: fewer samples than channels; store samples along the "
            f"first axis, i.e. shape (N,) or (N, channels) (e.g. {name}.ravel() or {name}.T)"
        )
    return a


def _check_meta(meta: dict, units: Any, src: str) -> None:
    """Types of the metadata keys the library uses (a wrong type is refused here, not as a traceback later)."""
    if not isinstance(units, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in units.items()):
        raise DataError(f'{src}: meta \'units\' must be an object of strings, e.g. {{"u": "V", "y": "um"}}')
    if "t0" in meta and (
        isinstance(meta["t0"], bool) or not isinstance(meta["t0"], (int, float)) or not math.isfinite(meta["t0"])
    ):
        raise DataError(f"{src}: meta 't0' must be a finite number of seconds, got {meta['t0']!r}")
    for key in ("preprocessing", "segments"):
        if key in meta and not isinstance(meta[key], list):
            raise DataError(f"{src}: meta {key!r} must be a list, got {type(meta[key]).__name__}")
    for i, seg in enumerate(meta.get("segments", [])):
        if not (
            isinstance(seg, dict)
            and all(isinstance(v := seg.get(k), int) and not isinstance(v, bool) and v >= 0 for k in ("start", "stop"))
        ):
            raise DataError(f"{src}: meta 'segments'[{i}] must be an object with integer start and stop >= 0")
    for key in ("provenance", "signal", "twin_config"):
        if key in meta and not isinstance(meta[key], dict):
            raise DataError(f"{src}: meta {key!r} must be an object, got {type(meta[key]).__name__}")


def _scalar_fs(value: Any, src: str) -> float:
    a = np.asarray(value)
    if a.size != 1:
        raise DataError(f"{src}: fs must be a single number, got an array of shape {a.shape}")
    try:
        return float(a.reshape(()))
    except (TypeError, ValueError):
        raise DataError(f"{src}: fs is not a number ({a.reshape(())!r})") from None


# ---------------------------------------------------------------------------------------------- csv
def _read_csv(p: Path, src: str, u_col: str, y_col: str | None, explicit_y: bool):
    """Strict CSV reading (rules in :mod:`sysid.data.csvread` and docs/data-files.md)."""
    from sysid.data.csvread import TIME_COLUMNS, parse_csv

    table = parse_csv(p, src)
    index = table.index
    time_cols = [n for n in index if n.strip().lower() in TIME_COLUMNS]
    wanted = [s.strip() for spec in (u_col, y_col) if spec is not None for s in str(spec).split(",")]
    table.prefetch(wanted + time_cols[:1])  # one parsing pass for every column used

    def columns(spec: str, role: str) -> np.ndarray:
        names = [s.strip() for s in str(spec).split(",") if s.strip()]
        missing = [n for n in names if n not in index]
        if missing:
            raise DataError(
                f"{src}: missing column {missing[0]!r} for {role} (columns: {', '.join(index) or 'none'}); "
                f"choose with --{role}-col"
            )
        cols = table.columns(names)
        return cols[0] if len(cols) == 1 else np.column_stack(cols)

    u = columns(u_col, "u")
    y = None
    if y_col is not None:
        names = [s.strip() for s in str(y_col).split(",") if s.strip()]
        if all(n in index for n in names):
            y = columns(y_col, "y")
        elif explicit_y:
            columns(y_col, "y")  # raises the clear message
    fs = None
    if len(time_cols) > 1:
        raise DataError(f"{src}: several time columns ({', '.join(time_cols)}); keep one")
    if time_cols:
        name = time_cols[0]
        t = table.columns([name])[0] * TIME_COLUMNS[name.strip().lower()]
        fs = _fs_from_time(t, src, name)
    meta: dict[str, Any] = {"provenance": {"file": p.name, "u_col": u_col, "y_col": y_col}}
    if time_cols:
        meta["provenance"]["time_col"] = time_cols[0]
        meta["_fs_from"] = f"its time column {time_cols[0]!r}"
    return u, y, fs, {"u": "", "y": ""}, meta


def _fs_from_time(t: np.ndarray, src: str, name: str = "t") -> float:
    """Sampling rate [Hz] of a uniform time vector ``t`` [s] (uniform to 1 % of the mean step)."""
    if t.size < 2 or not np.isfinite(t).all():
        raise DataError(
            f"{src}: time column/variable {name!r} needs at least two finite values to give the sampling rate"
        )
    d = np.diff(t)
    span = t[-1] - t[0]
    if span <= 0:
        raise DataError(f"{src}: time column/variable {name!r} is not increasing")
    dt = span / (t.size - 1)
    if np.max(np.abs(d - dt)) > _UNIFORM_TOL * dt:
        raise DataError(
            f"{src}: time column/variable {name!r} is not uniformly sampled (steps {d.min():.6g}..{d.max():.6g} s); "
            "resample first"
        )
    return 1.0 / dt


# ---------------------------------------------------------------------------------------------- mat
def _read_mat(p: Path, src: str, u_var: str, y_var: str | None, fs_var: str, explicit_y: bool):
    from scipy.io import loadmat

    try:
        data = loadmat(p, squeeze_me=True)
        variables = {k: v for k, v in data.items() if not k.startswith("__")}
    except NotImplementedError:  # v7.3 = HDF5
        variables = _read_mat73(p, src)
    except Exception as exc:
        raise DataError(f"{src}: not a readable .mat file ({type(exc).__name__}: {exc})") from None
    if u_var not in variables:
        raise DataError(
            f"{src}: missing variable {u_var!r} for u (variables: {', '.join(sorted(variables)) or 'none'}); "
            "choose with --u-var"
        )
    u = _mat_numeric(variables[u_var], u_var, src)
    y = None
    if y_var is not None:
        if y_var in variables:
            y = _mat_numeric(variables[y_var], y_var, src)
        elif explicit_y:
            raise DataError(
                f"{src}: missing variable {y_var!r} for y (variables: {', '.join(sorted(variables))}); "
                "choose with --y-var"
            )
    # the rate: fs_var (default fs), else a scalar Ts [s], else a time vector t / time [s]; several must agree
    rates: list[tuple[float, str]] = []
    if fs_var in variables:
        rates.append((_scalar_fs(variables[fs_var], src), f"its {fs_var}"))
    if "Ts" in variables:
        ts = _scalar_fs(variables["Ts"], src)
        if not (math.isfinite(ts) and ts > 0):
            raise DataError(f"{src}: Ts must be a positive sampling interval in seconds, got {ts!r}")
        rates.append((1.0 / ts, "its Ts"))
    for tname in ("t", "time"):
        if tname in variables and tname not in (u_var, y_var):
            t = _mat_numeric(variables[tname], tname, src)
            if t.ndim != 1:
                raise DataError(f"{src}: time variable {tname!r} must be a vector, got shape {t.shape}")
            rates.append((_fs_from_time(t.astype(float), src, tname), f"its time variable {tname!r}"))
            break
    for r, w in rates[1:]:
        tol = _UNIFORM_TOL if "time" in w else 1e-9
        if not math.isclose(r, rates[0][0], rel_tol=tol):
            raise DataError(f"{src}: {rates[0][1]} ({rates[0][0]:.10g} Hz) and {w} ({r:.10g} Hz) disagree")
    fs = rates[0][0] if rates else None
    # MATLAB row and column vectors are squeezed to 1-D (one channel); matrices must be samples x channels
    u = _check_orientation(u, u_var, src)
    y = None if y is None else _check_orientation(y, y_var, src)
    meta: dict[str, Any] = {"provenance": {"file": p.name, "u_var": u_var, "y_var": y_var}}
    if rates:
        meta["_fs_from"] = rates[0][1]
    return u, y, fs, {"u": "", "y": ""}, meta


def _mat_numeric(value: Any, name: str, src: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "biufc":  # strings, cells, structs (numbers, incl. complex, go on to check_array)
        try:
            arr = arr.astype(float)
        except (TypeError, ValueError):
            raise DataError(f"{src}: variable {name!r} is not numeric ({arr.dtype})") from None
    return arr.squeeze()


def _read_mat73(p: Path, src: str) -> dict[str, np.ndarray]:
    try:
        import h5py
    except ImportError:  # pragma: no cover - h5py is a runtime dependency
        raise DataError(f"{src}: MATLAB v7.3 file needs h5py") from None
    out: dict[str, np.ndarray] = {}
    try:
        with h5py.File(p, "r") as f:
            for k in f.keys():
                link = f.get(k, getlink=True)
                if isinstance(link, h5py.ExternalLink):  # never follow a path to another file
                    raise DataError(
                        f"{src}: variable {k!r} is an external link to {link.filename}; "
                        "external links are refused (copy the data into the file)"
                    )
                v = f.get(k)
                if isinstance(v, h5py.Dataset):
                    if v.external or v.is_virtual:
                        raise DataError(
                            f"{src}: variable {k!r} stores its data in another file; refused "
                            "(copy the data into the file)"
                        )
                    out[k] = np.asarray(v).T
    except DataError:
        raise
    except Exception as exc:
        raise DataError(f"{src}: not a readable .mat file ({type(exc).__name__}: {exc})") from None
    return out
