"""Records: round trips through every format bit-exactly, slicing/splitting, the normaliser, and the
clear one-line error for each kind of bad input."""

import json

import numpy as np
import pytest
from scipy.io import savemat

from sysid.data.io import read_record, write_record
from sysid.data.record import Normaliser, Record
from sysid.errors import DataError


def _rec(n=257, seed=1, mimo=False):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 2)) if mimo else rng.standard_normal(n)
    y = rng.standard_normal(n) * 1e-6 + 1e3  # values whose decimal text is long
    return Record(u=u, y=y, fs=12345.678, units={"u": "V", "y": "um"}, meta={"seed": 1, "note": "x"})


@pytest.mark.parametrize("mimo", [False, True])
def test_npz_round_trip_bit_exact(tmp_path, mimo):
    rec = _rec(mimo=mimo)
    path = write_record(rec, tmp_path / "r.npz")
    back = read_record(path)
    assert np.array_equal(back.u, rec.u) and np.array_equal(back.y, rec.y)
    assert back.fs == rec.fs and back.units == rec.units and back.meta["note"] == "x"
    # plain numpy can read it without pickle
    with np.load(path, allow_pickle=False) as z:
        assert json.loads(str(z["meta"]))["seed"] == 1


@pytest.mark.parametrize("suffix", [".csv", ".mat"])
def test_csv_mat_round_trip_bit_exact(tmp_path, suffix):
    rec = _rec()
    back = read_record(write_record(rec, tmp_path / f"r{suffix}"))
    assert np.array_equal(back.u, rec.u) and np.array_equal(back.y, rec.y)
    assert back.fs == pytest.approx(rec.fs, rel=1e-12)


def test_csv_extra_columns_and_custom_names(tmp_path):
    rec = _rec()
    path = tmp_path / "r.csv"
    lines = ["t,vin,xout,extra,"] + [
        f"{i / rec.fs!r},{float(a)!r},{float(b)!r},junk," for i, (a, b) in enumerate(zip(rec.u, rec.y))
    ]
    path.write_text("\n".join(lines) + "\n")
    back = read_record(path, u_col="vin", y_col="xout")
    assert np.array_equal(back.u, rec.u) and np.array_equal(back.y, rec.y)


def test_mat_custom_variables(tmp_path):
    rec = _rec()
    path = tmp_path / "r.mat"
    savemat(path, {"vin": rec.u, "xout": rec.y, "fs": rec.fs})
    back = read_record(path, u_var="vin", y_var="xout")
    assert np.array_equal(back.u, rec.u) and np.array_equal(back.y, rec.y) and back.fs == rec.fs


def test_csv_headerless_with_index_columns_and_trailing_empty(tmp_path, shared_data):
    rec = read_record(shared_data / "piezo_tue_150v_1hz" / "hysteresis_v_150_1hz.csv", u_col="3", y_col="2", fs=5000)
    assert len(rec) == 50001 and rec.fs == 5000
    assert rec.u.max() == pytest.approx(150, abs=1)
    sb = read_record(shared_data / "silverbox" / "SNLS80mV.csv", u_col="V1", y_col="V2", fs=610.35)
    assert len(sb) == 131072


def test_slicing_split_and_time():
    rec = _rec(n=100)
    a, b = rec.split(fraction=0.3)
    assert len(a) == 30 and len(b) == 70
    assert np.array_equal(np.concatenate([a.u, b.u]), rec.u)
    assert b.t[0] == pytest.approx(30 / rec.fs)
    part = rec.time_slice(10 / rec.fs, 20 / rec.fs)
    assert len(part) == 10 and np.array_equal(part.y, rec.y[10:20])
    a, b = rec.split(index=40)
    assert len(a) == 40 and len(b) == 60
    for kw in ({}, {"fraction": 0.5, "index": 50}):
        with pytest.raises(DataError, match="exactly one of fraction or index"):
            rec.split(**kw)
    with pytest.raises(DataError, match=r"fraction must lie in \(0, 1\)"):
        rec.split(fraction=1.5)


def test_output_of_a_record_that_must_have_one():
    rec = _rec(n=50)
    assert rec.output is rec.y and rec.require_output() is rec
    bare = Record(u=rec.u, y=None, fs=rec.fs, source="drive.csv")
    for read in (lambda: bare.output, bare.require_output):
        with pytest.raises(DataError, match=r"^drive.csv: record has no output y \(input-only record\)$"):
            read()


