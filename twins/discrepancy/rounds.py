"""The rounds that extend the configuration: greedy rounds of trials, then a revisit of the effects they named.

**Greedy rounds** (:func:`extend`): every catalog effect the configuration lacks is tried (:func:`round_trials`),
the trials are ranked (:mod:`.ranking`) and a significant leader is added; repeated until nothing significant
remains or ``max_rounds`` effects were added.

**Revisit** (:func:`revisit`): when two hidden effects act at once, the first round sees their sum, and its
leader can be a third effect that mimics the sum better than either part alone (on steps, creep plus thermal
drift looks like an asymmetric hysteresis to the first round: gain 44 % against 1 % for the drift). The
second round then adds the other true effect, and the one the mimic stands in for is no longer significant
(its gain is what the mimic did not already absorb). A first-round leader can also be a default effect re-tested
at a wrong size (a slower sensor standing in for saturation plus a delay). So, once at least two causes were
named, each of them but the last is taken out in turn (an added effect switched off, a re-tested default put
back at its configured size), the others kept (their parameters refitted with the core in the full fits), and
every candidate is tried in its slot with the same trials and ranking as a round (a re-tested default
beside them). A significant candidate that beats the incumbent's own refit in that slot (F-test at ``alpha``)
replaces it, and the parameters of the causes kept are reported as refitted beside it; an incumbent that keeps
its slot keeps its joint refit where that fits both records better. After a replacement the greedy rounds
resume, since the effect the mimic hid can now be found. The last cause needs no revisit: its round already
tried every candidate with the others present. With one cause or none (noise only, a single effect) nothing
is revisited.

**A later leader with the causes named before** (:func:`_with_named`): a round's trials hold the earlier causes'
parameters at the values fitted without the new one, and an earlier cause fitted alone takes up part of the one
still missing (a thermal drift fitted before creep on steps: its size 13 % and its time constant 34 % short), so
the new one gains too little for its F-test (creep: 41 %, p 0.03). A leader that is not significant but gains at
least :data:`.pairs.PAIR_GAIN` (any gain with ``pairs`` True), while the residual is still far above the noise
(the ``unexplained`` verdict's rule), is refitted with the earlier causes' parameters beside it and the core, and
judged against the better of the stage and the stage refitted the same way without it; significant, it is named.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

from twins.base import Twin

from . import defaults as dflt
from . import features as ft
from .candidates import TRIAL_ERRORS, adopt, beyond_noise, round_trials
from .fields import choice_fields, effect_fields
from .options import DiagnoseOptions
from .pairs import PAIR_GAIN, joint_step
from .prediction import NOISE_EFFECTS, significance, sse, unpredictable
from .ranking import Ranking, cause_from, rank_round
from .trials import Stage, Trial, core_refit_sse, make_stage, run_trial

__all__ = ["Extension", "extend", "revisit"]


@dataclasses.dataclass
class Extension:
    """The configuration after the rounds, the causes they named and every round's numbers."""

    stage: Stage
    causes: list[dict[str, Any]]
    rounds: list[dict[str, Any]]


@dataclasses.dataclass
class _Loop:
    """What the rounds share: the inputs, the calibration, the candidate pool and the core refitted with them."""

    inp: Any  # diagnose's prepared inputs (records, twin, core)
    cal: Any  # diagnose's calibration (prior, effects to re-test)
    pool: list[str]
    core_r: list[str]
    opts: DiagnoseOptions
    retest_left: list[str]
    first: Ranking | None = None  # the first greedy round's ranking (for the runner-up branch)


