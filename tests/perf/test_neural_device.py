"""GPU against CPU for the simulation-error identifiers: fit time on the benchmark data and settings they are scored
with, the same model on every device.

Each case is fitted on the CPU (one torch thread, the library's default: the reference), on CUDA with
``ss-encoder``'s CUDA graphs (the default there) and, for ``ss-encoder``, on CUDA eagerly (``cuda_graphs=false``:
every kernel launched from Python, as before the graphs). A short budget of epochs stands in for the full training
(the cost per epoch does not change along it); the CUDA benchmarks skip on a machine without CUDA:

- ``ss-encoder`` on Bouc–Wen (its settings, 5 of 150 epochs): 40 960 estimation samples, 50-step sections,
  batches of 256 — and of 2048, the batch a GPU is said to need;
- ``ss-encoder`` on Silverbox (its settings, 3 of 60 epochs): 65 062 samples, a 13 000-sample hold-out run per epoch;
- ``wh-net`` on Wiener–Hammerstein (its settings, 50 epochs of 16 × 1000-sample sections).

Every benchmark names its CPU case as ``reference`` (the summary prints the speed-up) and stores the best hold-out
RMSE (normalised units); a CUDA fit must match the CPU's to 1e-3 relative (float32 training on both devices).
Run on a GPU machine: ``python -m pytest tests/perf/test_neural_device.py --benchmark-enable -p no:cacheprovider
-o addopts=""``.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from benchmarks.datasets import load_dataset  # noqa: E402
from benchmarks.scoring.settings import NORMALISE, settings_for  # noqa: E402
from sysid.registry import get_identifier  # noqa: E402

CASES = {  # case: (identifier, dataset, option overrides)
    "ss-encoder-bouc-wen": ("ss-encoder", "bouc-wen", {"epochs": 5}),
    "ss-encoder-bouc-wen-b2048": ("ss-encoder", "bouc-wen", {"epochs": 5, "batch_size": 2048}),
    "ss-encoder-silverbox": ("ss-encoder", "silverbox", {"epochs": 3}),
    "wh-net-wiener-hammerstein": ("wh-net", "wiener-hammerstein", {"epochs": 50}),
}
MODES = {"cpu": {"device": "cpu"}, "cuda": {"device": "cuda"}, "cuda-eager": {"device": "cuda", "cuda_graphs": False}}
_best: dict[str, float] = {}
needs_cuda = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")


def _fit(case: str, mode: str, epochs: int | None = None):
    identifier, dataset, extra = CASES[case]
    params = {**settings_for(identifier, dataset), **extra, **MODES[mode]}
    params.pop(NORMALISE, None)
    if epochs is not None:
        params["epochs"] = epochs
    model = get_identifier(identifier)(**params)
    t0 = time.perf_counter()
    model.fit(load_dataset(dataset).est_records)
    if mode != "cpu":
        torch.cuda.synchronize()
    return model, time.perf_counter() - t0


def _run(benchmark, case: str, mode: str) -> float:
    _fit(case, mode, epochs=1)  # data cache, torch's first calls, the CUDA context and graphs' first capture
    out: dict = {}

    def timed():
        out["model"], out["seconds"] = _fit(case, mode)

    benchmark.pedantic(timed, rounds=1, iterations=1)
    model = out["model"]
    best = float(np.nanmin(model.val_history_))
    benchmark.extra_info.update(
        {
            "case": case,
            "mode": mode,
            "fit_seconds": out["seconds"],
            "epochs_run": len(model.loss_history_),
            "best_holdout_rmse": best,
            "cuda_graphs": bool(getattr(model, "cuda_graphs_", False)),
        }
    )
    return best


@pytest.mark.parametrize("case", sorted(CASES))
def test_fit_cpu_reference(benchmark, case):
    _best[case] = _run(benchmark, case, "cpu")
    assert np.isfinite(_best[case])


@needs_cuda
@pytest.mark.parametrize("mode", ["cuda", "cuda-eager"])
@pytest.mark.parametrize("case", sorted(CASES))
def test_fit_cuda(benchmark, case, mode):
    if mode == "cuda-eager" and not case.startswith("ss-encoder"):
        pytest.skip("only ss-encoder has CUDA graphs")
    benchmark.extra_info.update({"reference": f"test_fit_cpu_reference[{case}]", "gpu": torch.cuda.get_device_name(0)})
    best = _run(benchmark, case, mode)
    if case.startswith("ss-encoder"):
        assert benchmark.extra_info["cuda_graphs"] == (mode == "cuda")
    cpu = _best.get(case)
    if cpu is not None:  # the same model to float rounding
        assert abs(best - cpu) <= 1e-3 * cpu
