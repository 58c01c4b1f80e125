"""CLI `piezotwin signal` and `piezotwin preprocess`: records written, steps in command-line order, bad values
exit 2."""

import json
import subprocess
import sys

import numpy as np
import pytest

from benchmarks.cli import main
from sysid.data.io import read_record, write_record
from sysid.data.record import Record
from sysid.signals import excitation as S
from sysid.signals import preprocess as P


def run_cli(args, capsys):
    try:
        code = main([str(a) for a in args])
    except SystemExit as e:
        code = e.code
    out = capsys.readouterr()
    return code, out.out, out.err


def test_signal_multisine_writes_input_only_record(tmp_path, capsys):
    f = tmp_path / "ms.npz"
    code, out, err = run_cli(
        [
            "signal",
            "multisine",
            "--fs",
            1000,
            "--duration",
            2,
            "--band",
            "10:100",
            "--components",
            20,
            "--amplitude",
            3,
            "--phase",
            "schroeder",
            "--grid",
            "odd",
            "--periods",
            2,
            "-o",
            f,
        ],
        capsys,
    )
    assert code == 0, err
    rec = read_record(f)
    assert rec.y is None and rec.fs == 1000 and len(rec) == 2000
    ref = S.multisine(
        1000, duration=2, band=(10, 100), components=20, amplitude=3, phase="schroeder", grid="odd", periods=2
    )
    np.testing.assert_array_equal(rec.u, ref)
    sig = rec.meta["signal"]
    assert sig["kind"] == "multisine" and sig["info"]["n_components"] == 20
    assert all(b % 2 == 1 for b in sig["info"]["excited_bins"])
    with np.load(f, allow_pickle=False) as z:  # plain numpy can read it
        assert json.loads(str(z["meta"]))["signal"]["crest_factor"] == pytest.approx(S.crest_factor(ref))


def test_signal_rms_and_other_kinds(tmp_path, capsys):
    f = tmp_path / "s.npz"
    assert (
        run_cli(
            ["signal", "sine", "--fs", 1000, "--duration", 1, "--freq", 50, "--amplitude", 2, "--rms", "-o", f], capsys
        )[0]
        == 0
    )
    u = read_record(f).u
    assert np.sqrt(np.mean(u**2)) == pytest.approx(2.0) and np.max(np.abs(u)) == pytest.approx(2 * np.sqrt(2))
    assert (
        run_cli(["signal", "chirp", "--fs", 1e5, "--duration", 0.01, "--band", "1000:20000", "-o", f], capsys)[0] == 0
    )
    np.testing.assert_array_equal(read_record(f).u, S.chirp(1e5, 0.01, 1000, 20000))
    assert run_cli(["signal", "prbs", "--fs", 100, "--order", 6, "-o", f], capsys)[0] == 0
    assert len(read_record(f)) == 63
    assert (
        run_cli(["signal", "stepped-sine", "--fs", 1000, "--freqs", "5,10", "--settle", 0.1, "-o", f], capsys)[0] == 0
    )
    rec = read_record(f)
    assert [s["freq_hz"] for s in rec.meta["segments"]] == [5.0, 10.0]
    assert run_cli(["signal", "thesis-cantilever", "-o", f], capsys)[0] == 0
    np.testing.assert_array_equal(read_record(f).u, S.thesis_cantilever_multisine(seed=0))