def extend(inp: Any, cal: Any, base: Stage, max_rounds: int, opts: DiagnoseOptions) -> Extension:
    """Greedy rounds; each significant leader is added to the configuration; then the revisit (module docstring)."""
    twin = inp.twin
    # trials refit the core without the parameters of the effects that are on: a trial that refitted the creep
    # rate would credit any added effect with the re-test's gain (the re-tests fit those parameters themselves)
    core_r = [c for c in inp.core if c not in cal.held]
    pool = [
        e
        for e in (opts.candidates if opts.candidates is not None else twin.EFFECTS)
        if e in twin.EFFECTS and e not in twin.effects and e not in NOISE_EFFECTS and e not in unpredictable(twin)
    ]
    loop = _Loop(inp, cal, pool, core_r, opts, list(cal.retest))
    ext = Extension(base, [], [])
    n_max = max(int(max_rounds), 0)
    _rounds(loop, ext, n_max)
    _branch(loop, ext, base, n_max)
    return ext


def _rounds(loop: _Loop, ext: Extension, n_max: int) -> None:
    """Greedy rounds, the revisit (and the rounds it reopens), the re-check of mis-sized defaults."""
    _greedy(loop, ext, n_max)
    if len(ext.causes) > 1:
        if revisit(loop, ext):
            _greedy(loop, ext, n_max)
        _recheck_defaults(loop, ext)


def _branch(loop: _Loop, ext: Extension, base: Stage, n_max: int) -> None:
    """The runner-up branch: when the rounds stopped with room for more causes but the residual still far above
    the noise (``EXCESS_LIMIT``× its variance, the ``unexplained`` verdict), round 1 is taken again with its best
    significant runner-up outside the leader's group as the cause, and the rounds run from there. A first-round
    leader can be a mimic that blocks the rest: a sensor re-tested at a tenth of its bandwidth stands in for a
    delay (gain 68 % against 59 %), and with it in place neither the delay nor the saturation gains anything
    (saturation + delay, seed 9). The branch is kept where its validation residual is significantly smaller
    (F-test at ``alpha``); its rounds are listed with ``branch``."""
    inp, first, opts = loop.inp, loop.first, loop.opts
    if first is None or not ext.causes or len(ext.causes) >= n_max or not beyond_noise(inp, ext.stage, opts.skip):
        return
    alt_i = next((i for i, t in enumerate(first.trials) if i and t.significant and t.effect not in first.group), None)
    if alt_i is None:
        return
    runner, leader, saved = first.trials[alt_i], first.top.effect, list(loop.retest_left)
    order = [alt_i] + [i for i in range(len(first.trials)) if i != alt_i]
    ranking = Ranking([first.trials[i] for i in order], [runner.effect], [first.rows[i] for i in order])
    opts.say(f"the rounds from {leader} left the residual far above the noise: trying round 1 with {runner.effect}")
    loop.retest_left = [e for e in loop.cal.retest if not (runner.retest and e == runner.effect)]
    alt = Extension(
        adopt(inp, runner.twin, opts),
        [cause_from(ranking, base, inp.twin, loop.cal.prior, 1)],
        [{"round": 1, "branch": runner.effect, "instead_of": leader}],
    )
    _rounds(loop, alt, n_max)
    n_eff = ft.effective_samples(inp.val.y[opts.skip :] - ext.stage.yhat_val[opts.skip :])
    kept = bool(
        alt.stage.sse_val < ext.stage.sse_val
        and significance(ext.stage.sse_val, alt.stage.sse_val, n_eff, 1) < opts.alpha
    )
    ext.rounds += [{**r, "branch": runner.effect} for r in alt.rounds]
    ext.rounds[-len(alt.rounds)]["kept"] = kept
    if not kept:
        loop.retest_left = saved
        return
    alt.causes[0]["evidence"] += (
        f"; named in place of {leader}, round 1's leader: the rounds from {leader} left "
        f"the validation NRMSE at {ext.stage.nrmse_val:.4g}, those from {runner.effect} "
        f"at {alt.stage.nrmse_val:.4g}"
    )
    ext.causes, ext.stage = alt.causes, alt.stage


