"""The benchmark's regression check for CI: a stratified sample of the stored run, diagnosed again.

:func:`choose_sample` picks, from a full run's rows, the cheapest cases of each group the headline rates are
made of (catalog mechanisms at ≥ 3× their detection limit, per family; mechanisms outside the catalog that were
detected; no mechanism) within a CPU budget. :func:`compare` sets the sample's rates now against the same cases'
stored outcomes: a group fails when its rate drops by more than the sampling error of the full run's rate for a
sample of its size (2 σ; a group whose full-run rate is 1 allows no drop); the confident wrong names fail when
their count grows beyond 2 σ.
"""

from __future__ import annotations

import math
from typing import Any

from .score import _acceptable, _size, current, outcome

__all__ = ["group_of", "choose_sample", "compare"]


def group_of(row: dict[str, Any], limits: dict[str, float | None]) -> str | None:
    """The headline group of a row, or None where it counts in none of them."""
    fam, mech = row["case"]["family"], row["case"]["mechanism"]
    if mech is None:
        return "none"
    if _acceptable(row):
        dl = limits.get(f"{fam}:{mech}")
        return f"catalog:{fam}" if dl is not None and _size(row) >= 3 * dl else None
    return "outside" if row.get("verdict") != "none" else None


def choose_sample(
    rows: list[dict[str, Any]], limits: dict[str, float | None], per_group: int = 5, budget_cpu_s: float = 450.0
) -> list[int]:
    """Seeds of the cheapest ``per_group`` cases of each group (by their stored CPU seconds), within the budget:
    taken in rounds — the cheapest of every group, then the second of every group, … — so that a group of costly
    cases (the acoustic twin's) still has its cheapest case in the sample."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        if "error" in r:
            continue
        g = group_of(r, limits)
        if g is not None:
            groups.setdefault(g, []).append(r)
    ranked = {g: sorted(v, key=lambda r: r["cpu_s"])[:per_group] for g, v in groups.items()}
    order = [ranked[g][i] for i in range(per_group) for g in sorted(ranked) if i < len(ranked[g])]
    seeds, spent = [], 0.0
    for r in order:
        if spent + r["cpu_s"] <= budget_cpu_s:
            seeds.append(int(r["case"]["seed"]))
            spent += r["cpu_s"]
    return sorted(seeds)


def compare(
    now: list[dict[str, Any]],
    stored: list[dict[str, Any]],
    limits: dict[str, float | None],
    full_rates: dict[str, float],
) -> dict[str, Any]:
    """Per group: stored and current right rate of the sample, the allowed drop, pass/fail (module docstring)."""
    ref = {r["case"]["seed"]: current(r) for r in stored}
    now = [current(r) for r in now]
    by_group: dict[str, list[tuple[bool, bool]]] = {}
    wrong_now = wrong_then = 0
    for r in now:
        old = ref.get(r["case"]["seed"])
        if old is None:
            continue
        g = group_of(old, limits)
        o_now, o_then = outcome(r), outcome(old)
        wrong_now += o_now["confident_wrong"]
        wrong_then += o_then["confident_wrong"]
        if g is not None:
            by_group.setdefault(g, []).append((o_now["outcome"] == "right", o_then["outcome"] == "right"))
    rows, ok = [], True
    for g, pairs in sorted(by_group.items()):
        n = len(pairs)
        r_now, r_then = sum(a for a, _ in pairs) / n, sum(b for _, b in pairs) / n
        p = full_rates.get(g, r_then)
        allowed = 2.0 * math.sqrt(max(p * (1.0 - p), 0.0) / n)  # no floor: a group of one case can fail too
        passed = r_now >= r_then - allowed - 1e-12
        ok &= passed
        row = {"group": g, "n": n, "stored": r_then, "now": r_now, "allowed_drop": allowed, "passed": passed}
        rows.append(row)
    n_all = max(len(now), 1)
    p_w = max(wrong_then, 1) / n_all
    wrong_ok = wrong_now <= wrong_then + max(2.0 * math.sqrt(p_w * (1 - p_w) * n_all), 1.0)
    ok &= wrong_ok
    return {
        "passed": ok,
        "groups": rows,
        "confident_wrong": {"stored": wrong_then, "now": wrong_now, "passed": wrong_ok},
    }
