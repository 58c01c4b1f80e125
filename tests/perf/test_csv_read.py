"""Speed of the strict CSV reader: a 1e6-row ``t,u,y`` file is read by
:func:`sysid.data.io.read_record` (structure checks + time column + parsing) within 2x of a bare
``pandas.read_csv`` of the same file. Both are wall-clock times (``time.perf_counter``), taken alternately in
the same run, best of 5 each, so that the load of a shared machine hits both alike (CPU time is not used:
pandas' reader reports far less CPU than wall time here, which would flatter the ratio's denominator).

Run: ``python -m pytest tests/perf/test_csv_read.py --benchmark-enable -p no:cacheprovider -o addopts=""``.
"""

import time

import numpy as np
import pytest

from sysid.data.io import read_record

N = 1_000_000


@pytest.fixture(scope="module")
def big_csv(tmp_path_factory):
    rng = np.random.default_rng(0)
    t = np.arange(N) / 1000.0
    data = np.column_stack([t, rng.standard_normal(N), rng.standard_normal(N)])
    path = tmp_path_factory.mktemp("csv") / "big.csv"
    np.savetxt(path, data, delimiter=",", header="t,u,y", comments="", fmt="%.17g")
    return path


def _best_pair(fa, fb, repeats: int = 5) -> tuple[float, float]:
    """Best wall time of ``fa`` and of ``fb``, run alternately."""
    best_a = best_b = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fa()
        best_a = min(best_a, time.perf_counter() - t0)
        t0 = time.perf_counter()
        fb()
        best_b = min(best_b, time.perf_counter() - t0)
    return best_a, best_b


def test_csv_reader_within_2x_of_pandas(big_csv, benchmark):
    pd = pytest.importorskip("pandas")
    rec = benchmark.pedantic(read_record, args=(big_csv,), rounds=1, iterations=1)
    assert len(rec) == N and rec.fs == pytest.approx(1000.0)
    ours, ref = _best_pair(lambda: read_record(big_csv), lambda: pd.read_csv(big_csv))
    ratio = ours / ref
    benchmark.extra_info.update({"rows": N, "ours_s": ours, "pandas_s": ref, "ratio": ratio})
    print(f"read_record {ours:.3f} s, pandas.read_csv {ref:.3f} s, ratio {ratio:.2f}")
    assert ratio < 2.0
