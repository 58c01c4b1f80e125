"""The vendored TU/e actuator record, the calibration of the twin to it, protocols and the CLI round trip."""

import hashlib
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from benchmarks.cli import main
from benchmarks.datasets import files
from sysid.data.io import read_record, write_record
from twins.cantilever import CantileverTwin
from twins.cantilever.lab import calibrate_lab, lab_split, load_lab_record, plot_lab_loops, static_line_r2


def test_vendored_record_matches_its_source():
    entry = files.get("piezo-tue")
    rec = files.piezo_tue_record()
    folder = entry.folder_path()
    src = entry.source_path().read_text()
    prov = (folder / "PROVENANCE.txt").read_text()
    assert entry.licence_path().read_text().startswith("MIT License")
    csv_sha = re.search(r"sha256\s*:\s*([0-9a-f]{64})", src).group(1)
    assert csv_sha in prov  # the npz was made from the CSV that SOURCE.txt describes
    assert f"u {hashlib.sha256(rec.u.tobytes()).hexdigest()}" in prov
    assert f"y {hashlib.sha256(rec.y.tobytes()).hexdigest()}" in prov
    assert len(rec) == 50_001 and rec.fs == 5000.0 and rec.units == {"u": "V", "y": "um"}
    assert rec.u.min() == -150.0 and rec.u.max() == 150.0
    assert 19.6 < rec.y.max() < 19.8 and -19.8 < rec.y.min() < -19.6


def test_vendored_record_equals_the_csv(shared_data):
    csv = shared_data / "piezo_tue_150v_1hz" / "hysteresis_v_150_1hz.csv"
    d = np.genfromtxt(csv, delimiter=",")
    rec = files.piezo_tue_record()
    assert np.array_equal(rec.u, d[:, 3]) and np.array_equal(rec.y, d[:, 2])


def test_lab_functions_take_the_record_from_the_caller():
    rec = files.piezo_tue_record()
    assert load_lab_record(rec) is rec
    from_file = load_lab_record(files.get("piezo-tue").paths()[0])  # or a Record file the caller names
    assert np.array_equal(from_file.u, rec.u) and np.array_equal(from_file.y, rec.y)
    with pytest.raises(TypeError):
        lab_split()  # the twin package does not know where the measurement is kept
    with pytest.raises(ValueError, match="measured record"):
        calibrate_lab()


def test_static_line_baseline_is_0977():
    est, val = lab_split(files.piezo_tue_record())
    assert static_line_r2(est, val) == pytest.approx(0.977, abs=0.001)


def test_calibration_short_segment_cli_round_trip(tmp_path, capsys):
    """Fast version of the lab check: 2 s around the first step → the next 1 s, through the CLI."""
    rec = files.piezo_tue_record()
    est, val = rec[15000:25000], rec[25000:30000]
    write_record(est, tmp_path / "est.npz")
    write_record(val, tmp_path / "val.npz")
    params = tmp_path / "p.json"
    code = main(
        [
            "calibrate",
            "cantilever",
            "--data",
            str(tmp_path / "est.npz"),
            "--val",
            str(tmp_path / "val.npz"),
            "--set",
            "amp_limit_v=150",
            "--effects",
            "creep",
            "--json",
            "-o",
            str(params),
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["parameters"]) == set(CantileverTwin.CALIBRATION_PARAMS)
    for v in out["parameters"].values():
        assert v["stderr"] is not None and np.isfinite(v["stderr"])
    assert out["scores"]["estimation"]["r2"] >= 0.995
    assert out["scores"]["validation"]["r2"] >= 0.995
    assert out["scores"]["validation"]["continuation"] is True
    assert out["scores"]["validation"]["nrmse"] == pytest.approx(
        np.sqrt(1 - out["scores"]["validation"]["r2"]), rel=1e-6
    )
    # the parameter file loads into generate and simulate
    tw = CantileverTwin.from_options(params_file=params)
    assert tw.params.gain_um_per_v == pytest.approx(out["parameters"]["gain_um_per_v"]["value"])
    assert (
        main(
            [
                "generate",
                "cantilever",
                "steps",
                "--params",
                str(params),
                "--option",
                "hold_s=1",
                "-o",
                str(tmp_path / "g.npz"),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "simulate",
                "cantilever",
                "--input",
                str(tmp_path / "val.npz"),
                "--params",
                str(params),
                "-o",
                str(tmp_path / "s.npz"),
            ]
        )
        == 0
    )
    assert len(read_record(tmp_path / "s.npz")) == len(val)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["bouc-wen", "prandtl-ishlinskii"])
