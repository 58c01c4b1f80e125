"""The acoustic twin against measured water-channel impulse responses (USbodyComm, vendored with its licence)."""

import hashlib

import pytest

from benchmarks.datasets import files
from sysid.errors import DataError
from twins.acoustic.labdata import compare, fit_transducer, load_charac, measured_decays


@pytest.fixture(scope="module")
def data():
    return files.water_fir()


@pytest.fixture(scope="module")
def fitted(data):
    params, summary = fit_transducer(40, data)  # the transducer is fitted at ONE distance
    return params, summary, compare(params, (20, 40, 80), data)


def test_vendored_data_is_intact_and_licensed(data):
    entry = files.get("ultrasound-water-fir")
    assert entry.licence_path().read_text().startswith("The data and photographs in this project are licensed")
    source = entry.source_path().read_text()
    for name, path in zip(entry.files, entry.paths()):
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        assert f"{digest}  {name}" in source
    assert sorted(data) == [1, 20, 40, 80]
    assert load_charac(20, data).shape == (20, 2000)
    with pytest.raises(DataError, match="no measured impulse responses"):
        load_charac(20, None)  # the twin package reads no files: the caller passes the measurement
    with pytest.raises(DataError, match="at 30 mm"):
        load_charac(30, data)


def test_fir_peak_amplitude_decay_with_distance_within_10_percent(fitted, data):
    _, _, cmp = fitted
    measured = measured_decays(data)["envelope_peak_mean"]
    for key in ("20_40", "40_80"):
        assert cmp["decay"][key]["measured"] == pytest.approx(measured[key], rel=1e-12)
        assert cmp["decay"][key]["twin"] == pytest.approx(cmp["decay"][key]["measured"], rel=0.10)
    # the data decay slower than spherical spreading (×0.5 per doubling) between 20 and 40 mm
    assert cmp["decay"]["20_40"]["measured"] > 0.55


def test_fir_magnitude_spectra_within_stated_tolerance(fitted):
    _, summary, cmp = fitted
    assert summary["rms_db"] < 3.0  # fit at 40 mm, 0.75-1.5 MHz
    for d in (20, 80):  # predictions at the other distances
        row = cmp["per_distance"][d]
        assert row["spectrum_rms_error_db"] < 3.0
        assert row["spectrum_max_abs_error_db"] < 8.0
        assert abs(row["spectrum_mean_error_db"]) < 1.0  # absolute level predicted from 40 mm
        assert row["peak_frequency_twin_hz"] == pytest.approx(row["peak_frequency_measured_hz"], rel=0.07)
