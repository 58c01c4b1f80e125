"""Fuzz test of every data-reading command: malformed files and option values.

A seeded, table-driven generator mutates good CSV / NPZ / MAT records (truncation, stray bytes, delimiters,
extra or missing cells, blank and comment lines, UTF-16, CRLF, inf/nan text, wrong shapes, dtypes, fs and
metadata) and draws option values (nan, inf, huge, negative, text ...). Each case runs
``benchmarks.cli.main`` in-process and must end in exit 0 (a valid input) or exit 2 with exactly one line on
stderr and no traceback (any exception escaping ``main`` fails the test); the input file is byte-for-byte
unchanged and a refused case leaves no new file. The default run is bounded to a few seconds; the
``slow`` run goes through many more cases and adds calibrate/diagnose/search.
"""

import hashlib
import io
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.io import savemat

from benchmarks.cli import main

FS = 1000.0
N = 300


def _good_arrays():
    rng = np.random.default_rng(3)
    u = 40 * np.sin(2 * np.pi * 7 * np.arange(N) / FS) + rng.standard_normal(N)
    y = np.convolve(u, [0.0, 0.4, 0.2])[:N]
    return u, y


def _csv_text() -> str:
    u, y = _good_arrays()
    return "t,u,y\n" + "".join(f"{k / FS!r},{a!r},{b!r}\n" for k, (a, b) in enumerate(zip(u, y)))


# ------------------------------------------------------------------ mutations
def mutate_csv(text: str, rng: np.random.Generator) -> bytes:
    lines = text.splitlines()
    k = int(rng.integers(1, len(lines)))
    kind = int(rng.integers(0, 16))
    if kind == 0:
        return text.encode()[: int(rng.integers(0, len(text)))]
    if kind == 1:
        pos = int(rng.integers(0, len(text)))
        return (
            text[:pos] + "".join(rng.choice(list(',;\t x.#"\n\r-e'), size=int(rng.integers(1, 4)))) + text[pos:]
        ).encode()
    if kind == 2:
        lines[k] += ",1"
    elif kind == 3:
        lines[k] = lines[k].rsplit(",", 1)[0]
    elif kind == 4:
        lines.insert(k, "")
    elif kind == 5:
        lines.insert(k, "# a comment")
    elif kind == 6:
        cells = lines[k].split(",")
        cells[int(rng.integers(0, len(cells)))] = str(
            rng.choice(["inf", "nan", "1e999", "--1", "", "x", "0,5", "1.2.3"])
        )
        lines[k] = ",".join(cells)
    elif kind == 7:
        lines[0] = str(rng.choice(["u,t,y", "a,b,c", "t;u;y", "t,u", "t,u,y,z", '"t","u","y"', "time_ms,u,y", "t,u,u"]))
    elif kind == 8:
        return ("\n".join(lines) + "\n").encode("utf-16")
    elif kind == 9:
        return ("\r\n".join(lines) + "\r\n").encode()
    elif kind == 10:
        lines = [ln.replace(",", ";") for ln in lines]
    elif kind == 11:
        lines = [ln.replace(",", ";").replace(".", ",") for ln in lines]
    elif kind == 12:
        lines = lines[:1] + lines[1:][::-1]  # time running backwards
    elif kind == 13:
        lines = lines[: int(rng.integers(1, 4))]
    elif kind == 14:
        lines = [ln.replace(",", "\t") for ln in lines]
    else:
        return b"\xef\xbb\xbf" + ("\n".join(lines) + "\n").encode()
    return ("\n".join(lines) + "\n").encode()


def npz_bytes(rng: np.random.Generator) -> bytes:
    u, y = _good_arrays()
    arrays = {"u": u, "y": y, "fs": FS}
    kind = int(rng.integers(0, 14))
    if kind == 0:
        arrays["u"] = u[None, :]
    elif kind == 1:
        arrays["y"] = y[:-5]
    elif kind == 2:
        arrays["fs"] = rng.choice([np.nan, -1.0, 0.0, 1e308, 1e-300, np.inf])
    elif kind == 3:
        arrays["fs"] = np.array([1.0, 2.0])
    elif kind == 4:
        arrays["fs"] = np.array("fast")
    elif kind == 5:
        arrays["u"] = np.array(["a"] * N)
    elif kind == 6:
        arrays["u"] = np.zeros((N, 2, 2))
    elif kind == 7:
        metas = [{"units": 5}, {"t0": "x"}, {"segments": 3}, {"units": [1], "segments": "x"}, {"preprocessing": 1}]
        arrays["meta"] = np.array(json.dumps(metas[int(rng.integers(0, len(metas)))]))
    elif kind == 8:
        arrays["meta"] = np.array("{not json")
    elif kind == 9:
        del arrays["u"]
    elif kind == 10:
        arrays["u"] = u.astype(np.complex128) + 1j
    elif kind == 11:
        arrays["u"] = np.array([])
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    raw = buf.getvalue()
    if kind == 12:
        raw = raw[: int(rng.integers(0, len(raw)))]
    elif kind == 13:
        b = bytearray(raw)
        for _ in range(8):
            b[int(rng.integers(0, len(b)))] = int(rng.integers(0, 256))
        raw = bytes(b)
    return raw


