"""Published reference numbers: free-run RMSE on the official test data, in the units of the dataset's y.

The values are collected from the benchmarks' result pages (nonlinearbenchmark.org), the cited papers and the
SysIdentPy book. Each entry says which model reached it;
``kind`` is one of ``linear_baseline`` (best linear approximation, BLA), ``best_published``,
``best_published_grey_box`` and ``sysidentpy`` (SysIdentPy's published polynomial NARX number).
"""

from __future__ import annotations

from typing import Any

MV = 1e-3  # V per mV

# dataset -> test name -> kind -> {value, unit, model}
REFERENCES: dict[str, dict[str, dict[str, dict[str, Any]]]] = {
    "wiener-hammerstein": {
        "test": {
            "linear_baseline": {"value": 44.4 * MV, "unit": "V", "model": "BLA"},
            "best_published": {"value": 0.241 * MV, "unit": "V", "model": "SUBNET"},
            "sysidentpy": {"value": 42.2 * MV, "unit": "V", "model": "polynomial NARX (small model)"},
        },
        "test-official": {
            "best_published": {"value": 0.241 * MV, "unit": "V", "model": "SUBNET (official dataloader's test set)"},
        },
    },
    "silverbox": {
        "multisine": {
            "best_published": {"value": 0.31 * MV, "unit": "V", "model": "GRU"},
            "sysidentpy": {"value": 7.73 * MV, "unit": "V", "model": "polynomial NARX (FROLS)"},
        },
        "arrow": {
            "best_published": {"value": 1.41 * MV, "unit": "V", "model": "SUBNET (arrow full)"},
            "sysidentpy": {"value": 4.15 * MV, "unit": "V", "model": "polynomial NARX (FROLS)"},
        },
        "arrow-no-extrapolation": {
            "best_published": {"value": 0.307 * MV, "unit": "V", "model": "SUBNET encoder (0.307-0.316 mV for nx 4-8)"},
        },
    },
    "cascaded-tanks": {
        "test": {
            "linear_baseline": {"value": 0.75, "unit": "V", "model": "BLA"},
            "best_published": {"value": 0.34, "unit": "V", "model": "black-box"},
            "best_published_grey_box": {"value": 0.18, "unit": "V", "model": "grey-box"},
        },
    },
    "bouc-wen": {
        "multisine": {
            "best_published": {"value": 1.87e-5, "unit": "m", "model": "PNLSS"},
        },
    },
}


def references_for(dataset: str) -> dict[str, dict[str, dict[str, Any]]]:
    """Reference numbers of ``dataset`` by test name (empty when none are published)."""
    return {
        t: {k: dict(v, metric="free-run RMSE") for k, v in kinds.items()}
        for t, kinds in REFERENCES.get(dataset, {}).items()
    }
