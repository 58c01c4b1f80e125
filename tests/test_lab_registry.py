"""Lab data are found through one registry (dataset id → files, licence, source note, loader) in the benchmark
package, and handed down as records and arrays: the twin and sysid packages build no path into it."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from benchmarks.datasets import files, lab
from sysid.errors import ConfigError, DataError

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", list(files.LAB_DATA))
def test_every_entry_has_its_files_licence_and_source(name):
    entry = files.get(name)
    assert entry.id == name and entry.files
    for path in entry.paths():
        assert path.is_file() and path.stat().st_size > 0, path
    assert entry.licence_path().read_text().strip(), "licence file empty"
    assert entry.source_path().read_text().strip(), "SOURCE.txt empty"


def test_scored_entries_load_the_records_load_dataset_scores():
    assert files.SCORED_LAB == tuple(lab.LAB_SPECS)
    rec = files.piezo_tue_record()
    raw = lab.read_vendored("piezo-tue")["hysteresis_v_150_1hz"]
    assert np.array_equal(rec.u, raw.u) and np.array_equal(rec.y, raw.y) and rec.fs == raw.fs == 5000.0


def test_source_folder_and_unknown_names(tmp_path):
    with pytest.raises(ConfigError, match="unknown lab dataset"):
        files.get("nosuch")
    with pytest.raises(DataError, match="not a folder"):
        files.read("ultrasound-water-fir", source=tmp_path / "missing")
    with pytest.raises(DataError, match="not found"):
        files.read("ultrasound-water-fir", source=tmp_path)  # a folder without the published files


# a path built into the benchmark package: Path(...)/"benchmarks", "benchmarks/data", parents[n]/"benchmarks"
_UPWARD_PATH = re.compile(r"""["']benchmarks["']\s*/|/\s*["']benchmarks["']|["']benchmarks/data""")


def test_lower_packages_build_no_path_into_the_benchmark_data():
    offenders = [
        f"{p.relative_to(ROOT)}:{i}"
        for pkg in ("sysid", "twins")
        for p in sorted((ROOT / pkg).rglob("*.py"))
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if _UPWARD_PATH.search(line)
    ]
    assert offenders == []
