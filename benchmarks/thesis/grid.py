"""Table 5.3's grid of networks on data set 2: a stated random sample of its architectures at full budget.

The grid (Table 5.3): n_u and n_y each in {2…10, 16, 32, 64, 128, 256, 512, 1024}, 1–8 hidden layers of one
width in {2…10, 16, 25, 32, 50, 64, 75, 100, 128, 256, 512, 1024}, sigmoid / ReLU / tanh, RMSprop lr 1e-4,
batch 128, 75 epochs; §5.2: "each model was run twice". :func:`sample` draws configurations uniformly without
replacement (seeded), :func:`grid_tasks` lists their fits on the thesis preset's data set 2 (each a pure
function of its arguments, Dask-safe), :func:`summarize` turns the results into the stored file.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.thesis import acoustic
from benchmarks.thesis.plan import TIERS

__all__ = ["LAGS", "LAYERS", "WIDTHS", "ACTIVATIONS", "RUNS", "grid_size", "sample", "grid_tasks", "summarize"]

LAGS = (*range(2, 11), 16, 32, 64, 128, 256, 512, 1024)
LAYERS = tuple(range(1, 9))
WIDTHS = (*range(2, 11), 16, 25, 32, 50, 64, 75, 100, 128, 256, 512, 1024)
ACTIVATIONS = ("sigmoid", "relu", "tanh")
RUNS = 2  # §5.2: "each model was run twice"
FILE_FORMAT = "piezotwin-thesis-grid/1"


def grid_size() -> int:
    return len(LAGS) ** 2 * len(LAYERS) * len(WIDTHS) * len(ACTIVATIONS)


def config(i: int) -> dict[str, Any]:
    """The ``i``-th configuration of the grid (row-major over n_u, n_y, layers, width, activation)."""
    i, a = divmod(int(i), len(ACTIVATIONS))
    i, w = divmod(i, len(WIDTHS))
    i, layers = divmod(i, len(LAYERS))
    nu, ny = divmod(i, len(LAGS))
    return {
        "nu": LAGS[nu],
        "ny": LAGS[ny],
        "hidden": [WIDTHS[w]] * LAYERS[layers],
        "activation": ACTIVATIONS[a],
    }


def sample(n: int | None, seed: int = 0) -> list[dict[str, Any]]:
    """``n`` configurations drawn uniformly without replacement with ``numpy.random.default_rng(seed)`` (``None``:
    the whole grid, in order)."""
    size = grid_size()
    if n is None or n >= size:
        return [config(i) for i in range(size)]
    idx = np.random.default_rng(seed).choice(size, size=int(n), replace=False)
    return [config(int(i)) for i in sorted(idx)]


def label(c: dict[str, Any]) -> str:
    return f"nu{c['nu']}-ny{c['ny']}-{'x'.join(map(str, c['hidden']))}-{c['activation']}"


def grid_tasks(configs: list[dict[str, Any]], runs: int = RUNS) -> dict[str, tuple]:
    """key -> (function, arguments): ``runs`` trainings of each configuration at the full tier's 75 epochs on the
    thesis preset's data set 2."""
    full = TIERS["full"]
    tasks: dict[str, tuple] = {}
    for c in configs:
        for s in range(runs):
            tasks[f"grid/{label(c)}/{s}"] = (
                acoustic.ds2_task,
                (c["ny"], tuple(c["hidden"]), c["activation"], s, full, 1, None, True, c["nu"]),
            )
    return tasks


def _mean(vals: list[Any]) -> float | None:
    ok = [float(v) for v in vals if v is not None and math.isfinite(v)]
    return float(np.mean(ok)) if ok else None


def summarize(
    configs: list[dict[str, Any]], results: dict[str, dict[str, Any]], seed: int, measured: dict[str, Any]
) -> dict[str, Any]:
    """The stored sample: each configuration's mean R² (estimation and validation FRS, one-step), its runs' CPU
    seconds and parameters; the best by estimation FRS R² (the dissertation chose on estimation, §5.2)."""
    out = []
    for c in configs:
        rr = [r for k, r in results.items() if k.startswith(f"grid/{label(c)}/")]
        out.append(
            {
                **c,
                "label": label(c),
                "runs": len(rr),
                **{k: _mean([r.get(k) for r in rr]) for k in ("r2_frs_est", "r2_frs_val", "r2_osa_est", "r2_osa_val")},
                "n_parameters": int(rr[0]["n_parameters"]) if rr else None,
                "cpu_seconds": float(sum(r.get("cpu_seconds") or 0.0 for r in rr)),
            }
        )
    ranked = sorted((c for c in out if c["r2_frs_est"] is not None), key=lambda c: -c["r2_frs_est"])
    return {
        "format": FILE_FORMAT,
        "grid_size": grid_size(),
        "sample_size": len(configs),
        "seed": int(seed),
        "runs_per_configuration": RUNS,
        "epochs": TIERS["full"].acoustic_epochs,
        "data": "thesis preset, data set 2 (multisine estimation, 1 ms chirp validation)",
        "configurations": out,
        "best": ranked[0]["label"] if ranked else None,
        "cpu_seconds": float(sum(c["cpu_seconds"] for c in out)),
        "measured": measured,
    }


def write(data: dict[str, Any], path: str | Path) -> Path:
    from sysid.data.jsonio import clean_json
    from sysid.data.safeio import atomic_write_text

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(clean_json(data), indent=1, ensure_ascii=False) + "\n")
    return path


def load(path: str | Path) -> dict[str, Any] | None:
    """The stored sample, or ``None`` when absent or not a grid file."""
    path = Path(path)
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return data if isinstance(data, dict) and data.get("format") == FILE_FORMAT else None