def test_lab_first_5s_calibration_predicts_last_5s(model, tmp_path):
    """Calibrated on the first 5 s, free-run R² on the last 5 s ≥ 0.995 (a static line: 0.977)."""
    rec = files.piezo_tue_record()
    res = calibrate_lab(model, rec=rec)
    assert res.scores["validation"]["r2"] >= 0.995
    png = plot_lab_loops(res.twin, tmp_path / "lab.png", rec)
    assert png.stat().st_size > 10_000


# ---------------------------------------------------------------------------- protocols
def test_thesis_multisine_protocol():
    rec = CantileverTwin().generate("thesis-multisine")
    assert len(rec) == 80_000 and rec.fs == 10_000.0
    assert np.max(np.abs(rec.u)) == pytest.approx(100.0)
    assert rec.meta["components"] == 5000 and rec.meta["grid_hz"] == pytest.approx(0.1)
    U = np.abs(np.fft.rfft(rec.u)) ** 2
    f = np.fft.rfftfreq(len(rec), 1 / rec.fs)
    assert U[f > 520].sum() < 1e-3 * U[f <= 500].sum()  # band-limited to 500 Hz (8 s of a 10 s period)
    assert rec.units == {"u": "V", "y": "um"} and rec.meta["protocol"] == "thesis-multisine"


def test_thesis_sines_protocol_segments():
    rec = CantileverTwin().generate("thesis-sines")
    segs = rec.meta["segments"]
    assert [s["freq_hz"] for s in segs] == [0.1, 1, 10, 50, 100, 150, 200, 250, 300, 400, 450, 500]
    assert segs[0]["start"] == 0 and segs[-1]["stop"] == len(rec)
    for s in segs:
        n = s["stop"] - s["start"]
        assert n == round(s["periods"] * rec.fs / s["freq_hz"])
        seg = rec.u[s["start"] : s["stop"]]
        k = np.argmax(np.abs(np.fft.rfft(seg)))
        assert k / n * rec.fs == pytest.approx(s["freq_hz"], rel=1e-6)
    assert segs[0]["stop"] == 100_000  # 0.1 Hz: one whole period (10 s)


def test_steps_protocol_and_cli_generate(tmp_path):
    rec = CantileverTwin().generate("steps", hold_s=2)
    assert rec.fs == 1000.0 and len(rec) == 10_000
    assert set(np.unique(rec.u)) == {-80.0, 0.0, 80.0}
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks.cli", "generate", "cantilever", "nosuch", "-o", str(tmp_path / "x.npz")],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and "thesis-multisine" in proc.stderr and "Traceback" not in proc.stderr
    with pytest.raises(Exception, match="unknown option"):
        CantileverTwin().generate("steps", bogus=1)


def test_local_multisine_fallback_lines_exact():
    from twins.cantilever.protocols import multisine_local

    x = multisine_local(1000.0, 2.0, 50, 20.0, seed=3)
    X = np.abs(np.fft.rfft(x))
    k = np.flatnonzero(X > 1e-9 * X.max())
    assert list(k) == list(range(1, 41))  # 0.5 Hz grid, lines 1…40 (≤ 20 Hz), equal amplitudes
    assert np.ptp(X[k]) < 1e-9 * X.max() and np.max(np.abs(x)) == pytest.approx(1.0)


def test_calibration_recovers_known_parameters_from_noisy_twin_data():
    """1 s of the thesis multisine from a twin with changed parameters (noise + quantiser on): the fit from the
    default start recovers every parameter to 1 % (f₁ lies outside the 500 Hz band and is still found)."""
    truth = CantileverTwin(seed=5).with_params(
        gain_um_per_v=0.35,
        bw_alpha=0.25,
        bw_beta=0.012,
        bw_gamma=0.005,
        f1_hz=650.0,
        zeta1=0.03,
        creep_per_decade=0.02,
        offset_um=0.5,
    )
    rec = truth.generate("thesis-multisine", duration_s=1.0)
    res = CantileverTwin().calibrate(rec)
    assert res.scores["estimation"]["r2"] > 0.9999
    for k, v in res.fitted.items():
        true = getattr(truth.params, k)
        if true == 0.0:
            assert abs(v) < 0.01, k
        else:
            assert v == pytest.approx(true, rel=0.01), k
    assert res.twin.effects == CantileverTwin.default_effects()


def test_calibration_refuses_settings_that_are_not_continuous():
    rec = files.piezo_tue_record()[16000:17000]
    for name in ("hysteresis", "pi_operators"):
        with pytest.raises(Exception, match="not a continuous parameter"):
            CantileverTwin().calibrate(rec, names=[name])
