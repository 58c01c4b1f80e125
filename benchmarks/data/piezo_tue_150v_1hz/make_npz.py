"""How ``piezo_tue_150v_1hz.npz`` was made from the original CSV (see SOURCE.txt). Re-run from the repo root:

    python benchmarks/data/piezo_tue_150v_1hz/make_npz.py /path/to/hysteresis_v_150_1hz.csv

The CSV has no header and 4 columns [empty index, time_s, displacement_um, voltage_V]. We take u = column 3
(voltage, V), y = column 2 (displacement, µm), fs = 5000 Hz (the time column steps by 0.2 ms ± 20 ns of
round-off, i.e. uniform). Every one of the 50 001 rows is kept, values unchanged (float64), nothing filtered.
The file is written with numpy.savez_compressed in the project's Record layout (u, y, fs, meta JSON), which
sysid.io.read_record and plain numpy.load(..., allow_pickle=False) read.
"""

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def main(csv_path: str) -> None:
    raw = Path(csv_path).read_bytes()
    data = np.genfromtxt(csv_path, delimiter=",")
    t, y, u = data[:, 1], data[:, 2], data[:, 3]
    dt = np.diff(t)
    assert np.all(np.abs(dt - 2e-4) < 1e-7), "time column is not uniform at 5 kHz"
    assert np.all(np.isfinite(u)) and np.all(np.isfinite(y))
    meta = {
        "name": "piezo_tue_150v_1hz",
        "description": "measured piezo actuator, 150 V 1 Hz sine after 3.26 s at 0 V, 10 s at 5 kHz (TU/e)",
        "origin": "github.com/chandratue/SmartHysteresis Data/hysteresis_v_150_1hz.csv @ e7672dab",
        "paper": "Chandra et al., Appl. Phys. Lett. 2023, doi:10.1063/5.0146134",
        "licence": "MIT (LICENSE_from_initial_commit.txt)",
        "csv_sha256": hashlib.sha256(raw).hexdigest(),
        "columns": {"u": "col 3 voltage [V]", "y": "col 2 displacement [um]"},
        "units": {"u": "V", "y": "um"},
    }
    np.savez_compressed(HERE / "piezo_tue_150v_1hz.npz", u=u, y=y, fs=np.float64(5000.0),
                        meta=np.array(json.dumps(meta)))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "../shared/data/piezo_tue_150v_1hz/hysteresis_v_150_1hz.csv")
