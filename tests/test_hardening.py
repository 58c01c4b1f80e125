"""Nothing lost, nothing misread, no traceback — the measured failing cases, each reproduced.

Every refusal: exit status 2, exactly one line on stderr naming the file/option, no traceback, inputs
byte-for-byte unchanged and no new file left in the folder. Valid files are read exactly right (the expected
values are written in the test, not taken from the reader). Most cases call ``benchmarks.cli.main``
in-process; interruption (SIGTERM, SIGINT) and the file-size limit run in a subprocess.
"""

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli import main
from sysid.data.io import read_record
from sysid.errors import DataError

ROOT = Path(__file__).resolve().parents[1]
FS = 1000.0
N = 400


@pytest.fixture(scope="module")
def cantilever_io():
    from twins.registry import get_twin

    uc = 50 * np.sin(2 * np.pi * 5 * np.arange(500) / FS)
    return uc, get_twin("cantilever")().simulate(uc, FS)


@pytest.fixture()
def d(tmp_path, cantilever_io) -> Path:
    rng = np.random.default_rng(1)
    u = rng.standard_normal(N)
    y = np.convolve(u, [0.0, 0.5, 0.3])[:N]
    np.savez(tmp_path / "in.npz", u=u, y=y, fs=FS)
    np.savez(tmp_path / "val100.npz", u=u, y=y, fs=100.0)
    uc, yc = cantilever_io
    np.savez(tmp_path / "m.npz", u=uc, y=yc, fs=FS)
    np.savez(tmp_path / "m100.npz", u=uc, y=yc, fs=100.0)
    (tmp_path / "afile").write_text("not a folder\n")
    return tmp_path


def _snapshot(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): (hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir")
        for p in sorted(folder.rglob("*"))
        if not p.is_symlink()
    }


def refused(argv: list[str], folder: Path, capsys, expected: str | None = None) -> str:
    """Run ``argv`` in-process; assert exit 2, one stderr line, no traceback, folder unchanged."""
    before = _snapshot(folder)
    try:
        code = main([str(a) for a in argv])
    except SystemExit as e:  # argparse
        code = e.code
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    if expected:
        assert expected in lines[0], lines[0]
    assert _snapshot(folder) == before, "a refused command changed or left files"
    return lines[0]


# ------------------------------------------------------------------ data loss
def test_output_that_is_the_input_is_refused_before_work(d, capsys):
    refused(["preprocess", d / "in.npz", "--detrend", "-o", d / "in.npz"], d, capsys, "same file as the input")
    refused(["simulate", "cantilever", "--input", d / "m.npz", "-o", d / "m.npz"], d, capsys, "same file")
    os.symlink(d / "in.npz", d / "link.npz")
    refused(["preprocess", d / "in.npz", "--detrend", "-o", d / "link.npz"], d, capsys, "same file")
    os.link(d / "m.npz", d / "hard.npz")
    refused(["simulate", "cantilever", "--input", d / "hard.npz", "-o", d / "m.npz"], d, capsys, "same file")
    refused(["identify", "arx", "--est", d / "in.npz", "-o", d / "in.npz"], d, capsys, "same file")


def test_failed_run_keeps_the_existing_output(d, capsys):
    old = d / "old.npz"
    old.write_bytes(b"previous output")
    # the failure comes after reading (segment longer than the record), while the output is being prepared
    refused(["preprocess", d / "in.npz", "--segment", "100000", "-o", old], d, capsys, "segment length")
    assert old.read_bytes() == b"previous output"


def test_refused_option_leaves_no_file(d, capsys):
    refused(
        ["identify", "arx", "--est", d / "in.npz", "-o", d / "m.json", "--plots", d / "afile" / "sub"],
        d,
        capsys,
        "afile is a file",
    )
    refused(
        [
            "search",
            "arx",
            "--est",
            d / "in.npz",
            "--val",
            d / "in.npz",
            "--grid",
            "ny=1,2",
            "--trials",
            "-5",
            "--storage",
            d / "st.db",
        ],
        d,
        capsys,
        "--trials",
    )


