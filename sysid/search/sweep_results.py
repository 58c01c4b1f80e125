"""A sweep's results read back from its study: per-run rows (:func:`collect`), mean and SD per configuration
(:func:`summarise`), JSON lines (:func:`export_jsonl`) and the R² histograms of one configuration."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from sysid.search.sweep import R2_KEYS, _clean, _open_storage

__all__ = ["collect", "summarise", "export_jsonl", "plot_r2_distribution"]


def collect(url: str, study_name: str) -> list[dict[str, Any]]:
    """All finished runs of a study (one dict per run, first complete trial of each configuration)."""
    import optuna
    from optuna.trial import TrialState

    st = optuna.load_study(study_name=study_name, storage=_open_storage(url))
    seen: set[str] = set()
    runs: list[dict[str, Any]] = []
    for t in sorted(st.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)), key=lambda t: t.number):
        key = t.user_attrs.get("config_key")
        if key is None or key in seen:
            continue
        seen.add(key)
        for run in t.user_attrs.get("runs", []):
            runs.append({"trial": t.number, "config_key": key, **run})
    return runs


def _stat(values: list[float | None]) -> tuple[float | None, float | None, int]:
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if v.size == 0:
        return None, None, 0
    return float(v.mean()), (float(v.std(ddof=1)) if v.size > 1 else 0.0), int(v.size)


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per configuration: mean/SD of R² (one-step / free-run × estimation / validation), parameters, runs.

    ``configs`` is ordered best first by mean validation free-run R² (Table 5.5 lists the same ascending);
    ``best_runs`` are the individual runs of the best configuration (Table 5.6 analogue).
    """
    by: dict[str, list[dict[str, Any]]] = {}
    for run in runs:
        by.setdefault(run["config_key"], []).append(run)
    configs = []
    for key, rs in by.items():
        entry: dict[str, Any] = {
            "config": rs[0]["config"],
            "config_key": key,
            "n_parameters": rs[0]["n_parameters"],
            "runs": len(rs),
            "fit_seconds_mean": float(np.mean([r["fit_seconds"] for r in rs])),
        }
        for part, mode in R2_KEYS:
            mean, sd, n_ok = _stat([r[part][mode]["r2"] for r in rs])
            tag = f"{'est' if part == 'estimation' else 'val'}_{'osa' if mode == 'one_step' else 'frs'}"
            entry[f"r2_{tag}_mean"] = mean
            entry[f"r2_{tag}_sd"] = sd
            if mode == "free_run":
                entry[f"diverged_{tag}"] = len(rs) - n_ok
        configs.append(entry)
    configs.sort(key=lambda e: -np.inf if e["r2_val_frs_mean"] is None else e["r2_val_frs_mean"], reverse=True)
    best = configs[0]["config_key"] if configs else None
    best_runs = sorted(
        (r for r in runs if r["config_key"] == best),
        key=lambda r: -np.inf if r["validation"]["free_run"]["r2"] is None else r["validation"]["free_run"]["r2"],
    )
    return {
        "n_configs": len(configs),
        "n_runs": len(runs),
        "configs": configs,
        "best": configs[0] if configs else None,
        "best_runs": [
            {
                "repeat": r["repeat"],
                "seed": r["seed"],
                "r2_est_osa": r["estimation"]["one_step"]["r2"],
                "r2_est_frs": r["estimation"]["free_run"]["r2"],
                "r2_val_osa": r["validation"]["one_step"]["r2"],
                "r2_val_frs": r["validation"]["free_run"]["r2"],
            }
            for r in best_runs
        ],
    }


def export_jsonl(runs: list[dict[str, Any]], path: str | Path) -> Path:
    """One JSON object per run (config, seed, n_parameters, fit_seconds, estimation/validation scores)."""
    from sysid.data.safeio import atomic_write_text

    return atomic_write_text(path, "".join(json.dumps(_clean(run)) + "\n" for run in runs))


def plot_r2_distribution(runs: list[dict[str, Any]], config_key_: str, path: str | Path) -> Path:
    """Fig. 5.13 analogue: histograms of free-run R² in estimation and validation with fitted normal curves."""
    from sysid.report.plots import pyplot, save_and_close

    plt = pyplot()
    rs = [r for r in runs if r["config_key"] == config_key_]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, part, title in zip(axes, ("estimation", "validation"), ("(a) estimation", "(b) validation")):
        v = np.array([r[part]["free_run"]["r2"] for r in rs if r[part]["free_run"]["r2"] is not None], dtype=float)
        v = v[np.isfinite(v)]
        if v.size:
            ax.hist(v, bins=max(5, min(30, v.size // 2)), density=True, alpha=0.6)
            if v.size > 1 and v.std() > 0:
                x = np.linspace(v.min(), v.max(), 200)
                ax.plot(x, np.exp(-0.5 * ((x - v.mean()) / v.std(ddof=1)) ** 2) / (v.std(ddof=1) * np.sqrt(2 * np.pi)))
            ax.set_title(f"{title}: mean {v.mean():.4f}, SD {v.std(ddof=1) if v.size > 1 else 0:.4f}, {v.size} runs")
        ax.set_xlabel("free-run R²")
    fig.suptitle(config_key_)
    fig.tight_layout()
    return save_and_close(fig, path, dpi=110)
