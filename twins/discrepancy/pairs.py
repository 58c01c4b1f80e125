"""Two effects that mask each other: a round's leader tried jointly with every other candidate.

A greedy round judges each effect alone. Two mechanisms can hide each other: under a square-root outflow law
(two cascaded tanks) a constant sensor offset gains nothing while the upper tank's overflow is missing — the core
parameters bend to stand in for the overflow — and the overflow gains too little alone to pass the F-test on a
slow, strongly correlated residual (its effective number of samples is a few dozen in a thousand). Together
they take a third of the residual (cascaded tanks benchmark, docs/diagnosis.md).

When a round's leader is not significant but lowers the residual, and the residual is still far above the
noise (the ``unexplained`` verdict's rule), :func:`joint_step` adopts the leader tentatively, runs the round
again from there with the leader's parameters refitted beside the core, and judges each pair against the
configuration *before* the leader: an F-test with both effects' parameter counts and the effective samples of
that residual, at ``alpha`` divided by every single and joint trial of the round (Bonferroni), and the relative
gain floor ``min_rel_gain``. The best passing pair names both effects, each marked with ``joint_with`` and the
pair's ``p_joint``; their confidence is at most ½ (a pair found together can trade gain between its members).
:attr:`.options.DiagnoseOptions.pairs` True tries every such leader, False none; None (the default) tries, for a
twin whose class sets ``JOINT_TRIALS`` (a model given by its equations: compiled, cheap to simulate, and its
mechanisms inside the equations are those the core's parameters bend to stand in for), a leader that lowers the
validation NRMSE by at least :data:`PAIR_GAIN` alone — the mark of a mechanism held back by another (the tanks'
overflow: 11.7 %) — and skips the small gains of a configuration that lacks nothing.
"""

from __future__ import annotations

from typing import Any

from . import features as ft
from .candidates import adopt, beyond_noise, round_trials
from .fields import effect_fields
from .prediction import significance
from .ranking import Ranking, cause_from, rank_round
from .trials import Stage, Trial

__all__ = ["joint_step", "PAIR_GAIN"]

#: the least relative gain of a leader that is not significant alone for which the default tries its pairs
PAIR_GAIN = 0.05


def joint_step(loop: Any, ext: Any, ranking: Ranking, rnd: int, n_max: int) -> bool:
    """Try the leader of round ``rnd`` (``ranking``, not significant alone) jointly with each other candidate;
    when a pair is significant, add both causes to ``ext`` (in place) and return True (module docstring)."""
    inp, cal, opts, skip = loop.inp, loop.cal, loop.opts, loop.opts.skip
    stage: Stage = ext.stage
    top = ranking.top
    gain0 = 1.0 - top.nrmse_val / stage.nrmse_val if stage.nrmse_val > 0 else 0.0
    if (
        opts.pairs is False
        or (opts.pairs is None and not (getattr(type(stage.twin), "JOINT_TRIALS", False) and gain0 >= PAIR_GAIN))
        or top.retest
        or len(ext.causes) + 2 > n_max
        or top.sse_val >= stage.sse_val
        or not beyond_noise(inp, stage, skip)
    ):
        return False
    tent = adopt(inp, top.twin, opts)
    top_fields = effect_fields(top.twin, top.twin.EFFECTS[top.effect].params.values())
    core_x = loop.core_r + [f for f in top_fields if f not in loop.core_r]
    remaining = [e for e in loop.pool if e not in tent.twin.effects]
    opts.say(f"round {rnd}: {top.effect} is not significant alone; trying it jointly with {len(remaining)} others")
    trials, errors = round_trials(inp, cal, tent, remaining, [], core_x, f"{rnd} with {top.effect}", opts)
    ext.rounds += errors
    if not trials:
        return False
    n_eff0 = ft.effective_samples(inp.val.y[skip:] - stage.yhat_val[skip:])
    level = opts.alpha / (len(ranking.trials) + len(trials))
    judged = []
    for tr in trials:
        p = significance(stage.sse_val, tr.sse_val, n_eff0, top.n_added + tr.n_added)
        gain = max(0.0, 1.0 - tr.nrmse_val / stage.nrmse_val) if stage.nrmse_val > 0 else 0.0
        judged.append((tr, p, gain))
    row: dict[str, Any] = {
        "round": rnd,
        "pair_with": top.effect,
        "nrmse_val_before": stage.nrmse_val,
        "n_eff": n_eff0,
        "level": level,
        "pairs": [
            {"effect": tr.effect, "nrmse_val": tr.nrmse_val, "p_joint": p, "gain": g, "params": tr.effect_params}
            for tr, p, g in judged
        ],
        "kept": None,
    }
    ext.rounds.append(row)
    passing = [(tr, p, g) for tr, p, g in judged if p < level and g >= opts.min_rel_gain]
    if not passing:
        return False
    second, p_joint, _ = min(passing, key=lambda x: x[0].sse_val)
    row["kept"] = second.effect
    _name_pair(loop, ext, ranking, trials, tent, second, p_joint, level, rnd)
    return True


def _name_pair(
    loop: Any,
    ext: Any,
    ranking: Ranking,
    trials: list[Trial],
    tent: Stage,
    second: Trial,
    p_joint: float,
    level: float,
    rnd: int,
) -> None:
    """Both causes of a significant pair, with the rows and groups a round would give them, added to ``ext``; the
    configuration with both becomes the stage."""
    inp, cal, opts, skip = loop.inp, loop.cal, loop.opts, loop.opts.skip
    stage: Stage = ext.stage
    top = ranking.top
    # the second effect's row and group as a round from the tentative configuration would give them
    ranking2 = rank_round(
        trials,
        tent,
        inp.est,
        inp.val,
        inp.twin,
        cal.prior,
        ft.effective_samples(inp.val.y[skip:] - tent.yhat_val[skip:]),
        opts,
    )
    i2 = next(i for i, t in enumerate(ranking2.trials) if t is second)
    order = [i2] + [i for i in range(len(ranking2.trials)) if i != i2]
    group2 = ranking2.group if ranking2.trials[0] is second else [second.effect]
    ranking2 = Ranking([ranking2.trials[i] for i in order], group2, [ranking2.rows[i] for i in order])
    first = cause_from(ranking, stage, inp.twin, cal.prior, rnd)
    other = cause_from(ranking2, tent, inp.twin, cal.prior, rnd)
    other["params"] = dict(second.effect_params)
    first["params"] = {
        f: float(getattr(second.twin.params, f)) for f in first["params"] if hasattr(second.twin.params, f)
    } or first["params"]
    for c, mate, score in (
        (first, second.effect, ranking.rows[0]["signature_score"]),
        (other, top.effect, ranking2.rows[0]["signature_score"]),
    ):
        c["joint_with"] = mate
        c["p_joint"] = p_joint
        c["confidence"] = float(max(0.0, min(0.5, (1.0 - p_joint) * 0.5 * (0.8 + 0.2 * score))))
        c["evidence"] += (
            f"; significant jointly with {mate}: together they lower the validation NRMSE "
            f"{stage.nrmse_val:.4g} → {second.nrmse_val:.4g} (F-test p = {p_joint:.2g} with "
            f"{top.n_added + second.n_added} parameters, level {level:.2g})"
        )
    ext.causes += [first, other]
    ext.stage = adopt(inp, second.twin, opts)
