"""Nested candidates: a richer effect that contains a simpler one of the same round (``EffectSpec.nests``) leads
only where its extra parameters earn their place.

Stribeck friction with no static excess is Coulomb friction, so whenever Coulomb friction is what the data hold
the Stribeck trial fits at least as well and ranks first by gain. Two tests decide, and the simpler significant
trial leads the round when either says the extra freedom is not used:

- the richer fit lies on the special case: its contrast (``EffectSpec.nest_contrast``, e.g. f₊ − f₋ for an
  asymmetric friction) is within :data:`CONTRAST_Z` standard errors of 0, or below :data:`CONTRAST_REL` of the
  listed parameters' summed size (the standard errors of a discontinuous law such as sign(v) come from a
  Jacobian that hardly sees the jump and are too small). This holds even where the simpler trial's own fit
  stopped short of its optimum, so that its validation error alone would make the richer look better;
- the F-test of the two nested fits on the validation residual (:func:`.prediction.significance` with the
  difference of their parameter counts) is not significant at ``alpha``.
"""

from __future__ import annotations

import math

from twins.base import Twin

from . import features as ft
from .prediction import significance
from .trials import Trial

__all__ = ["prefer_simpler", "on_special_case", "CONTRAST_Z", "CONTRAST_REL"]

#: standard errors within which a richer fit's contrast counts as 0 (two-sided, about 95 %)
CONTRAST_Z = 2.0
#: share of the listed parameters' summed size below which a contrast counts as 0 (friction levels 2 % apart)
CONTRAST_REL = 0.02


def on_special_case(trial: Trial, contrast: tuple[tuple[str, float], ...]) -> bool:
    """The trial's fitted contrast Σ w·θ is within :data:`CONTRAST_Z` standard errors of 0 (the errors of the
    parameters taken as independent) or below :data:`CONTRAST_REL` of Σ |θ| over the listed parameters (a weight
    0 lists one for the scale only); False without a contrast or without finite fitted values."""
    if not contrast:
        return False
    try:
        value = sum(w * float(trial.fitted[k]) for k, w in contrast)
        size = sum(abs(float(trial.fitted[k])) for k, _ in contrast)
        var = sum((w * float(trial.stderr.get(k, math.nan))) ** 2 for k, w in contrast if w)
    except (KeyError, TypeError, ValueError):
        return False
    if not (math.isfinite(value) and math.isfinite(size)):
        return False
    return abs(value) <= CONTRAST_REL * size or (math.isfinite(var) and abs(value) <= CONTRAST_Z * math.sqrt(var))


def prefer_simpler(trials: list[Trial], twin: Twin, val_y, skip: int, alpha: float) -> None:
    """Move the simplest adequate member of the leader's nesting chain to the front of ``trials`` (best first,
    significant first); in place."""
    moved = True
    while moved and trials:
        moved = False
        top = trials[0]
        spec = twin.EFFECTS[top.effect]
        nests = getattr(spec, "nests", ())
        for i, tr in enumerate(trials[1:], start=1):
            if tr.effect not in nests or not tr.significant or tr.n_added >= top.n_added:
                continue
            n_eff = ft.effective_samples(val_y[skip:] - top.yhat_val[skip:])
            same = on_special_case(top, getattr(spec, "nest_contrast", ()))
            if same or significance(tr.sse_val, top.sse_val, n_eff, top.n_added - tr.n_added) >= alpha:
                trials.insert(0, trials.pop(i))
                moved = True
                break
