"""Results that must not depend on the CPU they ran on (the regression check's premise).

Each check runs the same computation in fresh processes that differ only in what a different machine would
change: torch's CPU kernel set (``ATEN_CPU_CAPABILITY`` = generic / AVX2) or the BLAS thread count.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

TRAIN = r"""
import json, numpy as np
from sysid.neural.narx_mlp import NARXMLP
from sysid.data.record import Record
rng = np.random.default_rng(0)
u = rng.standard_normal(3000)
y = np.zeros_like(u)
for k in range(2, u.size):  # a mildly nonlinear second-order system
    y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + 0.5 * u[k - 1] + 0.1 * np.tanh(y[k - 1]) ** 2
m = NARXMLP(ny=2, nu=2, hidden=[8, 8], epochs=3, dtype="{dtype}", device="cpu").fit(Record(u=u, y=y, fs=1.0))
print(json.dumps(np.asarray(m.weights_, dtype=np.float64).tolist()))
"""


def _run(code: str, **env: str) -> str:
    full = {**os.environ, **env}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=full, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip().splitlines()[-1]


def _has_avx2() -> bool:
    import torch

    return torch.backends.cpu.get_cpu_capability() in ("AVX2", "AVX512")


@pytest.mark.heavy
@pytest.mark.skipif(not _has_avx2(), reason="needs a CPU with AVX2 to compare torch's AVX2 and generic kernels")
def test_float64_one_step_training_is_the_same_with_generic_and_avx2_kernels():
    """float64 training of the NARX-MLP gives the same weights with torch's generic and AVX2 kernels to ~1e-16
    relative (measured 7e-17: the kernels round reductions differently and one-step training does not amplify
    it); float32 differs ~1e8 times more (measured 2e-8)."""
    import numpy as np

    w = {
        (dt, isa): np.array(json.loads(_run(TRAIN.replace("{dtype}", dt), ATEN_CPU_CAPABILITY=isa)))
        for dt in ("float64", "float32")
        for isa in ("default", "avx2")
    }
    scale = np.abs(w["float64", "avx2"]).max()
    d64 = np.abs(w["float64", "default"] - w["float64", "avx2"]).max() / scale
    d32 = np.abs(w["float32", "default"] - w["float32", "avx2"]).max() / scale
    print(f"relative weight difference generic vs AVX2: float64 {d64:.2e}, float32 {d32:.2e}")
    assert d64 < 1e-9 and d32 > 1e3 * d64


def test_scored_rows_do_not_depend_on_the_blas_thread_count():
    """The scorer pins BLAS to one thread: the same rows with OPENBLAS_NUM_THREADS 1 and 2."""
    code = (
        "import json; from benchmarks import scoring; r = scoring.score(['arx', 'narx-poly'], ['cascaded-tanks'], "
        "quick=True, sysidentpy=False); print(json.dumps([(x['identifier'], x['free_run'], x['one_step']) "
        "for x in r.rows]))"
    )
    a, b = (json.loads(_run(code, OPENBLAS_NUM_THREADS=n)) for n in ("1", "2"))
    assert a == b