def _recheck_defaults(loop: _Loop, ext: Extension) -> None:
    """Each mis-sized default named beside other causes, judged again in the final configuration.

    The revisit refits every cause's parameters with the core, and a default re-tested in a late round only to
    make up for an earlier cause's first fit (a sensor bandwidth 3–5× wider standing in for a delay fitted 10 %
    long before the saturation was known) is back near its configured size there. Its parameters are reported
    as refitted (the round's values under ``params_first_fit``). The cause is withdrawn (a ``rounds`` row with
    ``withdrawn``) where every parameter is within 5 % of its configured value (the refit stays: a size that
    close is no mis-sizing to report), or where putting the configured values back no longer makes the fit
    significantly worse (F-test at ``alpha``, relative gain ``min_rel_gain``; the configured values are put
    back)."""
    inp, prior, opts, skip = loop.inp, loop.cal.prior, loop.opts, loop.opts.skip
    for cause in [c for c in ext.causes if c.get("kind") == "mis-sized default"]:
        twin, eff = ext.stage.twin, cause["effect"]
        fields = effect_fields(twin, twin.EFFECTS[eff].params.values())
        cause.setdefault("params_first_fit", dict(cause["params"]))
        cause["params"] = {f: float(getattr(twin.params, f)) for f in fields}
        ratio = {
            f: (
                cause["params"][f] / float(getattr(prior.params, f))
                if float(getattr(prior.params, f)) != 0
                else float("inf")
            )
            for f in fields
        }
        cause["ratio_to_configured"] = ratio
        if all(abs(math.log(max(r, 1e-300))) <= math.log(_SAME_SIZE) for r in ratio.values()):
            note = f"refitted to within {100 * (_SAME_SIZE - 1):.0f} % of its configured size"
        else:
            n_eff = ft.effective_samples(inp.val.y[skip:] - ext.stage.yhat_val[skip:])
            if dflt.holds(
                twin,
                eff,
                ext.stage.sse_val,
                len(fields),
                inp.est,
                inp.val,
                prior,
                n_eff,
                opts.alpha,
                opts.min_rel_gain,
                skip,
            ):
                continue
            note = "back at its configured size the final configuration fits not significantly worse"
            ext.stage = adopt(inp, _taken_out(twin, eff, True, prior), opts)
        ext.causes.remove(cause)
        ext.rounds.append({"round": cause["round"], "withdrawn": eff, "params": cause["params"], "note": note})


#: parameters within this factor of their configured values are the configured size (as in the cause's text)
_SAME_SIZE = 1.05


def _greedy(loop: _Loop, ext: Extension, n_max: int) -> None:
    """Rounds until nothing significant remains or ``n_max`` causes were named; updates ``ext`` in place."""
    inp, cal, opts, skip = loop.inp, loop.cal, loop.opts, loop.opts.skip
    while len(ext.causes) < n_max:
        rnd = 1 + max([r["round"] for r in ext.rounds if isinstance(r.get("round"), int)] + [0])
        stage = ext.stage
        remaining = [e for e in loop.pool if e not in stage.twin.effects]
        if not remaining and not loop.retest_left:
            break
        n_eff0 = ft.effective_samples(inp.val.y[skip:] - stage.yhat_val[skip:])
        trials, errors = round_trials(inp, cal, stage, remaining, loop.retest_left, loop.core_r, rnd, opts)
        ext.rounds += errors
        if not trials:
            break
        ranking = rank_round(
            trials, stage, inp.est, inp.val, inp.twin, cal.prior, n_eff0, opts, not ext.causes, loop.core_r
        )
        ext.rounds.append(
            {
                "round": rnd,
                "nrmse_val_before": stage.nrmse_val,
                "n_eff": n_eff0,
                "candidates": ranking.rows,
                "group": ranking.group,
            }
        )
        if rnd == 1:
            loop.first = ranking
        top = ranking.top
        opts.round_done(
            f"round {rnd}: {len(trials)} trials, leader {top.effect} (validation gain {top.gain:.3g}, "
            f"p = {top.p_value:.2g}, {'significant' if top.significant else 'not significant'}), "
            f"{time.perf_counter() - inp.t_start:.0f} s"
        )
        if not top.significant:
            if _with_named(loop, ext, ranking, rnd, n_eff0) or joint_step(loop, ext, ranking, rnd, n_max):
                continue
            break
        ext.causes.append(cause_from(ranking, stage, inp.twin, cal.prior, rnd))
        if top.retest:
            loop.retest_left.remove(top.effect)
        ext.stage = adopt(inp, top.twin, opts)