def mat_bytes(rng: np.random.Generator) -> bytes:
    u, y = _good_arrays()
    mdict = {"u": u, "y": y, "fs": FS}
    kind = int(rng.integers(0, 7))
    if kind == 0:
        mdict["u"] = np.vstack([u, u])
    elif kind == 1:
        mdict["fs"] = np.array([1.0, 2.0])
    elif kind == 2:
        mdict["u"] = "text"
    elif kind == 3:
        mdict["t"] = np.arange(N) / 500.0  # disagrees with fs
    elif kind == 4:
        mdict = {"u": u, "y": y, "Ts": -1.0}
    buf = io.BytesIO()
    savemat(buf, mdict)
    raw = buf.getvalue()
    if kind == 5:
        raw = raw[: int(rng.integers(0, len(raw)))]
    return raw


BAD_VALUES = ["nan", "inf", "-inf", "-5", "0", "1e308", "1e-300", "99999999999999999999", "abc", "", "1,5", "-0", "0.5"]


def option_cases(rng: np.random.Generator, good: Path, out: Path) -> list[list[str]]:
    v = lambda: str(rng.choice(BAD_VALUES))  # noqa: E731
    return [
        ["preprocess", str(good), "--fs", v(), "--remove-offset", "-o", str(out)],
        ["preprocess", str(good), "--moving-average", v(), "-o", str(out)],
        ["preprocess", str(good), "--decimate", v(), "-o", str(out)],
        ["preprocess", str(good), "--resample", v(), "-o", str(out)],
        ["preprocess", str(good), "--bandpass", f"{v()}:{v()}:{v()}", "-o", str(out)],
        ["preprocess", str(good), "--segment", f"{v()}:{v()}", "-o", str(out)],
        ["preprocess", str(good), "--detrend", v(), "-o", str(out)],
        ["preprocess", str(good), "--outliers", f"{v()}:{v()}", "-o", str(out)],
        ["simulate", "cantilever", "--input", str(good), "--seed", v(), "-o", str(out)],
        ["simulate", "cantilever", "--input", str(good), "--set", f"gain_um_per_v={v()}", "-o", str(out)],
        ["identify", "arx", "--est", str(good), "--set", f"ny={v()},nu={v()}"],
        ["signal", "multisine", "--fs", v(), "--duration", "0.1", "-o", str(out)],
        ["signal", "multisine", "--fs", "1000", "--duration", v(), "--periods", v(), "-o", str(out)],
        ["signal", "sine", "--fs", "1000", "--duration", "0.1", "--freq", v(), "--amplitude", v(), "-o", str(out)],
        ["signal", "prbs", "--fs", "1000", "--order", v(), "--bit-samples", v(), "-o", str(out)],
    ]


def _digest(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


def _check(argv: list[str], folder: Path, capsys, keep: set[str]) -> int:
    before = _digest(folder)
    try:
        code = main(argv)
    except SystemExit as e:
        code = e.code
    err = capsys.readouterr().err
    assert code in (0, 2), (argv, err)
    after = _digest(folder)
    for name in before:  # inputs (and everything else present) unchanged
        assert after.get(name) == before[name] or name not in keep, (argv, name)
    if code == 2:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in err, (argv, err)
        assert set(after) == set(before), (argv, "a refused command left", set(after) - set(before))
    for name in set(after) - keep:  # outputs of accepted cases are removed before the next case
        (folder / name).unlink()
    return code


def _commands(path: Path, out: Path, slow: bool) -> list[list[str]]:
    cmds = [
        ["preprocess", str(path), "--remove-offset", "-o", str(out)],
        ["simulate", "cantilever", "--input", str(path), "-o", str(out)],
        ["identify", "arx", "--est", str(path), "--set", "ny=2,nu=2"],
    ]
    if slow:
        cmds += [
            ["calibrate", "cantilever", "--data", str(path)],
            ["identify", "arx", "--est", str(path), "--val", str(path), "-o", str(out.with_suffix(".json"))],
        ]
    return cmds


def _fuzz(tmp_path: Path, capsys, cases: int, seed: int, slow: bool = False) -> dict[str, int]:
    """``cases`` random bad (or good) inputs, a fixed number so that the run does not depend on the machine's speed."""
    rng = np.random.default_rng(seed)
    good = tmp_path / "good.npz"
    u, y = _good_arrays()
    np.savez(good, u=u, y=y, fs=FS)
    out = tmp_path / "out.npz"
    text = _csv_text()
    counts = {"cases": 0, "accepted": 0, "refused": 0}
    for _ in range(cases):
        which = int(rng.integers(0, 4))
        if which == 3:
            argv = option_cases(rng, good, out)[int(rng.integers(0, 15))]
        else:
            suffix, data = [
                (".csv", lambda: mutate_csv(text, rng)),
                (".npz", lambda: npz_bytes(rng)),
                (".mat", lambda: mat_bytes(rng)),
            ][which]
            path = tmp_path / f"case{suffix}"
            path.write_bytes(data())
            cmds = _commands(path, out, slow)
            argv = cmds[int(rng.integers(0, len(cmds)))]
        keep = {p.name for p in tmp_path.iterdir()}
        code = _check(argv, tmp_path, capsys, keep)
        counts["cases"] += 1
        counts["accepted" if code == 0 else "refused"] += 1
    return counts


def test_fuzz_commands_quick(tmp_path, capsys):
    counts = _fuzz(tmp_path, capsys, cases=24, seed=0)  # every case is checked inside (_check)
    assert counts["refused"] > 0, counts


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(1, 5))
def test_fuzz_commands_long(tmp_path, capsys, seed):
    counts = _fuzz(tmp_path, capsys, cases=300, seed=seed, slow=True)
    assert counts["refused"] > 0 and counts["accepted"] > 0, counts
