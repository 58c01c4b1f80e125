"""Validation that validates: the validation record must carry excitation.

A validation record whose input holds still (u ≈ constant, e.g. the 0 V rest at the end of a step test)
scores only the twin's response to nothing: offset, drift and the tail of creep. Every configuration that
matches the last level passes it, so it validates nothing. Criterion (documented, used for both the default
split and a ``--val`` record):

    excitation(seg) = std(u_seg) / std(u_all)  ≥  ``MIN_EXCITATION`` (0.1)

where ``u_all`` is the input of the whole record (estimation + validation). A single step inside the segment
passes (std = step·√(p(1−p)) for a step at a fraction p of the segment: ≥ 0.1·step for 1 % ≤ p ≤ 99 %); a hold
gives 0. When the default split (``fraction``, 60 % estimation) leaves an unexcited part, the other fractions
of :data:`FRACTIONS` are tried in order, and the first one where both parts are excited is used and stated;
when none is, the diagnosis asks for ``--val``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import DataError

__all__ = ["MIN_EXCITATION", "FRACTIONS", "excitation", "choose_split", "check_validation"]

#: smallest std(u_segment)/std(u_all) that counts as excitation
MIN_EXCITATION = 0.1
#: estimation fractions tried after the default one, in order
FRACTIONS = (0.6, 0.5, 0.7, 0.4, 0.8, 0.3, 0.9, 0.2)


def excitation(u_seg: np.ndarray, u_all: np.ndarray) -> float:
    """std(u_seg)/std(u_all) (0 for a constant segment; ``inf`` when the whole record is constant and the
    segment too: the caller treats a constant record separately)."""
    s_all = float(np.std(np.asarray(u_all, float)))
    s = float(np.std(np.asarray(u_seg, float)))
    if s_all <= 0:
        return 0.0
    return s / s_all


def choose_split(data: Record, fraction: float = 0.6) -> tuple[Record, Record, dict[str, Any]]:
    """(estimation, validation, info) for ``data``: the default split at ``fraction`` when both parts carry
    excitation, else the first excited split of :data:`FRACTIONS` (``info['note']`` says which and why).

    Raises DataError when the input is constant or no split leaves both parts excited (then a ``--val``
    record is needed)."""
    u = np.asarray(data.u, float)
    if u.ndim != 1:
        est, val = data.split(fraction=fraction)
        return est, val, {"fraction": fraction, "moved": False}
    if not float(np.std(u)) > 0:
        raise DataError(
            f"{data.source}: the input u is constant over the whole record: nothing excites the twin, "
            "nothing can be diagnosed"
        )
    order = [float(fraction)] + [f for f in FRACTIONS if abs(f - float(fraction)) > 1e-9]
    tried = []
    for f in order:
        k = int(round(len(u) * f))
        if not 0 < k < len(u):
            continue
        xe, xv = excitation(u[:k], u), excitation(u[k:], u)
        tried.append((f, xe, xv))
        if xe >= MIN_EXCITATION and xv >= MIN_EXCITATION:
            est, val = data.split(index=k)
            info: dict[str, Any] = {
                "fraction": f,
                "index": k,
                "excitation_est": xe,
                "excitation_val": xv,
                "moved": f != float(fraction),
            }
            if info["moved"]:
                f0, xe0, xv0 = tried[0]
                part = "validation" if xv0 < MIN_EXCITATION else "estimation"
                info["note"] = (
                    f"the default split at {100 * f0:.0f} % leaves the {part} part without excitation "
                    f"(std(u) {min(xe0, xv0):.3g}× the record's, u ≈ constant: a hold); split at "
                    f"{100 * f:.0f} % instead (validation: last {100 * (1 - f):.0f} %, "
                    f"t ≥ {k / data.fs:.4g} s)"
                )
            return est, val, info
    raise DataError(
        f"{data.source}: no split of the record leaves excitation in both estimation and validation "
        f"(tried estimation fractions {', '.join(f'{f:g}' for f, _, _ in tried)}; std(u) of a part must "
        f"be ≥ {MIN_EXCITATION:g}× the record's); give a validation record with --val"
    )


def check_validation(est: Record, val: Record) -> dict[str, Any]:
    """Refuse a separate validation record whose input holds still (see the module docstring)."""
    ue, uv = np.asarray(est.u, float), np.asarray(val.u, float)
    if ue.ndim != 1 or uv.ndim != 1:
        return {"excitation_val": float("nan")}
    u_all = np.concatenate([ue, uv])
    x = excitation(uv, u_all)
    if not x >= MIN_EXCITATION or not math.isfinite(x):
        raise DataError(
            f"{val.source}: the validation input carries no excitation (std(u) {x:.3g}× the records' "
            f"together, u ≈ constant {float(np.mean(uv)):.4g}); it would validate nothing: give a "
            "validation record whose input moves"
        )
    return {"excitation_val": x}
