"""A parameter study of a twin: one twin parameter takes each of a list of values, the twin is rebuilt with it
and its ``sweep_metrics`` (and ``sweep_spectrum`` where it has one) are collected, one task per value on an
:class:`~benchmarks.execution.Executor`; the rows keep the order of the values. ``piezotwin sweep`` parses its
arguments into :func:`parse_spec` and :func:`sweep`, writes :func:`write_report` and prints the table.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from benchmarks.execution import Executor
from sysid.config import coerce
from sysid.data.jsonio import clean_json
from sysid.data.safeio import atomic_write_text
from sysid.errors import ConfigError
from twins.base import param_info

__all__ = ["parse_spec", "sweep_point", "sweep", "write_report", "public"]


def parse_spec(spec: str, params_cls: type) -> tuple[str, list[Any]]:
    """``"distance_m=0.05,0.1"`` → ("distance_m", [0.05, 0.1]) coerced to the parameter's type."""
    if "=" not in spec:
        raise ConfigError(f"sweep: expected PARAM=v1,v2,..., got {spec!r}")
    name, _, text = spec.partition("=")
    name = name.strip()
    info = param_info(params_cls)
    if name not in info:
        raise ConfigError(f"sweep: unknown parameter {name!r}; valid: {', '.join(info)}")
    values = [v.strip() for v in text.split(",") if v.strip()]
    if not values:
        raise ConfigError(f"sweep: no values given for {name}")
    return name, [coerce(v, info[name].default, name) for v in values]


def sweep_point(twin, name: str, value: Any, protocol: str | None, identify: bool) -> tuple[dict[str, Any], Any]:
    """One value of the study (a task): the row of figures and the spectrum (or None)."""
    tw = twin.with_params(**{name: value})
    row = {"value": value, **tw.sweep_metrics(protocol=protocol, identify=identify)}
    return row, (tw.sweep_spectrum() if hasattr(tw, "sweep_spectrum") else None)


def sweep(
    twin,
    name: str,
    values: list[Any],
    protocol: str | None = None,
    identify: bool = True,
    executor=None,
    progress: bool = False,
) -> dict[str, Any]:
    """Run the study; returns {twin, param, unit, rows: [{value, **metrics}], ...}. One task per value on
    ``executor`` (:class:`benchmarks.execution.Executor`; default in-process), rows in the order of ``values``."""
    if not hasattr(twin, "sweep_metrics"):
        raise ConfigError(f"twin {twin.name} defines no sweep metrics; sweep is available for: acoustic")
    if protocol is not None:
        twin.check_protocol(protocol)
    ex = executor or Executor()
    tw = ex.share(twin)
    results = ex.map(
        sweep_point, [(tw, name, v, protocol, identify) for v in values], desc=f"sweep {name}", progress=progress
    )
    rows = [row for row, _ in results]
    spectra = [(v, *spec) for v, (_, spec) in zip(values, results) if spec is not None]
    unit = param_info(type(twin.params))[name].unit
    return {
        "twin": twin.name,
        "param": name,
        "unit": unit,
        "effects": sorted(twin.effects),
        "rows": rows,
        "_spectra": spectra,
    }


def write_report(result: dict[str, Any], out: Path) -> list[str]:
    """PNG plots (spectra when the twin has them, each numeric figure against the parameter) and the JSON table
    of ``result`` in ``out``; the paths written."""
    import numpy as np

    from sysid.report.plots import pyplot, save_and_close

    plt = pyplot()

    out.mkdir(parents=True, exist_ok=True)
    name, unit = result["param"], result["unit"]
    files = []
    if result["_spectra"]:
        fig, axes = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
        for v, f, curves in result["_spectra"]:
            axes[0].plot(f / 1e3, curves["direct"], label=f"{name}={v}")
            axes[1].plot(f / 1e3, curves["full"], lw=0.6, label=f"{name}={v}")
        axes[0].set_title("direct path (gated) |V_rx/V_oc|")
        axes[1].set_title("with reverberation and configured effects")
        for ax in axes:
            ax.axvspan(900, 1350, color="0.9", zorder=0)
            ax.set_ylabel("dB")
            ax.grid(alpha=0.3)
        axes[1].set_xlabel("frequency [kHz]")
        axes[0].legend(fontsize=7)
        fig.tight_layout()
        path = out / f"sweep_{name}_spectra.png"
        save_and_close(fig, path, dpi=110)
        files.append(str(path))
    keys = [
        k
        for k, v in result["rows"][0].items()
        if k != "value" and isinstance(v, (int, float)) and not isinstance(v, bool)
    ]
    keys += [k for k in ("identified_model_r2",) if k not in keys and any(r.get(k) is not None for r in result["rows"])]
    if keys:
        values = [r["value"] for r in result["rows"]]
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
        x = np.asarray(values, float) if numeric else np.arange(len(values))
        fig, axes = plt.subplots(len(keys), 1, figsize=(7, 2.2 * len(keys)), sharex=True)
        axes = np.atleast_1d(axes)
        for ax, k in zip(axes, keys):
            y = [np.nan if r.get(k) is None else r[k] for r in result["rows"]]
            ax.plot(x, y, "o-" if numeric else "o")
            ax.set_ylabel(k, fontsize=8)
            ax.grid(alpha=0.3)
        if not numeric:
            axes[-1].set_xticks(x, [str(v) for v in values], rotation=30)
        axes[-1].set_xlabel(f"{name} [{unit}]" if unit else name)
        fig.tight_layout()
        path = out / f"sweep_{name}_metrics.png"
        save_and_close(fig, path, dpi=110)
        files.append(str(path))
    path = out / f"sweep_{name}.json"
    atomic_write_text(path, json.dumps(clean_json(public(result)), indent=2))
    files.append(str(path))
    return files


def public(result: dict[str, Any]) -> dict[str, Any]:
    """``result`` without its private entries (the spectra kept for the report)."""
    return {k: v for k, v in result.items() if not k.startswith("_")}
