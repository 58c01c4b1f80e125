"""Simulate an exported FMU with fmpy on an input array and compare it with the native twin."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from sysid.errors import DataError

__all__ = ["fmu_simulate", "relative_rms"]


def fmu_simulate(
    path: str | Path, u: np.ndarray, fs: float, start_values: Mapping[str, Any] | None = None, model_description=None
) -> np.ndarray:
    """Output of the FMU at ``path`` (a ``.fmu`` or a folder it was extracted to) for the input samples ``u`` at ``fs``
    [Hz], aligned with ``simulate``.

    fmpy co-simulates with communication step ``output_interval = 1/fs`` (physics notes C.4) for
    ``len(u)`` steps; the FMU's output at ``t_{k+1}`` is the twin's sample ``k`` (see
    :mod:`twins.fmu.slave`), so the returned array is ``y(t_1) ... y(t_N)``: element ``k`` belongs to ``u[k]``.
    """
    import fmpy

    u = np.asarray(u, dtype=float)
    if u.ndim != 1 or len(u) == 0 or not np.all(np.isfinite(u)):
        raise DataError("u must be a non-empty finite 1-D array")
    n = len(u)
    t = np.arange(n + 1) * (1.0 / fs)  # the same grid fmpy steps on (start + k * output_interval)
    # one extra sample so that the input is defined at every communication point t_0 .. t_N
    sig = np.zeros(n + 1, dtype=[("time", float), ("u", float)])
    sig["time"] = t
    sig["u"][:n] = u
    sig["u"][n] = u[-1]
    res = fmpy.simulate_fmu(
        str(path),
        stop_time=n / fs,
        output_interval=1.0 / fs,
        input=sig,
        output=["y"],
        start_values=dict(start_values or {}),
        model_description=model_description,
    )
    y = np.asarray(res["y"], dtype=float)
    if len(y) != n + 1:
        raise RuntimeError(f"fmpy returned {len(y)} samples, expected {n + 1}")
    return y[1:]


def relative_rms(y: np.ndarray, ref: np.ndarray) -> float:
    """``rms(y - ref) / rms(ref)``."""
    y, ref = np.asarray(y, float), np.asarray(ref, float)
    den = float(np.sqrt(np.mean(ref**2)))
    return float(np.sqrt(np.mean((y - ref) ** 2))) / den if den > 0 else float(np.sqrt(np.mean((y - ref) ** 2)))
