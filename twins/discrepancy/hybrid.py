"""The remainder a diagnosis could not name, modelled: the hybrid twin of an ``unexplained`` verdict.

When the rounds end with the validation residual far above the noise (:func:`.unexplained.outside`, the
``unexplained`` verdict), :func:`hybrid_block` fits a :class:`twins.hybrid.HybridTwin` — the final configuration
plus a black-box remainder on [u, ŷ_twin] — to the estimation record and simulates the validation record with it
(free run, as the continuation of the estimation record where it continues it, as every prediction of the
diagnosis). The JSON block ``hybrid`` reports the identifier, its settings, the validation R² and NRMSE of the
twin alone and of the hybrid, and ``share_taken``: the share of the twin's validation residual power
(the discrepancy) that the remainder model removes, 1 − SSE_hybrid/SSE_twin (negative when it makes the free run
worse — reported as measured). The verdict is not changed: a black-box remainder names no physical cause.
"""

from __future__ import annotations

import time
from typing import Any, cast

import numpy as np

from sysid.errors import ConfigError, DataError
from sysid.evaluation.metrics import nrmse, r2
from twins.base import Twin
from twins.hybrid import HybridTwin

from .prediction import INITIAL_KEY, deterministic, simulate_val, sse
from .trials import Stage

__all__ = ["hybrid_block", "hybrid_text"]


def hybrid_block(inp: Any, stage: Stage, skip: int) -> tuple[dict[str, Any], HybridTwin | None]:
    """Fit the hybrid twin on ``inp.est`` beside the configuration of ``stage``; its JSON block and the twin
    (None when no remainder model could be fitted: the block then holds ``error``)."""
    t0 = time.perf_counter()
    est, val = inp.est, inp.val
    y = np.asarray(val.output, float).reshape(-1)
    before = {"r2_val": float(stage.r2_val), "nrmse_val": float(stage.nrmse_val)}
    try:
        hy = HybridTwin(deterministic(stage.twin)).fit(est, skip=skip)
    except (ConfigError, DataError, ValueError, np.linalg.LinAlgError) as exc:
        return {"fitted": False, "error": str(exc), "before": before, "seconds": time.perf_counter() - t0}, None
    start = val.meta.get(INITIAL_KEY)
    if start:  # a separate validation record's start: handed back starting where its scored prediction did
        hy = hy.with_params(**start)
    yh = simulate_val(cast(Twin, hy), est, val)
    ok = bool(np.all(np.isfinite(yh[skip:])))
    s0, s1 = stage.sse_val, sse(y, yh, skip)
    after = {
        "r2_val": r2(y, yh, skip) if ok else float("-inf"),
        "nrmse_val": nrmse(y, yh, skip) if ok else float("inf"),
    }
    block = {
        "fitted": True,
        **hy.describe(),
        "candidates": hy.fit_table_,
        "before": before,
        "after": after,
        "share_taken": float(1.0 - s1 / s0) if s0 > 0 and np.isfinite(s1) else float("-inf"),
        "note": "black-box remainder on [u, twin output]: it models what the catalog could not name and names no "
        "physical cause",
        "seconds": time.perf_counter() - t0,
    }
    return block, hy


def hybrid_text(block: dict[str, Any]) -> str:
    """One line for the text report."""
    if not block.get("fitted"):
        return f"hybrid twin: no remainder model ({block.get('error', '')})"
    b, a = block["before"], block["after"]
    return (
        f"hybrid twin (twin + {block['identifier']} remainder on u and the twin's output): validation R2 "
        f"{b['r2_val']:.4g} -> {a['r2_val']:.4g}, NRMSE {b['nrmse_val']:.4g} -> {a['nrmse_val']:.4g}; the "
        f"remainder takes {100 * block['share_taken']:.1f} % of the discrepancy (no physical cause named)"
    )