def _with_named(loop: _Loop, ext: Extension, ranking: Ranking, rnd: int, n_eff0: float) -> bool:
    """A later round's leader that is not significant, refitted jointly with the causes named before it (their
    parameters refitted beside it and the core); True when it then is, and was added to ``ext`` (module docstring).
    Judged in its round (``n_eff0``: the effective samples of its stage's residual) against the better of the stage
    and the stage refitted the same way without it."""
    inp, cal, opts, skip = loop.inp, loop.cal, loop.opts, loop.opts.skip
    stage, top = ext.stage, ranking.top
    small = top.gain < PAIR_GAIN and opts.pairs is not True  # DiagnoseOptions.pairs True: every leader
    if not ext.causes or top.retest or small or top.sse_val >= stage.sse_val:
        return False
    if not beyond_noise(inp, stage, skip):  # what is left is noise: no parameters to trade for a second name
        return False
    twin = stage.twin
    named = [c["effect"] for c in ext.causes if c.get("kind") != "mis-sized default" and c["effect"] in twin.effects]
    core_x = _core_with(loop, twin, named)
    if core_x == loop.core_r:
        return False
    start = dict(top.effect_params)
    opts.say(f"round {rnd}: {top.effect} is not significant alone; refitted jointly with {', '.join(named)}")
    try:
        tr = run_trial(
            stage.twin,
            top.effect,
            inp.est,
            inp.val,
            core_x,
            {**stage.analysis_est, "fs": inp.est.fs},
            opts,
            refit_core=True,
            start=start,
        )
        tr.ref_sse_val = core_refit_sse(stage, inp.est, inp.val, core_x, opts)
    except TRIAL_ERRORS:
        return False
    joint = rank_round(
        [tr] + [t for t in ranking.trials if t is not top], stage, inp.est, inp.val, inp.twin, cal.prior, n_eff0, opts
    )
    ext.rounds.append(
        {
            "round": rnd,
            "with_named": named,
            "nrmse_val_before": stage.nrmse_val,
            "n_eff": n_eff0,
            "candidates": joint.rows,
            "group": joint.group,
        }
    )
    if joint.top is not tr or not tr.significant:
        return False
    cause = cause_from(joint, stage, inp.twin, cal.prior, rnd)
    cause["evidence"] += f"; fitted jointly with {', '.join(named)} (their parameters refitted beside it)"
    cause["joint_with_named"] = named
    ext.causes.append(cause)
    ext.stage = adopt(inp, tr.twin, opts)
    _refresh_params(ext, named)
    return True