def _default_signals() -> None:
    """In the child before exec: SIGINT and SIGTERM back to their defaults. A disposition this test process
    inherited or an earlier test left (SIGINT ignored) would otherwise pass to the CLI, whose Python then
    never raises KeyboardInterrupt, and the test would check the harness, not the CLI."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _spawn(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "benchmarks.cli", *map(str, args)],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_default_signals,
        env={**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"},
    )


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_during_write_leaves_old_output(tmp_path, sig, code):
    """A 1.6e7-sample record (128 MB of .npz) is interrupted while its temporary file grows: the previous
    output survives byte for byte and no temporary file remains."""
    out = tmp_path / "g.npz"
    out.write_bytes(b"old")
    proc = _spawn(["signal", "multisine", "--fs", "1e6", "--duration", "16", "--band", "1:1000", "-o", out], tmp_path)
    deadline = time.time() + 120
    while time.time() < deadline and not list(tmp_path.glob(".g.npz.tmp-*")):
        time.sleep(0.005)
    # Freeze the writer the moment its temporary file exists, so that the signal lands inside the write however
    # fast this machine writes 128 MB (on an idle one the whole write can finish between two polls).
    proc.send_signal(signal.SIGSTOP)
    assert list(tmp_path.glob(".g.npz.tmp-*")), "the writer never started or finished before it was stopped"
    proc.send_signal(sig)
    proc.send_signal(signal.SIGCONT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert out.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.npz"]


def test_file_size_limit_keeps_old_output(d):
    """``ulimit -f`` makes the write fail midway: clean error, old output intact, no fragment."""
    big = d / "big.npz"
    np.savez(big, u=np.zeros(200_000), y=np.zeros(200_000), fs=FS)
    old = d / "old.npz"
    old.write_bytes(b"previous")
    cmd = f"ulimit -f 100; exec {sys.executable} -m benchmarks.cli preprocess {big} --segment 1000 -o {old}"
    proc = subprocess.run(
        ["bash", "-c", cmd],
        capture_output=True,
        text=True,
        cwd=d,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert proc.returncode == 2 and "cannot write" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, (
        proc.stderr
    )
    assert old.read_bytes() == b"previous"
    assert not list(d.glob(".old.npz.tmp-*"))


# ------------------------------------------------------------------ silent misreads
def test_csv_comma_decimals_with_semicolons_read_exactly(tmp_path):
    p = tmp_path / "de.csv"
    p.write_text("t;u;y\n0;1,5;-0,623274\n0,01;2,5;3\n0,02;-1;1e-3\n")
    rec = read_record(p)
    assert rec.fs == pytest.approx(100.0)
    assert rec.u.tolist() == [1.5, 2.5, -1.0] and rec.y.tolist() == [-0.623274, 3.0, 0.001]


def test_csv_extra_or_missing_cells_blank_rows_refused_with_line(tmp_path):
    cases = {
        "extra.csv": ("t,u,y\n0,1,2\n0.001,1,-0,623274\n0.002,1,1\n", "line 3 (row 3) has 4 cells"),
        "short.csv": ("t,u,y\n0,1,2\n0.001,1\n0.002,1,1\n", "line 3 (row 3) has 2 cells, fewer"),
        "blank.csv": ("t,u,y\n0,1,2\n\n0.001,1,3\n0.002,1,1\n", "line 3 is blank"),
        "text.csv": ("t,u,y\n0,1,2\n0.001,1x,3\n", "(line 3, column 2)"),
        "mixed.csv": ("u;y\n1,5;2\n3.5;4\n", "both '.' and ','"),
    }
    for name, (text, expected) in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(DataError, match=expected.replace("(", r"\(").replace(")", r"\)")):
            read_record(tmp_path / name, fs=1000)


def test_csv_variants_read_exactly(tmp_path):
    """CRLF + BOM + quoted header, `#` comments, a millisecond time column, tab and space delimiters."""
    (tmp_path / "a.csv").write_bytes(b'\xef\xbb\xbf"time_ms","u","y"\r\n0,1,2\r\n0.1,3,4\r\n0.2,5,6\r\n')
    (tmp_path / "b.csv").write_text("# exported by scope\nTime\tu\ty\n0\t1\t2\n# marker\n0.5\t3\t4\n1.0\t5\t6\n\n")
    np.savetxt(tmp_path / "c.csv", [[0, 1, 2], [0.01, 3, 4], [0.02, 5, 6]], header="t,u,y")
    (tmp_path / "d.csv").write_text("time_us,u,y\n0,1,2\n2,3,4\n4,5,6\n")
    expected_fs = {"a.csv": 1e4, "b.csv": 2.0, "c.csv": 100.0, "d.csv": 5e5}
    for name, fs in expected_fs.items():
        rec = read_record(tmp_path / name)
        assert rec.fs == pytest.approx(fs, rel=1e-9), name
        assert rec.u.tolist() == [1, 3, 5] and rec.y.tolist() == [2, 4, 6], name


def test_fs_contradicting_time_column_refused_with_both_values(tmp_path, capsys):
    p = tmp_path / "t.csv"
    p.write_text("time_s,u,y\n" + "".join(f"{k / 1000!r},{k},{k}\n" for k in range(50)))
    line = refused(["preprocess", p, "--fs", "2000", "--remove-offset", "-o", tmp_path / "o.npz"], tmp_path, capsys)
    assert "2000" in line and "1000" in line and "time_s" in line
    np.savetxt(tmp_path / "s.csv", np.column_stack([np.arange(50) / 100, np.ones(50), np.ones(50)]), header="t,u,y")
    line = refused(
        ["preprocess", tmp_path / "s.csv", "--fs", "1000", "--remove-offset", "-o", tmp_path / "o.npz"],
        tmp_path,
        capsys,
    )
    assert "1000" in line and "100 Hz" in line


def test_row_arrays_are_refused_not_transposed(tmp_path):
    from scipy.io import savemat

    np.savez(tmp_path / "row.npz", u=np.ones((1, 200)), y=np.ones((1, 200)), fs=FS)
    with pytest.raises(DataError, match=r"shape \(1, 200\)"):
        read_record(tmp_path / "row.npz")
    savemat(tmp_path / "two.mat", {"u": np.ones((2, 200)), "y": np.ones((2, 200)), "fs": FS})
    with pytest.raises(DataError, match=r"shape \(2, 200\)"):
        read_record(tmp_path / "two.mat")
    savemat(tmp_path / "vec.mat", {"u": np.arange(200.0)[None, :], "y": np.arange(200.0)[:, None], "fs": FS})
    rec = read_record(tmp_path / "vec.mat")  # MATLAB row/column vectors: one channel, explicitly
    assert rec.u.shape == (200,) and rec.u[3] == 3.0 and rec.y[5] == 5.0


def test_mat_rate_from_time_vector_or_ts(tmp_path):
    from scipy.io import savemat

    savemat(tmp_path / "t.mat", {"u": np.ones(100), "y": np.ones(100), "t": np.arange(100) / 250.0})
    savemat(tmp_path / "ts.mat", {"u": np.ones(100), "y": np.ones(100), "Ts": 0.004})
    savemat(tmp_path / "both.mat", {"u": np.ones(100), "y": np.ones(100), "Ts": 0.004, "fs": 1000.0})
    assert read_record(tmp_path / "t.mat").fs == pytest.approx(250.0)
    assert read_record(tmp_path / "ts.mat").fs == pytest.approx(250.0)
    with pytest.raises(DataError, match="disagree"):
        read_record(tmp_path / "both.mat")


def test_mat73_external_link_refused(tmp_path):
    h5py = pytest.importorskip("h5py")
    with h5py.File(tmp_path / "secret.h5", "w") as f:
        f["u"] = np.arange(10.0)
    with h5py.File(tmp_path / "x.mat", "w", userblock_size=512) as f:
        f["u"] = h5py.ExternalLink(str(tmp_path / "secret.h5"), "/u")
        f["fs"] = np.array([[1000.0]])
    with open(tmp_path / "x.mat", "r+b") as fh:  # MATLAB 7.3 header in the user block
        text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
        fh.write(text.ljust(116, b" ") + bytes(8) + b"\x00\x02" + b"IM")
    with pytest.raises(DataError, match="external link"):
        read_record(tmp_path / "x.mat")


def test_est_and_val_at_different_rates_refused(d, capsys):
    for argv in (
        ["identify", "arx", "--est", d / "in.npz", "--val", d / "val100.npz"],
        ["identify", "arx", "--est", d / "in.npz", "--est", d / "val100.npz"],
        ["calibrate", "cantilever", "--data", d / "m.npz", "--val", d / "m100.npz"],
        ["search", "arx", "--est", d / "in.npz", "--val", d / "val100.npz", "--grid", "ny=1", "--storage", d / "s.db"],
    ):
        line = refused(argv, d, capsys, "share fs")
        assert "100 Hz" in line and "1000 Hz" in line


# ------------------------------------------------------------------ options
@pytest.mark.parametrize(
    "extra,expected",
    [
        (["identify", "arx", "--est", "{d}/in.npz", "--set", "ny=inf"], "ny"),
        (["identify", "arx", "--est", "{d}/in.npz", "--set", "ny=1e300"], "ny"),
        (["identify", "narx-mlp", "--est", "{d}/in.npz", "--set", "hidden=-4"], "hidden"),
        (["diagnose", "cantilever", "--data", "{d}/m.npz", "--skip", "-5"], "--skip"),
        (["score", "--margin", "nan", "--update-baselines", "--baselines", "{d}/b.json"], "--margin"),
        (
            ["simulate", "cantilever", "--input", "{d}/m.npz", "--fs", "1e308", "-o", "{d}/o.npz"],
            "outside the accepted range",
        ),
        (
            ["simulate", "cantilever", "--input", "{d}/m.npz", "--fs", "1e-300", "-o", "{d}/o.npz"],
            "outside the accepted range",
        ),
        (["simulate", "cantilever", "--input", "{d}/m.npz", "--seed", "1e30", "-o", "{d}/o.npz"], "seed"),
        (
            [
                "search",
                "arx",
                "--est",
                "{d}/in.npz",
                "--val",
                "{d}/in.npz",
                "--grid",
                "ny=1",
                "--repeats",
                "99999999999999999999",
            ],
            "--repeats",
        ),
        (["signal", "multisine", "--fs", "1e4", "--duration", "1e5", "-o", "{d}/s.npz"], "GiB"),
        (["preprocess", "{d}/in.npz", "--bandpass", "1:10:1000000000", "-o", "{d}/o.npz"], "--bandpass"),
        (["export-fmu", "cantilever", "--fs", "1e308", "-o", "{d}/x.fmu"], "outside the accepted range"),
    ],
)
def test_bad_option_values(extra, expected, d, capsys):
    refused([a.replace("{d}", str(d)) for a in extra], d, capsys, expected)


@pytest.mark.parametrize(
    "payload,expected",
    [
        ({"params": [1, 2]}, "'params' must be an object"),
        ({"params": {}, "effects": 5}, "'effects' must be a list"),
        ({"params": {"gain_um_per_v": [1, 2]}}, "must be a number"),
        ({"params": {"gain_um_per_v": None}}, "must be a number"),
    ],
)
def test_params_file_structure(payload, expected, d, capsys):
    p = d / "p.json"
    p.write_text(json.dumps({"format": "piezotwin-params/1", "twin": "cantilever", **payload}))
    refused(["simulate", "cantilever", "--input", d / "m.npz", "--params", p, "-o", d / "o.npz"], d, capsys, expected)


@pytest.mark.parametrize(
    "meta,expected",
    [
        ({"units": 5}, "'units'"),
        ({"t0": "abc"}, "'t0'"),
        ({"segments": 5}, "'segments'"),
        ({"segments": [{"start": "a", "stop": 3}]}, "segments"),
        ({"preprocessing": {}}, "'preprocessing'"),
    ],
)
def test_npz_metadata_types(meta, expected, tmp_path):
    np.savez(tmp_path / "m.npz", u=np.ones(10), y=np.ones(10), fs=FS, meta=np.array(json.dumps(meta)))
    with pytest.raises(DataError, match=expected):
        read_record(tmp_path / "m.npz")


# ------------------------------------------------------------------ storage and baselines
@pytest.mark.parametrize(
    "storage,expected",
    [
        ("not a url://x", "not a"),
        ("sqlite:////nonexistent/dir/x.db", "does not exist"),
        ("{d}/data.csv", "not an SQLite"),
        ("foo://bar", "unknown database kind"),
        ("postgresql://", "driver"),
    ],
)
def test_search_storage_refused(storage, expected, d, capsys):
    (d / "data.csv").write_text("u,y\n1,2\n")
    refused(
        [
            "search",
            "arx",
            "--est",
            d / "in.npz",
            "--val",
            d / "in.npz",
            "--grid",
            "ny=1",
            "--storage",
            storage.replace("{d}", str(d)),
        ],
        d,
        capsys,
        expected,
    )


def test_two_processes_create_a_new_sqlite_store(tmp_path):
    """Three processes opening the same new SQLite store at once all succeed (table creation under a lock).
    Without the lock this fails most of the time ('table studies already exists', alembic_version UNIQUE)."""
    script = (
        "import sys, optuna; from sysid.search import _open_storage; from sysid.search.storage_check "
        "import init_sqlite; init_sqlite(sys.argv[1], _open_storage); optuna.create_study(study_name='s', "
        "storage=_open_storage(sys.argv[1]), load_if_exists=True); print('ok')"
    )
    url = f"sqlite:///{tmp_path / 'new.db'}"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", script, url], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
        )
        for _ in range(3)
    ]
    for p in procs:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0 and out.strip() == "ok", err


@pytest.mark.parametrize("content,expected", [("{{{", "JSON"), ("[]", "not a baselines file"), (None, "not found")])
def test_score_baselines_file_refused(content, expected, d, capsys):
    f = d / "b.json"
    if content is not None:
        f.write_text(content)
    refused(
        ["score", "--check", "--baselines", f, "--identifiers", "arx", "--datasets", "silverbox", "--quick"],
        d,
        capsys,
        expected,
    )


def test_generate_rate_option(d, capsys):
    refused(
        ["generate", "cantilever", "steps", "--option", "fs=1e308", "-o", d / "g.npz"],
        d,
        capsys,
        "outside the accepted range",
    )


def test_csv_field_beyond_csv_module_limit(tmp_path):
    p = tmp_path / "long.csv"
    p.write_text('u,y\n"' + "x" * 200_000 + '",1\n1,2\n')
    with pytest.raises(DataError, match="field limit"):
        read_record(p, fs=10)
