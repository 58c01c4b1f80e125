"""Budgets of ``piezotwin thesis``: the dissertation's (full), one that fits a shared 2-core machine (middle) and
one for the test suite (quick). A :class:`Tier` is plain data; each protocol module reads only its own fields.

The protocols themselves (lags, layers, activations, learning rate 1e-4, batch 128, RMSprop, the data sets'
recipes) are the same in every tier; a tier changes only epochs, repeats and, for ``quick``, record lengths.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

from sysid.errors import ConfigError

__all__ = ["Tier", "TIERS", "tier", "with_repeats"]


@dataclass(frozen=True)
class Tier:
    """One budget. Epochs: Table 4.1 (100) for the cantilever, Table 5.3 (75) for the acoustic networks."""

    name: str
    cantilever_epochs: int  # Table 4.1: 100
    cantilever_repeats: int  # issue: ≥ 5 per architecture (the dissertation does not say how many it ran)
    acoustic_epochs: int  # Table 5.3: 75
    acoustic_repeats: int  # Tables 5.4/5.5: means of 5 runs
    table_5_6_runs: int  # Table 5.6: 5 runs
    fig_5_13_runs: int  # Figure 5.13: 75 runs
    narx_epochs: int  # Table 5.2's NARX networks (trained here like the others, see acoustic.py)
    narx_repeats: int
    cantilever_duration_s: float | None = None  # None: the protocol's 8 s multisine
    short_records: bool = False  # quick: 1-period sines above 1 Hz, shorter acoustic simulation margin

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


TIERS: dict[str, Tier] = {
    "full": Tier("full", 100, 5, 75, 5, 5, 75, 75, 5),
    "middle": Tier("middle", 100, 3, 75, 3, 5, 20, 75, 3),  # what fits a shared 2-core machine
    "quick": Tier("quick", 1, 1, 1, 1, 1, 2, 1, 1, cantilever_duration_s=0.5, short_records=True),
}


def tier(name: str) -> Tier:
    if name not in TIERS:
        raise ConfigError(f"unknown tier {name!r}; valid: {', '.join(TIERS)}")
    return TIERS[name]


def with_repeats(t: Tier, repeats: int) -> Tier:
    """``--repeats N``: every repeated experiment runs N times (Table 5.6 and Fig. 5.13 at least N)."""
    if repeats < 1:
        raise ConfigError(f"--repeats must be ≥ 1, got {repeats}")
    return replace(
        t,
        cantilever_repeats=repeats,
        acoustic_repeats=repeats,
        narx_repeats=repeats,
        table_5_6_runs=max(repeats, t.table_5_6_runs) if t.name != "quick" else repeats,
        fig_5_13_runs=max(repeats, t.fig_5_13_runs),
    )