def revisit(loop: _Loop, ext: Extension) -> bool:
    """Each cause but the last, taken out and its slot tried again (module docstring); True when one was
    replaced. Updates ``ext`` in place."""
    inp, cal, opts, skip = loop.inp, loop.cal, loop.opts, loop.opts.skip
    changed = False
    for i in range(len(ext.causes) - 1):
        cause, twin = ext.causes[i], ext.stage.twin
        eff, retest = cause["effect"], cause.get("kind") == "mis-sized default"
        base = make_stage(_taken_out(twin, eff, retest, cal.prior), inp.est, inp.val, opts)
        others = [c["effect"] for c in ext.causes if c is not cause]
        core_x = _core_with(loop, twin, others)
        cands = [e for e in loop.pool if e not in base.twin.effects]
        opts.say(f"revisiting {eff}: {len(cands) + retest} candidates in its place")
        trials, errors = round_trials(inp, cal, base, cands, [eff] if retest else [], core_x, f"revisit {eff}", opts)
        ext.rounds += errors
        if not trials:
            continue
        n_eff0 = ft.effective_samples(inp.val.y[skip:] - base.yhat_val[skip:])
        ranking = rank_round(trials, base, inp.est, inp.val, inp.twin, cal.prior, n_eff0, opts, core=core_x)
        row = {
            "round": cause["round"],
            "revisit": eff,
            "nrmse_val_before": base.nrmse_val,
            "n_eff": n_eff0,
            "candidates": ranking.rows,
            "group": ranking.group,
            "replaced_by": None,
        }
        ext.rounds.append(row)
        top = ranking.top
        if top.effect == eff:
            _keep_refit(ext, cause, top, inp, opts)
            continue
        if not top.significant or not _beats(top, trials, eff, ext.stage, n_eff0, opts):
            continue
        new = cause_from(ranking, base, inp.twin, cal.prior, cause["round"])
        new["replaces"] = eff
        new["evidence"] += f"; replaces {eff}, which the first rounds named in its place"
        ext.causes[i] = new
        ext.stage = adopt(inp, top.twin, opts)
        row["replaced_by"] = top.effect
        if retest:  # back at its configured size: the next rounds may re-test it again
            loop.retest_left.append(eff)
        changed = True
        _refresh_params(ext, [c["effect"] for c in ext.causes if c is not new])
    return changed


def _core_with(loop: _Loop, twin: Twin, effects: list[str]) -> list[str]:
    """The core the rounds refit, with the parameters of ``effects`` (causes named before) refitted beside it."""
    return loop.core_r + [
        f for o in effects for f in effect_fields(twin, twin.EFFECTS[o].params.values()) if f not in loop.core_r
    ]


def _taken_out(twin: Twin, effect: str, retest: bool, prior: Twin) -> Twin:
    """``twin`` without ``effect``: switched off if it was added, its parameters back at their configured values
    if it is a re-tested default."""
    if not retest:
        return twin.with_effects(set(twin.effects) - {effect})
    spec_fields = twin.EFFECTS[effect].params.values()
    fields = effect_fields(twin, spec_fields) + choice_fields(twin, spec_fields)  # its variant back too
    return twin.with_params(**{f: getattr(prior.params, f) for f in fields})


def _keep_refit(ext: Extension, cause: dict[str, Any], tr: Trial, inp: Any, opts: DiagnoseOptions) -> None:
    """The incumbent kept its slot: its refit beside the other causes (their parameters and the core refitted
    with it) replaces the configuration where it fits both records better (a drift time constant first fitted
    beside a creep-free core is 16 % short and leaves the residual above the noise)."""
    if not (tr.sse_val <= ext.stage.sse_val and tr.sse_est < sse(inp.est.y, ext.stage.yhat_est, opts.skip)):
        return
    ext.stage = adopt(inp, tr.twin, opts)
    _refresh_params(ext, [c["effect"] for c in ext.causes])


def _refresh_params(ext: Extension, effects: list[str]) -> None:
    """The parameters of the added ``effects`` as refitted in a revisit (their first fits were made beside a mimic
    or beside a core bent to stand in for a missing effect); the earlier values stay under ``params_first_fit``."""
    twin = ext.stage.twin
    for c in ext.causes:
        if c["effect"] in effects and c.get("kind") != "mis-sized default":
            c.setdefault("params_first_fit", dict(c["params"]))
            c["params"] = {f: getattr(twin.params, f) for f in c["params"]}


def _beats(top: Trial, trials: list[Trial], incumbent: str, stage: Stage, n_eff: float, opts: DiagnoseOptions) -> bool:
    """The slot's leader explains the validation record significantly better than the incumbent (its refit in the
    slot, or the configuration as it stands, whichever is better)."""
    ref = min([t.sse_val for t in trials if t.effect == incumbent] + [stage.sse_val])
    return bool(top.sse_val < ref and significance(ref, top.sse_val, n_eff, 1) < opts.alpha)
