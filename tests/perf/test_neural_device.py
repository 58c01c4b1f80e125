"""GPU against CPU for the simulation-error identifiers, on the benchmark data and settings they are scored with.

Each CUDA benchmark names its CPU twin (same data, options and seed; one torch thread, the library's default) as
its reference, so the summary prints the speed-up; the CUDA ones skip on a machine without CUDA. A short budget of
epochs stands in for the full training (the cost per epoch does not change along it):

- ss-encoder on Bouc–Wen (its full settings, 5 of 150 epochs): 40 000 estimation samples, 50-step sections,
  batches of 256;
- wh-net on Wiener–Hammerstein (full settings, 50 epochs): 100 000 samples, full batch.

Run on a GPU machine: ``python -m pytest tests/perf/test_neural_device.py --benchmark-enable -p no:cacheprovider
-o addopts=""``. Both devices must give the same model to float rounding: the test checks the free-run RMSE.
"""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from benchmarks.datasets import load_dataset  # noqa: E402
from benchmarks.scoring.core import score_pair  # noqa: E402
from benchmarks.scoring.settings import settings_for  # noqa: E402

CASES = {"ss-encoder": ("bouc-wen", 5), "wh-net": ("wiener-hammerstein", 50)}
_rmse: dict[tuple[str, str], float] = {}


def _fit(identifier: str, device: str) -> float:
    dataset, epochs = CASES[identifier]
    params = {**settings_for(identifier, dataset), "epochs": epochs, "device": device}
    rows, _ = score_pair(identifier, load_dataset(dataset), params=params, seeds=[0])
    return float(rows[0]["free_run"]["rmse"])


@pytest.mark.parametrize("identifier", sorted(CASES))
def test_fit_cpu_reference(benchmark, identifier):
    benchmark.extra_info.update({"device": "cpu", "dataset": CASES[identifier][0], "epochs": CASES[identifier][1]})
    _fit(identifier, "cpu")  # data cache, numba compilation of the scoring and torch's first calls outside the timing
    _rmse[(identifier, "cpu")] = benchmark.pedantic(lambda: _fit(identifier, "cpu"), rounds=1, iterations=1)
    assert np.isfinite(_rmse[(identifier, "cpu")])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
@pytest.mark.parametrize("identifier", sorted(CASES))
def test_fit_cuda(benchmark, identifier):
    benchmark.extra_info.update(
        {
            "device": "cuda",
            "dataset": CASES[identifier][0],
            "epochs": CASES[identifier][1],
            "reference": f"test_fit_cpu_reference[{identifier}]",
            "gpu": torch.cuda.get_device_name(0),
        }
    )
    _fit(identifier, "cuda")  # CUDA context and kernels loaded outside the timing
    rmse = benchmark.pedantic(lambda: _fit(identifier, "cuda"), rounds=1, iterations=1)
    cpu = _rmse.get((identifier, "cpu"))
    if cpu is not None:  # same model to float rounding (float32 training on both devices)
        assert abs(rmse - cpu) <= 1e-4 * cpu
