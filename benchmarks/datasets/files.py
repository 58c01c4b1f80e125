"""Where the lab data live: dataset id → files, licence, source note and loader.

Every measured data file in ``benchmarks/data/`` is found through :data:`LAB_DATA`, the one table of them.
An entry names the folder, the data files in it, the licence and ``SOURCE.txt`` files that travel with them
(where the data come from and on what terms), and the loader that turns the folder into what its users
receive: Records for the scored benchmarks, arrays of impulse responses for the water channel. The twins that
are compared with lab data (:mod:`twins.cantilever.lab`, :mod:`twins.acoustic.labdata`) are handed those
records and arrays by this package; they never learn where the files are.

``read(id)`` loads the vendored copy; ``read(id, source=FOLDER)`` the same files from a folder of the
user's (for the water channel: the ``data`` folder of the published repository, which holds ``charac/``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.datasets import lab
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError

__all__ = [
    "LabData",
    "LAB_DATA",
    "SCORED_LAB",
    "get",
    "read",
    "piezo_tue_record",
    "water_fir",
    "read_water_fir",
    "WATER_DISTANCES_MM",
]

DATA_DIR = lab.DATA_DIR


@dataclass(frozen=True)
class LabData:
    """One lab dataset as stored: its folder under the data directory and what is in it."""

    id: str
    folder: str
    files: tuple[str, ...]  # data files, relative to the folder
    licence: str  # the licence file beside them
    load: Callable[[Path], Any]  # folder -> records or arrays
    source: str = "SOURCE.txt"  # origin, citation and how the copy was made

    def folder_path(self, data_dir: str | Path | None = None) -> Path:
        return Path(data_dir or DATA_DIR) / self.folder

    def paths(self, data_dir: str | Path | None = None) -> list[Path]:
        """The data files (not the licence or source notes)."""
        return [self.folder_path(data_dir) / f for f in self.files]

    def licence_path(self, data_dir: str | Path | None = None) -> Path:
        return self.folder_path(data_dir) / self.licence

    def source_path(self, data_dir: str | Path | None = None) -> Path:
        return self.folder_path(data_dir) / self.source

    def read(self, source: str | Path | None = None) -> Any:
        """What the loader makes of the vendored folder, or of ``source`` (a folder with the same files)."""
        folder = Path(source) if source is not None else self.folder_path()
        if not folder.is_dir():
            raise DataError(f"{folder}: not a folder (expected the files of {self.id}: {', '.join(self.files)})")
        return self.load(folder)


# ------------------------------------------------------------------------------------------ water channel
WATER_DISTANCES_MM = (1, 20, 40, 80)
_WATER_FS_HZ = 5e6  # every FIR struct of the .mat files states it


def _read_charac_mat(path: Path) -> np.ndarray:
    """The 20 impulse responses (FIR1..FIR4, 5 each; shape (20, 2000)) of one ``charac_water_<d>.mat``."""
    from scipy.io import loadmat

    if not path.exists():
        raise DataError(f"{path}: lab data file not found (distances: {', '.join(map(str, WATER_DISTANCES_MM))} mm)")
    m = loadmat(path, squeeze_me=True, struct_as_record=False)
    blocks = []
    for key in ("FIR1", "FIR2", "FIR3", "FIR4"):
        s = m[key]
        if abs(float(s.fs) - _WATER_FS_HZ) > 1.0:
            raise DataError(f"{path}: {key}.fs = {s.fs}, expected {_WATER_FS_HZ:g} Hz")
        blocks.append(np.atleast_2d(np.asarray(s.h, dtype=float)))
    return np.concatenate(blocks, axis=0)


def read_water_fir(folder: Path) -> dict[int, np.ndarray]:
    """Distance [mm] → measured impulse responses (20, 2000) at 5 MHz, from ``folder/charac/``."""
    return {d: _read_charac_mat(Path(folder) / "charac" / f"charac_water_{d}.mat") for d in WATER_DISTANCES_MM}


# ------------------------------------------------------------------------------------------ the table
def _vendored(name: str) -> Callable[[Path], dict[str, Record]]:
    def load(folder: Path) -> dict[str, Record]:
        return lab.read_vendored_folder(name, folder)

    return load


_LICENCES = {
    "silverbox": "LICENSE_pytorch-ident_repo.txt",
    "wiener-hammerstein": "LICENSE_sysid-neural-estimator_repo.txt",
    "cascaded-tanks": "LICENSE_sysid-neural-continuous_repo.txt",
    "bouc-wen": "LICENSE_dynonet_repo.txt",
    "piezo-tue": "LICENSE_from_initial_commit.txt",
}

# the scored benchmarks (``load_dataset``), in their registry order
SCORED_LAB: tuple[str, ...] = tuple(lab.LAB_SPECS)

LAB_DATA: dict[str, LabData] = {
    **{
        name: LabData(
            name, spec.folder, tuple(f"{stem}.npz" for stem in spec.records), _LICENCES[name], _vendored(name)
        )
        for name, spec in lab.LAB_SPECS.items()
    },
    "ultrasound-water-fir": LabData(
        "ultrasound-water-fir",
        "ultrasound_water_fir",
        tuple(f"charac/charac_water_{d}.mat" for d in WATER_DISTANCES_MM),
        "LICENSE.txt",
        read_water_fir,
    ),
}


def get(name: str) -> LabData:
    """The registry entry of lab dataset ``name``."""
    try:
        return LAB_DATA[name]
    except KeyError:
        raise ConfigError(f"unknown lab dataset {name!r}; valid: {', '.join(LAB_DATA)}") from None


def read(name: str, source: str | Path | None = None) -> Any:
    """Load lab dataset ``name`` (vendored copy, or the files in folder ``source``)."""
    return get(name).read(source)


def piezo_tue_record(source: str | Path | None = None) -> Record:
    """The measured TU/e piezo actuator record (u [V], y [µm], 5 kHz, 10 s) that the cantilever twin's lab
    configuration is calibrated and scored on."""
    (rec,) = read("piezo-tue", source).values()
    return rec


def water_fir(source: str | Path | None = None) -> dict[int, np.ndarray]:
    """The measured water-channel impulse responses, distance [mm] → (20, 2000) at 5 MHz."""
    return read("ultrasound-water-fir", source)
