"""Bad input on the CLI: exit status 2 and exactly one line on stderr that names the problem (and the file),
never a traceback, never silently dropped or altered data (one line naming the file and the problem, exit 2).

The table runs ``benchmarks.cli.main`` in-process (fast); a few cases run ``python -m benchmarks.cli`` in a
subprocess to prove that no traceback or warning reaches a real stderr.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.io import savemat

from benchmarks.cli import main
from sysid.data.io import read_record
from sysid.errors import DataError

FS = 1000.0
N = 400


@pytest.fixture(scope="module")
def d(tmp_path_factory) -> Path:
    """A folder of good and bad data files (small)."""
    from sysid.data.io import write_record
    from sysid.data.record import Record
    from twins.registry import get_twin

    p = tmp_path_factory.mktemp("bad_input")
    rng = np.random.default_rng(0)
    u = rng.standard_normal(N)
    y = np.convolve(u, [0.0, 0.5, 0.3])[:N]
    t = np.arange(N) / FS
    np.savez(p / "good.npz", u=u, y=y, fs=FS)
    np.savez(p / "uonly.npz", u=u, fs=FS)
    np.savez(p / "nofs.npz", u=u, y=y)
    np.savez(p / "fs0.npz", u=u, y=y, fs=0.0)
    np.savez(p / "unequal.npz", u=u, y=y[:-3], fs=FS)
    ui = u.copy()
    ui[7] = np.inf
    np.savez(p / "inf.npz", u=ui, y=y, fs=FS)
    np.savez(p / "mimo.npz", u=np.column_stack([u, u[::-1]]), y=np.column_stack([y, y]), fs=FS)
    np.savez(p / "const.npz", u=np.ones(N), y=np.ones(N), fs=FS)
    np.savez(p / "one.npz", u=u[:1], y=y[:1], fs=FS)
    np.savez(p / "zeros.npz", u=np.zeros(N), y=np.zeros(N), fs=FS)
    np.savez(p / "metalist.npz", u=u, y=y, fs=FS, meta=np.array("[1, 2]"))
    np.savez(p / "ucomplex.npz", u=u + 1j * u, y=y, fs=FS)
    (p / "trunc.npz").write_bytes((p / "good.npz").read_bytes()[:300])
    savemat(p / "good.mat", {"u": u, "y": y, "fs": FS})
    savemat(p / "ustr.mat", {"u": "hello", "y": y, "fs": FS})
    savemat(p / "fsvec.mat", {"u": u, "y": y, "fs": np.array([1.0, 2.0])})
    (p / "garbage.mat").write_bytes(b"not a MAT file at all " * 10)
    t, u, y = t.tolist(), u.tolist(), y.tolist()  # Python floats: repr is the shortest round-tripping text
    (p / "good.csv").write_text("t,u,y\n" + "".join(f"{a!r},{b!r},{c!r}\n" for a, b, c in zip(t, u, y)))
    (p / "nan.csv").write_text(
        "t,u,y\n" + "".join(f"{a!r},{'' if i == 5 else repr(b)},{c!r}\n" for i, (a, b, c) in enumerate(zip(t, u, y)))
    )
    (p / "header.csv").write_text("t,u,y\n")
    (p / "nonnum.csv").write_text("t,u,y\n0,1,2\n0.001,abc,3\n0.002,1,2\n")
    (p / "dup.csv").write_text("t,u,u\n0,1,2\n0.001,1,3\n0.002,1,2\n")
    (p / "empty.csv").write_text("")
    (p / "x.txt").write_text("1,2\n")
    (p / "adir.npz").mkdir()
    (p / "notjson.json").write_text("{{{")
    fs_c = 1000.0
    uc = 50 * np.sin(2 * np.pi * 5 * np.arange(500) / fs_c)
    yc = get_twin("cantilever")().simulate(uc, fs_c)
    write_record(Record(uc, yc, fs_c), p / "cant.npz")
    write_record(Record(uc, None, fs_c), p / "cant_u.npz")
    write_record(Record(np.column_stack([uc, uc]), np.column_stack([yc, yc]), fs_c), p / "cant_mimo.npz")
    return p


SIG = ["signal", "multisine", "--fs", "1000", "--duration", "1"]
PRE = ["preprocess", "{d}/good.npz"]
SIM = ["simulate", "cantilever", "--input", "{d}/cant_u.npz", "-o", "{d}/out/sim.npz"]
CAL = ["calibrate", "cantilever", "--data", "{d}/cant.npz"]
IDF = ["identify", "arx", "--est", "{d}/good.npz"]
OUT = ["-o", "{d}/out/x.npz"]

# (argv, expected substring of the one-line message); "{d}" is the data folder
CASES = [
    # list
    (["list", "nothing"], "invalid choice: 'nothing'"),
    # signal
    (SIG[:3] + ["0"] + SIG[4:] + OUT, "fs must be positive"),
    (SIG + ["--band", "300:100"] + OUT, "fmin (300 Hz) must be below fmax (100 Hz)"),
    (SIG + ["--band", "100:900"] + OUT, "Nyquist"),
    (SIG + ["--seed", "-1"] + OUT, "seed must be a non-negative integer"),
    (SIG + ["-o", "{d}/out/s.xyz"], "unknown format '.xyz'"),
    (SIG + ["-o", "{d}/adir.npz"], "adir.npz: is a directory"),
    (SIG + ["-o", "{d}/good.csv/s.npz"], "good.csv is a file, not a folder"),
    # preprocess: files
    (["preprocess", "{d}/missing.npz", "--remove-offset"] + OUT, "missing.npz: file not found"),
    (["preprocess", "{d}/adir.npz", "--remove-offset"] + OUT, "adir.npz: is a directory"),
    (["preprocess", "{d}/x.txt", "--remove-offset"] + OUT, "x.txt: unknown format '.txt'"),
    (["preprocess", "{d}/empty.csv", "--remove-offset"] + OUT, "empty.csv: file is empty"),
    (["preprocess", "{d}/header.csv", "--remove-offset"] + OUT, "header.csv: file has a header but no data rows"),
    (["preprocess", "{d}/nonnum.csv", "--remove-offset"] + OUT, "column 'u' row 3 is not a number: 'abc'"),
    (
        ["preprocess", "{d}/nan.csv", "--remove-offset"] + OUT,
        "nan.csv: u has 1 non-finite (NaN) samples, first at index 5",
    ),
    (["preprocess", "{d}/inf.npz", "--fill-missing"] + OUT, "inf.npz: u has infinite samples"),
    (["preprocess", "{d}/unequal.npz", "--remove-offset"] + OUT, "unequal lengths (400 and 397 samples)"),
    (["preprocess", "{d}/nofs.npz", "--remove-offset"] + OUT, "nofs.npz: no sampling rate in the file"),
    (["preprocess", "{d}/fs0.npz", "--remove-offset"] + OUT, "fs0.npz: sampling rate fs must be positive"),
    (PRE + ["--fs", "-1", "--remove-offset"] + OUT, "sampling rate fs must be positive and finite, got -1"),
    (
        ["preprocess", "{d}/good.csv", "--fs", "500", "--remove-offset"] + OUT,
        "contradicts the file's own sampling rate",
    ),
    (
        ["preprocess", "{d}/good.npz", "--fs", "999", "--remove-offset"] + OUT,
        "contradicts the file's own sampling rate",
    ),
    (["preprocess", "{d}/good.csv", "--u-col", "volts", "--remove-offset"] + OUT, "missing column 'volts' for u"),
    (["preprocess", "{d}/good.mat", "--y-var", "out", "--remove-offset"] + OUT, "missing variable 'out' for y"),
    (["preprocess", "{d}/trunc.npz", "--remove-offset"] + OUT, "trunc.npz: not a readable .npz file"),
    (["preprocess", "{d}/garbage.mat", "--remove-offset"] + OUT, "garbage.mat: not a readable .mat file"),
    (["preprocess", "{d}/metalist.npz", "--remove-offset"] + OUT, "'meta' must be a JSON object"),
    (["preprocess", "{d}/ucomplex.npz", "--remove-offset"] + OUT, "u has complex samples"),
    (["preprocess", "{d}/ustr.mat", "--remove-offset"] + OUT, "variable 'u' is not numeric"),
    (["preprocess", "{d}/fsvec.mat", "--remove-offset"] + OUT, "fs must be a single number"),
    (["preprocess", "{d}/dup.csv", "--remove-offset"] + OUT, "column 'u' appears 2 times in the header"),
    # preprocess: steps and output
    (PRE + ["--bandpass", "300:100"] + OUT, "fmin (300 Hz) must be below fmax (100 Hz)"),
    (PRE + ["--bandpass", "100:600"] + OUT, "Nyquist frequency fs/2 = 500 Hz"),
    (PRE + ["--outliers", "1000"] + OUT, "must be smaller than the signal length 400"),
    (PRE + ["--resample", "1e12"] + OUT, "not a ratio of integers"),
    (PRE + ["--decimate", "abc"] + OUT, "--decimate expects a number"),
    (PRE, "the following arguments are required: -o/--output"),
    (PRE + ["--remove-offset", "-o", "{d}/adir.npz"], "adir.npz: is a directory"),
    (PRE + ["--remove-offset", "-o", "{d}/out/p.h5"], "unknown format '.h5'"),
    # simulate / generate
    (["simulate", "nosuch", "--input", "{d}/cant_u.npz", "-o", "{d}/out/s.npz"], "unknown twin 'nosuch'"),
    (["simulate", "cantilever", "--input", "{d}/cant_mimo.npz", "-o", "{d}/out/s.npz"], "u must be 1-D"),
    (SIM + ["--set", "nosuch=1"], "unknown parameter 'nosuch' for twin cantilever"),
    (SIM + ["--set", "gain_um_per_v=abc"], "gain_um_per_v: expected float, got 'abc'"),
    (SIM + ["--set", "gain_um_per_v=99"], "gain_um_per_v=99.0 out of range [0.02, 1.5]"),
    (SIM + ["--set", "gain_um_per_v=nan"], "gain_um_per_v is NaN"),
    (SIM + ["--set", "creep_elements=2.5"], "creep_elements: expected int"),
    (SIM + ["--effect", "nosuch"], "unknown effect 'nosuch'"),
    (SIM + ["--effect", "input_delay:badkey=1"], "effect input_delay has no parameter 'badkey'"),
    (SIM + ["--effect", "input_delay:delay=1"], "input_delay_s=1.0 out of range"),
    (SIM + ["--params", "{d}/notjson.json"], "notjson.json: not a JSON parameter file"),
    (SIM + ["--params", "{d}/adir.npz"], "adir.npz: is a directory, expected a parameter file"),
    (SIM + ["--seed", "-1"], "seed must be a non-negative integer, got -1"),
    (["generate", "cantilever", "nosuch", "-o", "{d}/out/g.npz"], "unknown protocol 'nosuch'"),
    (["generate", "cantilever", "steps", "--option", "foo=1", "-o", "{d}/out/g.npz"], "unknown option(s) foo"),
    (["generate", "cantilever", "steps", "--option", "fs=nan", "-o", "{d}/out/g.npz"], "fs: must be finite"),
    (
        ["generate", "cantilever", "thesis-sines", "--option", "freqs_hz=abc", "-o", "{d}/out/g.npz"],
        "freqs_hz: expected frequencies in Hz",
    ),
    (["generate", "acoustic", "thesis-chirp-1ms", "--option", "keep=5", "-o", "{d}/out/g.npz"], "give preprocess=true"),
    # calibrate
    (["calibrate", "cantilever", "--data", "{d}/cant_u.npz"], "cant_u.npz: missing output"),
    (["calibrate", "cantilever", "--data", "{d}/cant_mimo.npz"], "data must be SISO"),
    (["calibrate", "acoustic", "--data", "{d}/cant_mimo.npz"], "data must be SISO"),
    (CAL + ["--fit", "nosuch"], "cannot fit unknown parameter 'nosuch'"),
    (CAL + ["--fit", ","], "no parameters to fit"),
    (["calibrate", "cantilever", "--data", "{d}/one.npz", "--fit", "gain_um_per_v"], "1 samples are too few to fit 1"),
    (["calibrate", "cantilever", "--data", "{d}/zeros.npz", "--fit", "gain_um_per_v"], "output y is constant"),
    (CAL + ["--fit", "gain_um_per_v", "-o", "{d}/good.csv/p.json"], "good.csv is a file, not a folder"),
    # identify
    (["identify", "nosuch", "--est", "{d}/good.npz"], "unknown identifier 'nosuch'"),
    (["identify", "arx", "--est", "{d}/uonly.npz"], "uonly.npz: missing output"),
    (IDF + ["--val", "{d}/uonly.npz"], "uonly.npz: missing output"),
    (IDF + ["--set", "foo=1"], "unknown arx option 'foo'"),
    (IDF + ["--set", "ny=abc"], "ny: expected int, got 'abc'"),
    (IDF + ["--set", "ny=-1"], "ny must be a non-negative integer"),
    (IDF + ["--set", "ny=1000"], "too few for the lags of arx"),
    (IDF + ["--set", "ny=100000000"], "regressors (limit"),
    (["identify", "narx-poly", "--est", "{d}/good.npz", "--set", "degree=0"], "degree must be an integer >= 1"),
    (["identify", "narx-poly", "--est", "{d}/good.npz", "--set", "degree=50"], "candidate terms (limit"),
    (["identify", "narx-poly", "--est", "{d}/good.npz", "--set", "criterion=foo"], "criterion 'foo' unknown"),
    (["identify", "arx", "--est", "{d}/const.npz"], "input u is constant"),
    (["identify", "arx", "--est", "{d}/one.npz"], "1 samples are too few for the lags"),
    (IDF + ["--val", "{d}/mimo.npz"], "2 inputs / 2 outputs"),
    (IDF + ["-o", "{d}/adir.npz"], "adir.npz: is a directory"),
    (IDF + ["--plots", "{d}/good.csv"], "good.csv"),
    # sweep
    (["sweep", "cantilever", "gain_um_per_v=0.3"], "defines no sweep metrics"),
    (["sweep", "acoustic", "distance_m"], "expected PARAM=v1,v2"),
    (["sweep", "acoustic", "nosuch=1,2"], "unknown parameter 'nosuch'"),
    (["sweep", "acoustic", "distance_m=,"], "no values given for distance_m"),
    (["sweep", "acoustic", "distance_m=abc"], "distance_m: expected float"),
    (["sweep", "acoustic", "distance_m=nan", "--no-identify"], "distance_m is NaN"),
    (["sweep", "acoustic", "distance_m=-1", "--no-identify"], "distance_m=-1.0 out of range"),
    (["sweep", "acoustic", "fluid=mercury", "--no-identify"], "fluid='mercury' not one of"),
    (["sweep", "acoustic", "distance_m=0.1", "--protocol", "nosuch", "--no-identify"], "unknown protocol 'nosuch'"),
]


def _argv(argv, d):
    return [a.replace("{d}", str(d)) for a in argv]


@pytest.mark.parametrize("argv,expected", CASES, ids=[f"{a[0]}: {e[:48]}" for a, e in CASES])
def test_bad_input_one_line_exit_2(argv, expected, d, capsys):
    try:
        code = main(_argv(argv, d))
    except SystemExit as e:  # argparse errors
        code = e.code
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1, err
    assert "Traceback" not in err
    assert expected in lines[0], lines[0]


@pytest.mark.parametrize(
    "argv,expected",
    [
        (
            ["preprocess", "{d}/trunc.npz", "--remove-offset", "-o", "{d}/out/t.npz"],
            "trunc.npz: not a readable .npz file",
        ),
        (["identify", "narx-poly", "--est", "{d}/good.npz", "--set", "degree=50"], "candidate terms"),
        (["calibrate", "acoustic", "--data", "{d}/cant_mimo.npz"], "data must be SISO"),
    ],
)
def test_subprocess_stderr_is_one_line(argv, expected, d):
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run(
        [sys.executable, "-m", "benchmarks.cli", *_argv(argv, d)],
        capture_output=True,
        text=True,
        cwd=root,
        env={**os.environ, "PYTHONPATH": str(root)},
        timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], proc.stderr  # no traceback, no warning lines


# ------------------------------------------------------------------ nothing altered silently
def test_explicit_fs_that_agrees_is_used(d):
    """--fs may restate the file's rate (the t column within its 1 % tolerance); the explicit value is used."""
    assert read_record(d / "good.csv", fs=1000.0).fs == 1000.0
    assert read_record(d / "good.csv", fs=1005.0).fs == 1005.0
    assert read_record(d / "good.npz", fs=1000.0).fs == 1000.0
    with pytest.raises(DataError, match="contradicts"):
        read_record(d / "good.npz", fs=1000.5)