def test_normaliser_inverts_exactly():
    rec = _rec(mimo=True)
    norm = Normaliser().fit(rec)
    z = norm.transform(rec)
    assert np.allclose(z.u.mean(axis=0), 0, atol=1e-12) and np.allclose(z.u.std(axis=0), 1)
    back = norm.inverse_transform(z)
    assert np.allclose(back.u, rec.u, rtol=1e-15, atol=1e-15 * np.abs(rec.u).max())
    assert np.max(np.abs(back.y - rec.y)) <= 4 * np.finfo(float).eps * np.abs(rec.y).max()
    again = Normaliser.from_dict(norm.to_dict())
    assert np.array_equal(again.transform_y(rec.y), z.y)


# ---------------------------------------------------------------------------------------------- bad input
def _one_line(exc):
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def test_missing_file(tmp_path):
    with pytest.raises(DataError) as e:
        read_record(tmp_path / "nope.npz")
    assert "nope.npz" in _one_line(e) and "not found" in _one_line(e)


def test_unknown_format(tmp_path):
    p = tmp_path / "data.xlsx"
    p.write_text("x")
    with pytest.raises(DataError) as e:
        read_record(p)
    assert "unknown format" in _one_line(e) and "data.xlsx" in _one_line(e)


def test_nan_refused_unless_filled(tmp_path):
    p = tmp_path / "gap.csv"
    p.write_text("u,y\n1,1\n2,\n3,3\n4,nan\n5,5\n")
    with pytest.raises(DataError) as e:
        read_record(p, fs=10)
    assert "gap.csv" in _one_line(e) and "NaN" in _one_line(e) and "index 1" in _one_line(e)
    rec = read_record(p, fs=10, fill_missing=True)
    assert np.array_equal(rec.y, [1, 2, 3, 4, 5])
    assert rec.meta["preprocessing"][0]["filled_indices"] == {"y": [1, 3]}


def test_inf_refused_even_with_fill(tmp_path):
    p = tmp_path / "inf.csv"
    p.write_text("u,y\n1,1\n2,inf\n")
    for fill in (False, True):
        with pytest.raises(DataError) as e:
            read_record(p, fs=10, fill_missing=fill)
        assert "inf" in _one_line(e)


def test_unequal_lengths(tmp_path):
    p = tmp_path / "bad.npz"
    np.savez(p, u=np.zeros(5), y=np.zeros(4), fs=1.0)
    with pytest.raises(DataError) as e:
        read_record(p)
    assert "unequal lengths" in _one_line(e) and "bad.npz" in _one_line(e)


@pytest.mark.parametrize("fs", [0.0, -5.0])
def test_nonpositive_fs(tmp_path, fs):
    p = tmp_path / "fs.npz"
    np.savez(p, u=np.zeros(5), y=np.zeros(5), fs=fs)
    with pytest.raises(DataError) as e:
        read_record(p)
    assert "fs must be positive" in _one_line(e)


def test_empty_file_and_empty_array(tmp_path):
    p = tmp_path / "empty.csv"
    p.write_text("")
    with pytest.raises(DataError) as e:
        read_record(p)
    assert "empty" in _one_line(e)
    p2 = tmp_path / "empty.npz"
    np.savez(p2, u=np.zeros(0), y=np.zeros(0), fs=1.0)
    with pytest.raises(DataError) as e:
        read_record(p2)
    assert "empty" in _one_line(e)


def test_missing_column(tmp_path):
    p = tmp_path / "cols.csv"
    p.write_text("t,a,b\n0,1,2\n0.1,1,2\n")
    with pytest.raises(DataError) as e:
        read_record(p)
    msg = _one_line(e)
    assert "missing column 'u'" in msg and "cols.csv" in msg and "a, b" in msg
    with pytest.raises(DataError) as e:
        read_record(p, u_col="a", y_col="zz")
    assert "missing column 'zz'" in _one_line(e)
    assert read_record(p, u_col="a", y_col="b").fs == pytest.approx(10.0)


def test_non_uniform_time_column(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("t,u,y\n0,1,1\n0.1,1,1\n0.3,1,1\n")
    with pytest.raises(DataError) as e:
        read_record(p)
    assert "not uniformly sampled" in _one_line(e)
