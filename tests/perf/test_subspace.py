"""Speed and memory of the subspace identifier ``n4sid``, with nfoursid 1.0 timed in the same run.

Run with ``make bench`` (or ``pytest tests/perf/test_subspace.py --benchmark-enable -m "slow or not slow"``).
Goal: a 10th-order 2×2 model from 1e6 samples in under 30 s and 4 GB on 2 cores, order chosen from the singular
values. nfoursid (also PO-MOESP) forms the whole block-Hankel matrix and an explicit Q; it is timed at the same
block rows and order, on 1e4 samples (time ratio) and in fresh processes on 1e5 and 1e6 samples, where it runs
out of memory (its SVD asks for an N × N matrix). Its code is not used by ours.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from sysid.data.record import Record
from sysid.linear.subspace import N4SID, ss_simulate

REPO = Path(__file__).resolve().parents[2]
BLOCK_ROWS = 10


def make_system(seed: int = 0, n: int = 10):
    """Stable 2×2 system of order n: complex pole pairs of radius 0.75–0.95 in a random basis."""
    rng = np.random.default_rng(seed)
    A = np.zeros((n, n))
    for k in range(n // 2):
        r, th = rng.uniform(0.75, 0.95), rng.uniform(0.1, 2.8)
        A[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = r * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    T = rng.standard_normal((n, n))
    return (
        T @ A @ np.linalg.inv(T),
        rng.standard_normal((n, 2)),
        rng.standard_normal((2, n)),
        0.5 * rng.standard_normal((2, 2)),
    )


def make_data(n: int, seed: int = 1):
    A, B, C, D = make_system()
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 2))
    y = ss_simulate(A, B, C, D, u)
    y += 0.05 * np.std(y, axis=0) * rng.standard_normal(y.shape)
    return u, y


def _fresh_process(n: int, which: str) -> dict:
    """Fit in a fresh interpreter; wall and CPU seconds and peak resident memory (ru_maxrss) of the process."""
    code = textwrap.dedent(f"""
        import json, time, sys, tracemalloc
        sys.path.insert(0, {str(REPO)!r})
        from tests.perf.test_subspace import make_data, ours, nfoursid_fit

        def hwm():  # peak resident memory of this process image [MB] (ru_maxrss survives exec on Linux: not used)
            for line in open("/proc/self/status"):
                if line.startswith("VmHWM"):
                    return int(line.split()[1]) / 1024
        u, y = make_data({n})
        base = hwm()
        tracemalloc.start()
        t0, c0 = time.perf_counter(), time.process_time()
        nx = ours(u, y) if {which!r} == "ours" else nfoursid_fit(u, y)
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        fit_peak = tracemalloc.get_traced_memory()[1] / 2**20
        print(json.dumps({{"seconds": dt, "cpu_seconds": cpu, "peak_rss_mb": hwm(), "data_rss_mb": base,
                           "fit_peak_alloc_mb": fit_peak, "nx": nx}}))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    if out.returncode != 0:
        return {"error": (out.stderr.strip().splitlines() or ["failed"])[-1]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def ours(u, y, nx=None) -> int:
    return N4SID(nx=nx, max_order=20, block_rows=BLOCK_ROWS if nx else None).fit(Record(u, y, fs=1.0)).nx_


def nfoursid_fit(u, y, nx: int = 10) -> int:
    import pandas as pd
    from nfoursid.nfoursid import NFourSID

    df = pd.DataFrame(np.hstack([u, y]), columns=["u1", "u2", "y1", "y2"])
    m = NFourSID(df, output_columns=["y1", "y2"], input_columns=["u1", "u2"], num_block_rows=BLOCK_ROWS)
    m.subspace_identification()
    ss, _ = m.system_identification(rank=nx)
    return int(ss.a.shape[0])


def test_n4sid_1e6_samples_2x2_10th_order(benchmark):
    u, y = make_data(1_000_000)
    rec = Record(u, y, fs=1.0)
    model = N4SID(max_order=20)
    cpu = []

    def run():
        c0 = time.process_time()
        model.fit(rec)
        cpu.append(time.process_time() - c0)

    benchmark.pedantic(run, rounds=1, iterations=1, warmup_rounds=0)
    seconds = benchmark.stats.stats.max
    A = make_system()[0]
    true, est = np.sort(np.abs(np.linalg.eigvals(A))), np.sort(np.abs(np.linalg.eigvals(model.A_)))
    mem = _fresh_process(1_000_000, "ours")
    info = {
        "n": 1_000_000,
        "nx": model.nx_,
        "seconds": seconds,
        "cpu_seconds": cpu[0],
        "subprocess": mem,
        "target_s": 30.0,
        "items": 1_000_000,
        "block_rows": model.block_rows_,
        "max_pole_modulus_error": float(np.max(np.abs(true - est))),
    }
    benchmark.extra_info.update(info)
    print(
        f"\nn4sid N=1e6, 2x2, order chosen {model.nx_}: {seconds:.2f} s in-process ({cpu[0]:.2f} s CPU); fresh process "
        f"{mem.get('seconds', float('nan')):.2f} s, peak RSS {mem.get('peak_rss_mb', float('nan')):.0f} MB "
        f"(after making the data {mem.get('data_rss_mb', float('nan')):.0f} MB; the fit's own peak allocation "
        f"{mem.get('fit_peak_alloc_mb', float('nan')):.0f} MB)"
    )
    assert model.nx_ == 10
    assert info["max_pole_modulus_error"] < 1e-3
    # On the shared 2-core machine the wall time counts other jobs' time slices (measured at load 10: 23 s wall,
    # 9.3 s CPU); the process's CPU time is the code's own cost on an idle machine, and the goal is checked on it.
    assert cpu[0] < 30.0
    assert mem["peak_rss_mb"] < 4096


def test_n4sid_vs_nfoursid_1e4(benchmark):
    """Time ratio at N = 1e4, the largest of 1e4/1e5 that nfoursid can do: at N = 1e5 its SVD with full matrices
    asks for an N × N array (74.5 GiB), recorded from a fresh process in ``extra_info["nfoursid_1e5"]``."""
    pytest.importorskip("nfoursid", reason="nfoursid not installed: no side-by-side timing")
    u, y = make_data(10_000)
    ours(u, y, nx=10)  # numba cache warm
    benchmark.pedantic(lambda: ours(u, y, nx=10), rounds=3, iterations=1)
    t_ours = benchmark.stats.stats.min
    nfoursid_fit(u[:2000], y[:2000])  # imports outside the timing
    t0 = time.perf_counter()
    nfoursid_fit(u, y)
    t_ref = time.perf_counter() - t0
    info = {
        "n": 10_000,
        "ours_s": t_ours,
        "nfoursid_s": t_ref,
        "ratio": t_ref / t_ours,
        "block_rows": BLOCK_ROWS,
        "reference": "nfoursid 1.0 (same block rows and order)",
        "nfoursid_1e5": _fresh_process(100_000, "nfoursid"),
    }
    benchmark.extra_info.update(info)
    print(
        f"\nPO-MOESP N=1e4 2x2 order 10, i={BLOCK_ROWS}: ours {t_ours:.3f} s, nfoursid {t_ref:.2f} s, "
        f"ratio {info['ratio']:.1f}x; nfoursid at N=1e5: {info['nfoursid_1e5']}"
    )


@pytest.mark.slow
def test_nfoursid_1e6_fresh_process(benchmark):
    """nfoursid on the 1e6-sample problem in a fresh process (it fails for memory; the error is recorded)."""
    pytest.importorskip("nfoursid", reason="nfoursid not installed")
    res = {}

    def run():
        res.update(ref=_fresh_process(1_000_000, "nfoursid"), ours=_fresh_process(1_000_000, "ours"))

    benchmark.pedantic(run, rounds=1, iterations=1, warmup_rounds=0)
    benchmark.extra_info.update(res)
    print(f"\nN=1e6 fresh processes: ours {res['ours']}, nfoursid {res['ref']}")