@pytest.mark.parametrize(
    "args",
    [
        ["signal", "multisine", "--fs", 1000, "--duration", 1, "--band", "300:200"],  # fmin >= fmax
        ["signal", "multisine", "--fs", 1000, "--duration", 1, "--band", "10:600"],  # above Nyquist
        ["signal", "multisine", "--fs", 1000, "--duration", 1, "--band", "10:20", "--components", 50],  # does not fit
        ["signal", "multisine", "--fs", 1000, "--duration", 1, "--band", "ten:20"],  # not a number
        ["signal", "multisine", "--fs", -5, "--duration", 1],  # fs <= 0
        ["signal", "multisine", "--fs", 1000],  # no duration
        ["signal", "multisine", "--fs", 1000, "--duration", 1, "--phase", "zigzag"],  # argparse choice
        ["signal", "chirp", "--fs", 1000, "--duration", 1],  # no band
        ["signal", "sine", "--fs", 1000, "--duration", 1, "--freq", 800],  # above Nyquist
        ["signal", "thesis-chirp", "--duration", 0.5],
        ["signal", "multisine", "--fs", 1000, "--duration", 1, "--amplitude", 0],
    ],
)
def test_signal_errors_exit_2_one_line(args, tmp_path, capsys):
    code, out, err = run_cli(args + ["-o", tmp_path / "x.npz"], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err
    assert not (tmp_path / "x.npz").exists()


@pytest.fixture
def noisy_record(tmp_path):
    rng = np.random.default_rng(0)
    n = 6000
    u = np.sin(2 * np.pi * np.arange(n) / 600) + 0.2
    y = 0.5 * u + 0.01 * rng.standard_normal(n) + np.linspace(0, 1, n)
    y[777] = 40.0
    path = tmp_path / "in.npz"
    write_record(Record(u=u, y=y, fs=6000.0), path)
    return path, u, y


def test_preprocess_steps_in_command_line_order(noisy_record, tmp_path, capsys):
    path, u, y = noisy_record
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    assert run_cli(["preprocess", path, "--decimate", 3, "--moving-average", 5, "-o", a], capsys)[0] == 0
    assert run_cli(["preprocess", path, "--moving-average", 5, "--decimate", 3, "-o", b], capsys)[0] == 0
    ra, rb = read_record(a), read_record(b)
    assert [e["step"] for e in ra.meta["preprocessing"]] == ["decimate", "moving_average"]
    assert [e["step"] for e in rb.meta["preprocessing"]] == ["moving_average", "decimate"]
    np.testing.assert_allclose(ra.y, P.moving_average(P.decimate(y, 3), 5), atol=1e-12)
    np.testing.assert_allclose(rb.y, P.decimate(P.moving_average(y, 5), 3), atol=1e-12)
    assert ra.fs == rb.fs == 2000.0


def test_preprocess_outliers_detrend_bandpass_suggest_json(noisy_record, tmp_path, capsys):
    path, u, y = noisy_record
    o = tmp_path / "o.npz"
    code, out, err = run_cli(
        [
            "preprocess",
            path,
            "--outliers",
            "20:8",
            "--detrend",
            "--bandpass",
            "2:100",
            "--suggest-rate",
            "--json",
            "-o",
            o,
        ],
        capsys,
    )
    assert code == 0, err
    rep = json.loads(out)
    assert [s["step"] for s in rep["steps"]] == ["hampel", "detrend", "bandpass", "suggest_rate"]
    assert [c["index"] for c in rep["steps"][0]["changes"]["replaced"]["y"]] == [777]
    assert rep["steps"][0]["changes"]["n_replaced"] == {"u": 0, "y": 1}
    assert rep["steps"][3]["changes"]["factor"] >= 1
    assert read_record(o).meta["preprocessing"] == rep["steps"]


def test_preprocess_fill_missing_is_recorded_first(tmp_path, capsys):
    p = tmp_path / "gap.csv"
    p.write_text("t,u,y\n" + "".join(f"{k / 100},{k},{'' if k == 5 else 2 * k}\n" for k in range(40)))
    o = tmp_path / "o.npz"
    code, out, err = run_cli(["preprocess", p, "--remove-offset", "--fill-missing", "-o", o], capsys)
    assert code == 0, err
    log = read_record(o).meta["preprocessing"]
    assert [e["step"] for e in log] == ["fill_missing", "remove_offset"]
    assert log[0]["changes"]["filled_indices"] == {"y": [5]}


@pytest.mark.parametrize(
    "steps",
    [
        ["--decimate", "0"],
        ["--decimate", "1.5"],
        ["--bandpass", "100:50"],
        ["--bandpass", "10:4000"],
        ["--moving-average", "-3"],
        ["--resample", "abc"],
        ["--outliers", "a:b"],
        ["--segment", "10:10"],
        [],
    ],
)
def test_preprocess_errors_exit_2_one_line(steps, noisy_record, tmp_path, capsys):
    path, _, _ = noisy_record
    code, out, err = run_cli(["preprocess", path, *steps, "-o", tmp_path / "x.npz"], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_preprocess_subprocess_one_line(tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "benchmarks.cli",
            "preprocess",
            str(tmp_path / "missing.npz"),
            "--detrend",
            "-o",
            str(tmp_path / "o.npz"),
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "not found" in proc.stderr
