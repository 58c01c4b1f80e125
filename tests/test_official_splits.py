"""Every records split against the official dataloader, ``nonlinear-benchmarks`` 1.0.1 (the package behind the
published SUBNET / nonlinearbenchmark.org numbers).

Nothing is downloaded: the loader's download helper and its ``loadmat`` are replaced by fakes whose "signals" are
the sample indices of the original files, so the records the loader returns name the exact sample ranges and the
initialisation windows (``state_initialization_window_length``) that its code defines.
"""

from __future__ import annotations

from importlib.metadata import version

import numpy as np
import pytest

from benchmarks.datasets import lab, load_dataset

benchmarks = pytest.importorskip("nonlinear_benchmarks.benchmarks")  # the test extra installs it
assert version("nonlinear-benchmarks") == "1.0.1", "the splits below are those of nonlinear-benchmarks 1.0.1"

# Original files as index signals: Silverbox SNLS80mV (131072 samples, row vectors), the WH 2009 record (188000,
# column), cascaded tanks uEst/uVal (1024 each; the validation record's indices offset by VAL so the two records
# stay apart).
VAL = 1_000_000
FILES = {
    "SNLS80mV.mat": {"V1": np.arange(131072.0)[None, :], "V2": np.arange(131072.0)[None, :]},
    "WienerHammerBenchMark.mat": {
        "uBenchMark": np.arange(188000.0)[:, None],
        "yBenchMark": np.arange(188000.0)[:, None],
        "fs": np.array([[lab.WH_FS_HZ]]),
    },
    "dataBenchmark.mat": {
        "uEst": np.arange(1024.0)[:, None],
        "yEst": np.arange(1024.0)[:, None],
        "uVal": VAL + np.arange(1024.0)[:, None],
        "yVal": VAL + np.arange(1024.0)[:, None],
        "Ts": np.array([[lab.CASCADED_TANKS_TS_S]]),
    },
}


@pytest.fixture
def official(monkeypatch, tmp_path):
    """The loader's functions, reading the index files above instead of downloading."""
    monkeypatch.setattr(benchmarks, "cashed_download", lambda *a, **k: str(tmp_path))
    monkeypatch.setattr(benchmarks, "loadmat", lambda path: FILES[str(path).replace("\\", "/").rsplit("/", 1)[-1]])
    return benchmarks


def _range(data) -> tuple[str, int, int]:
    """(record, start, stop) of a loader record made of index signals; checks it is contiguous."""
    idx = np.asarray(data.u, dtype=float).reshape(-1)
    assert np.array_equal(idx, idx[0] + np.arange(idx.size)), "not a contiguous slice"
    record = "val" if idx[0] >= VAL else "raw"
    off = VAL if record == "val" else 0
    return record, int(idx[0]) - off, int(idx[-1]) + 1 - off


def _ours(name: str, test: str | None) -> tuple[int, int]:
    split = lab.SPLITS[name]
    _, a, b = split["est"] if test is None else split["tests"][test]
    return a, b


def test_silverbox_matches_the_official_split(official):
    train, (multisine, arrow, arrow_no_ex) = official.Silverbox()
    assert _range(train)[1:] == _ours("silverbox", None)
    ds = load_dataset("silverbox")
    for test, data in (("multisine", multisine), ("arrow", arrow), ("arrow-no-extrapolation", arrow_no_ex)):
        assert _range(data)[1:] == _ours("silverbox", test), test
        assert ds.init_for(test) == data.state_initialization_window_length == 50


def test_wiener_hammerstein_official_test_set(official):
    """The official test [105200, 184000) with 50 samples of initialisation is ``test-official``; the 2009 call's
    [100000, 188000) stays as ``test``. The estimation part [0, 100000) never reaches the official test."""
    train, test = official.WienerHammerBenchMark()
    assert _range(test)[1:] == (105200, 184000) == _ours("wiener-hammerstein", "test-official")
    assert _range(train)[1:] == (5200, 105200)
    ds = load_dataset("wiener-hammerstein")
    assert ds.init_for("test-official") == test.state_initialization_window_length == 50
    assert _ours("wiener-hammerstein", None)[1] <= _range(test)[1]  # no estimation sample in the official test
    assert _ours("wiener-hammerstein", "test") == (100000, 188000) and ds.init_for("test") == 50
    raw = lab.read_vendored("wiener-hammerstein")["WienerHammerBenchmark"]
    np.testing.assert_array_equal(ds.tests["test-official"].y, raw.y[105200:184000])


def test_cascaded_tanks_official_window(official):
    """Same records (uEst/yEst estimation, uVal/yVal test); the official window is 50 samples (``test-official``),
    the benchmark description's 4 stay on ``test``."""
    train, test = official.Cascaded_Tanks()
    assert _range(train) == ("raw", 0, 1024) and _ours("cascaded-tanks", None) == (0, 1024)
    assert _range(test) == ("val", 0, 1024)
    assert lab.SPLITS["cascaded-tanks"]["tests"]["test-official"] == ("val", 0, 1024)
    ds = load_dataset("cascaded-tanks")
    assert ds.init_for("test-official") == test.state_initialization_window_length == 50
    assert ds.init_for("test") == ds.init_samples == 4
    np.testing.assert_array_equal(ds.tests["test-official"].y, ds.tests["test"].y)


def test_every_records_dataset_with_an_official_loader_is_checked():
    """The lab datasets the official package splits are the three above; Bouc-Wen has no official split there
    (the package returns the two validation records only) and piezo-tue is not in it."""
    import nonlinear_benchmarks

    names = {f.__name__ for f in nonlinear_benchmarks.all_splitted_benchmarks}
    assert {"Silverbox", "WienerHammerBenchMark", "Cascaded_Tanks"} <= names
    assert "BoucWen" not in names