def test_fill_missing_records_what_it_filled(d, capsys):
    out = d / "out" / "filled.npz"
    assert main(["preprocess", str(d / "nan.csv"), "--fill-missing", "-o", str(out)]) == 0
    rec = read_record(out)
    assert rec.meta["preprocessing"][0]["filled_indices"] == {"u": [5]}
    src = read_record(d / "good.csv")
    assert np.isfinite(rec.u).all() and np.array_equal(np.delete(rec.u, 5), np.delete(src.u, 5))


def test_real_valued_complex_array_is_accepted(tmp_path):
    np.savez(tmp_path / "c.npz", u=np.arange(4) + 0j, y=np.arange(4.0), fs=1.0)
    assert read_record(tmp_path / "c.npz").u.dtype == np.float64


@pytest.mark.parametrize(
    "payload,expected",
    [
        ([1, 2], "not a piezotwin model file"),
        ({"format": "piezotwin-model/1", "identifier": "arx"}, "lacks params, state"),
        ({"format": "piezotwin-model/1", "identifier": "arx", "params": {"bogus": 1}, "state": {}}, "bogus"),
        ({"format": "piezotwin-model/1", "identifier": "nosuch", "params": {}, "state": {}}, "unknown identifier"),
    ],
)
def test_model_file_that_is_not_a_model(payload, expected, tmp_path):
    from sysid.base import load_model
    from sysid.errors import InputError

    p = tmp_path / "m.json"
    p.write_text(json.dumps(payload))
    with pytest.raises(InputError, match=expected):
        load_model(p)
    with pytest.raises(InputError, match="is a directory"):
        load_model(tmp_path)
