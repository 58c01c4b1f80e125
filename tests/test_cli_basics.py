"""The CLI: bad input gives one line on stderr and exit status 2, never a traceback."""

import subprocess
import sys

import numpy as np
import pytest

from benchmarks.cli import main


def test_help_lists_commands(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for cmd in ("list", "simulate", "generate", "calibrate", "run"):
        assert cmd in out


@pytest.mark.parametrize(
    "args",
    [
        ["simulate", "nosuchtwin", "--input", "x.npz", "-o", "y.npz"],
        ["list", "nonsense"],
    ],
)
def test_errors_exit_2_one_line(args, capsys):
    try:
        code = main(args)
    except SystemExit as e:
        code = e.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert err and "Traceback" not in err


def test_bad_file_one_line_subprocess(tmp_path):
    bad = tmp_path / "bad.npz"
    np.savez(bad, u=np.array([1.0, np.nan]), fs=1.0)
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "benchmarks.cli",
            "simulate",
            "cantilever",
            "--input",
            str(bad),
            "-o",
            str(tmp_path / "o.npz"),
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr
