"""Recorded lab data: readers of the original published files, the vendored copies, and the official splits.

Each lab dataset is built in two steps:

1. *raw records*: the continuous records exactly as published (float64, nothing dropped or altered), either
   read from the original files (:func:`read_original`, what a user downloads from the benchmark's page) or
   from the compact copies vendored in ``benchmarks/data/<folder>/`` (:func:`read_vendored`; each is a Record
   ``.npz`` written by :mod:`benchmarks.datasets.vendor` from the originals, see its ``PROVENANCE.txt``);
2. :func:`build` cuts them into the official estimation and test splits with the initialisation window that
   the literature uses, and attaches the published reference numbers.

So the numbers scored here compare with the literature, and the same code runs on the user's own copy of the
published files (``load_dataset("silverbox", source="path/to/SilverboxFiles")``).
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sysid.data.io import read_record
from sysid.data.record import Record
from sysid.errors import DataError

DATA_DIR = Path(__file__).resolve().parents[1] / "data"

# Sampling rates from the benchmark descriptions (SOURCE.txt of each folder).
SILVERBOX_FS_HZ = 610.35  # Wigren & Schoukens 2013; the official loaders use 610.35 Hz (= 1e7/2**14 rounded)
WH_FS_HZ = 51200.0  # SYSID 2009 Wiener-Hammerstein benchmark, fs column of the file
CASCADED_TANKS_TS_S = 4.0  # Schoukens et al., Ts column of dataBenchmark.csv
BOUC_WEN_FS_HZ = 750.0  # Noel & Schoukens 2016, fs of the benchmark records
PIEZO_TUE_FS_HZ = 5000.0  # SmartHysteresis data: dt = 0.2 ms (SOURCE.txt)


@dataclass(frozen=True)
class LabSpec:
    """How one lab dataset is stored: the vendored folder, its record files and the original files."""

    name: str
    folder: str
    records: tuple[str, ...]  # raw record names = vendored file stems
    originals: tuple[str, ...]  # original file names (in the folder given as source)
    read_original: Callable[[Path], dict[str, Record]]


# ------------------------------------------------------------------------------------------ originals
def _csv_first_row(path: Path) -> dict[str, str]:
    """Header → value of the first data row (for scalar columns like fs/Ts stored only in row 1)."""
    with open(path, newline="", encoding="utf-8-sig") as fh:
        rows = csv.reader(fh)
        header = [h.strip() for h in next(rows)]
        first = next(rows)
    return {h: v.strip() for h, v in zip(header, first) if h}


def _find(source: Path, names: tuple[str, ...]) -> Path:
    """The first of ``names`` that exists in folder ``source`` (or ``source`` itself if it is that file)."""
    if source.is_file():
        if source.name in names or source.suffix.lower() in {Path(n).suffix.lower() for n in names}:
            return source
        raise DataError(f"{source}: expected one of {', '.join(names)}")
    for n in names:
        if (source / n).exists():
            return source / n
    raise DataError(f"{source}: none of {', '.join(names)} found")


def _check_fs(found: float, expected: float, src: Path, what: str = "fs") -> None:
    if not np.isclose(found, expected, rtol=1e-9):
        raise DataError(f"{src}: {what} = {found:g}, the benchmark description says {expected:g}")


def silverbox_original(source: Path) -> dict[str, Record]:
    """``SNLS80mV.csv`` (columns V1 = input, V2 = output, trailing empty column) or ``SNLS80mV.mat``."""
    p = _find(source, ("SNLS80mV.csv", "SNLS80mV.mat"))
    if p.suffix.lower() == ".csv":
        rec = read_record(p, fs=SILVERBOX_FS_HZ, u_col="V1", y_col="V2", require_y=True)
    else:
        rec = read_record(p, fs=SILVERBOX_FS_HZ, u_var="V1", y_var="V2", require_y=True)
    return {"SNLS80mV": _label(rec, "V", "V", p)}


def wiener_hammerstein_original(source: Path) -> dict[str, Record]:
    """``WienerHammerBenchmark.csv`` (uBenchMark, yBenchMark, fs in row 1) or ``WienerHammerBenchMark.mat``."""
    p = _find(source, ("WienerHammerBenchmark.csv", "WienerHammerBenchMark.mat", "WienerHammerBenchmark.mat"))
    if p.suffix.lower() == ".csv":
        fs = float(_csv_first_row(p)["fs"])
        _check_fs(fs, WH_FS_HZ, p)
        rec = read_record(p, fs=fs, u_col="uBenchMark", y_col="yBenchMark", require_y=True)
    else:
        rec = read_record(p, u_var="uBenchMark", y_var="yBenchMark", require_y=True)
        _check_fs(rec.fs, WH_FS_HZ, p)
    return {"WienerHammerBenchmark": _label(rec, "V", "V", p)}


def cascaded_tanks_original(source: Path) -> dict[str, Record]:
    """``dataBenchmark.csv`` (uEst, uVal, yEst, yVal, Ts in row 1) or ``dataBenchmark.mat``."""
    p = _find(source, ("dataBenchmark.csv", "dataBenchmark.mat"))
    fs = 1.0 / CASCADED_TANKS_TS_S
    out = {}
    for part in ("Est", "Val"):
        if p.suffix.lower() == ".csv":
            ts = float(_csv_first_row(p)["Ts"])
            _check_fs(ts, CASCADED_TANKS_TS_S, p, "Ts")
            rec = read_record(p, fs=fs, u_col=f"u{part}", y_col=f"y{part}", require_y=True)
        else:
            rec = read_record(p, fs=fs, u_var=f"u{part}", y_var=f"y{part}", require_y=True)
        out[part.lower()] = _label(rec, "V", "V", p)
    return out


def bouc_wen_original(source: Path) -> dict[str, Record]:
    """Training set ``train_forgione_generated.h5`` (or dynonet's ``train.h5``: ``multisine/{u,y,fs}``) and the
    official test records ``{u,y}val_{multisine,sinesweep}.mat`` (variables of the same names)."""
    import h5py

    if not source.is_dir():
        raise DataError(f"{source}: give the folder that holds the Bouc-Wen files")
    h5 = _find(source, ("train_forgione_generated.h5", "train.h5"))
    try:
        with h5py.File(h5, "r") as f:
            u = np.asarray(f["multisine/u"], dtype=np.float64)
            y = np.asarray(f["multisine/y"], dtype=np.float64)
            fs = float(np.asarray(f["multisine/fs"]).squeeze())
    except (OSError, KeyError) as exc:
        raise DataError(f"{h5}: not the Bouc-Wen training file (multisine/u, y, fs) ({exc})") from None
    _check_fs(fs, BOUC_WEN_FS_HZ, h5)
    out = {"train": _label(Record(u=u, y=y, fs=fs, source=str(h5)), "N", "m", h5)}
    from scipy.io import loadmat

    for kind in ("multisine", "sinesweep"):
        pu, py = _find(source, (f"uval_{kind}.mat",)), _find(source, (f"yval_{kind}.mat",))
        try:
            uu = np.asarray(loadmat(pu)[f"uval_{kind}"], dtype=np.float64).ravel()
            yy = np.asarray(loadmat(py)[f"yval_{kind}"], dtype=np.float64).ravel()
        except KeyError as exc:
            raise DataError(f"{pu.parent}: missing variable {exc} in the {kind} test files") from None
        rec = Record(u=uu, y=yy, fs=BOUC_WEN_FS_HZ, source=str(pu))
        out[f"test_{kind}"] = _label(rec, "N", "m", pu, py)
    return out


def piezo_tue_original(source: Path) -> dict[str, Record]:
    """``hysteresis_v_150_1hz.csv``: no header, columns [empty index, t s, displacement µm, voltage V]."""
    p = _find(source, ("hysteresis_v_150_1hz.csv",))
    rec = read_record(p, fs=PIEZO_TUE_FS_HZ, u_col="3", y_col="2", require_y=True)
    t = read_record(p, fs=PIEZO_TUE_FS_HZ, u_col="1", y_col=None).u
    dt = np.diff(t)
    if abs(np.mean(dt) * PIEZO_TUE_FS_HZ - 1.0) > 1e-3:
        raise DataError(f"{p}: time column gives {1.0 / np.mean(dt):.6g} Hz, expected {PIEZO_TUE_FS_HZ:g} Hz")
    return {"hysteresis_v_150_1hz": _label(rec, "V", "um", p)}


def _label(rec: Record, u_unit: str, y_unit: str, *files: Path) -> Record:
    meta = dict(rec.meta)
    meta["provenance"] = {"files": [f.name for f in files]}
    return rec.replace(units={"u": u_unit, "y": y_unit}, meta=meta)


LAB_SPECS: dict[str, LabSpec] = {
    "silverbox": LabSpec("silverbox", "silverbox", ("SNLS80mV",), ("SNLS80mV.csv",), silverbox_original),
    "wiener-hammerstein": LabSpec(
        "wiener-hammerstein",
        "wiener_hammerstein",
        ("WienerHammerBenchmark",),
        ("WienerHammerBenchmark.csv",),
        wiener_hammerstein_original,
    ),
    "cascaded-tanks": LabSpec(
        "cascaded-tanks", "cascaded_tanks", ("est", "val"), ("dataBenchmark.csv",), cascaded_tanks_original
    ),
    "bouc-wen": LabSpec(
        "bouc-wen",
        "bouc_wen_benchmark",
        ("train", "test_multisine", "test_sinesweep"),
        (
            "train_forgione_generated.h5",
            "uval_multisine.mat",
            "yval_multisine.mat",
            "uval_sinesweep.mat",
            "yval_sinesweep.mat",
        ),
        bouc_wen_original,
    ),
    "piezo-tue": LabSpec(
        "piezo-tue", "piezo_tue_150v_1hz", ("hysteresis_v_150_1hz",), ("hysteresis_v_150_1hz.csv",), piezo_tue_original
    ),
}


def read_original(name: str, source: str | Path) -> dict[str, Record]:
    """Raw records of lab dataset ``name`` from the original published files in ``source`` (folder or file)."""
    spec = LAB_SPECS[name]
    source = Path(source)
    if not source.exists():
        raise DataError(f"{source}: not found (expected the original files of {name}: {', '.join(spec.originals)})")
    return spec.read_original(source)


def read_vendored(name: str, data_dir: Path | None = None) -> dict[str, Record]:
    """Raw records of lab dataset ``name`` from the compact copies in ``benchmarks/data/<folder>/``."""
    return read_vendored_folder(name, (data_dir or DATA_DIR) / LAB_SPECS[name].folder)


def read_vendored_folder(name: str, folder: Path) -> dict[str, Record]:
    """Raw records of lab dataset ``name`` from its vendored record files (``<stem>.npz``) in ``folder``."""
    out = {}
    for stem in LAB_SPECS[name].records:
        path = folder / f"{stem}.npz"
        if not path.exists():
            raise DataError(f"{path}: vendored data missing (rebuild with python -m benchmarks.datasets.vendor)")
        out[stem] = read_record(path, require_y=True)
    return out


# ------------------------------------------------------------------------------------------ splits
# Official splits as half-open sample ranges [start, stop) of the raw records.
SPLITS: dict[str, dict[str, Any]] = {
    # Silverbox: official dataloader (nonlinear_benchmarks): multisine part [40650, 127400), its first 75 %
    # estimation, last 25 % test; arrow (full) test [100, 40575); arrow without extrapolation = its first 32000.
    "silverbox": {
        "est": ("SNLS80mV", 40650, 105712),
        "tests": {
            "multisine": ("SNLS80mV", 105712, 127400),
            "arrow": ("SNLS80mV", 100, 40575),
            "arrow-no-extrapolation": ("SNLS80mV", 100, 32100),
        },
    },
    # Wiener-Hammerstein 2009: estimation samples 1..100000, test 100001..188000 (1-based, SYSID 2009 call);
    # "test-official": the official dataloader's test [105200, 184000) (nonlinear_benchmarks 1.0.1, the test set of
    # SUBNET's published number; its training part [5200, 105200) overlaps this estimation part, which is kept).
    "wiener-hammerstein": {
        "est": ("WienerHammerBenchmark", 0, 100000),
        "tests": {
            "test": ("WienerHammerBenchmark", 100000, 188000),
            "test-official": ("WienerHammerBenchmark", 105200, 184000),
        },
    },
    # Cascaded tanks: "test" with the 4-sample window of the benchmark description, "test-official" the same samples
    # with the official dataloader's 50-sample window (TEST_INIT_SAMPLES).
    "cascaded-tanks": {"est": ("est", 0, 1024), "tests": {"test": ("val", 0, 1024), "test-official": ("val", 0, 1024)}},
    "bouc-wen": {
        "est": ("train", 0, 40960),
        "tests": {"multisine": ("test_multisine", 0, 8192), "sinesweep": ("test_sinesweep", 0, 153000)},
    },
    # piezo actuator (one 10 s record): first 5 s estimation, last 5 s test.
    "piezo-tue": {"est": ("hysteresis_v_150_1hz", 0, 25000), "tests": {"test": ("hysteresis_v_150_1hz", 25000, 50001)}},
}

INIT_SAMPLES = {"silverbox": 50, "wiener-hammerstein": 50, "cascaded-tanks": 4, "bouc-wen": 0, "piezo-tue": 0}
# Tests whose initialisation window differs from the dataset's INIT_SAMPLES (the official dataloader's windows).
TEST_INIT_SAMPLES = {"cascaded-tanks": {"test-official": 50}}


def cut(raws: dict[str, Record], name: str) -> tuple[Record, dict[str, Record]]:
    """(estimation record, named test records) of lab dataset ``name`` from its raw records."""
    split = SPLITS[name]

    def take(key: str, a: int, b: int, part: str) -> Record:
        rec = raws[key]
        if b > len(rec):
            raise DataError(f"{name}: record {key} has {len(rec)} samples, the official split needs {b}")
        out = rec[a:b]
        out.meta["split"] = {"dataset": name, "part": part, "record": key, "start": a, "stop": b}
        return out

    key, a, b = split["est"]
    est = take(key, a, b, "est")
    tests = {t: take(k, a, b, t) for t, (k, a, b) in split["tests"].items()}
    return est, tests
