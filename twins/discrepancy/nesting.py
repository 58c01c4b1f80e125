"""Nested candidates: a richer effect that contains a simpler one of the same round (``EffectSpec.nests``) leads
only where its extra parameters earn their place.

Stribeck friction with no static excess is Coulomb friction, so whenever Coulomb friction is what the data hold
the Stribeck trial fits at least as well and ranks first by gain. The F-test of the two nested fits on the
validation residual (:func:`.prediction.significance` with the difference of their parameter counts) decides:
where the richer fit is not significantly better at ``alpha``, the simpler significant trial leads the round.
"""

from __future__ import annotations

from twins.base import Twin

from . import features as ft
from .prediction import significance
from .trials import Trial

__all__ = ["prefer_simpler"]


def prefer_simpler(trials: list[Trial], twin: Twin, val_y, skip: int, alpha: float) -> None:
    """Move the simplest adequate member of the leader's nesting chain to the front of ``trials`` (best first,
    significant first); in place."""
    moved = True
    while moved and trials:
        moved = False
        top = trials[0]
        nests = getattr(twin.EFFECTS[top.effect], "nests", ())
        for i, tr in enumerate(trials[1:], start=1):
            if tr.effect not in nests or not tr.significant or tr.n_added >= top.n_added:
                continue
            n_eff = ft.effective_samples(val_y[skip:] - top.yhat_val[skip:])
            if significance(tr.sse_val, top.sse_val, n_eff, top.n_added - tr.n_added) >= alpha:
                trials.insert(0, trials.pop(i))
                moved = True
                break
