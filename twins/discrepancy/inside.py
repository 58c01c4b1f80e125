"""Hooks of the diagnosis for a model given by its equations (:mod:`twins.equations`): the mechanisms' ranges
follow the calibrated model, and what no mechanism explains is looked for inside the equations as a sparse term.

Both act through methods of the twin (``follow_calibration``, ``sparse_term``), so any twin that offers them
takes part and the loop itself stays unaware of the equations.
"""

from __future__ import annotations

from typing import Any

from .options import DiagnoseOptions
from .trials import Stage

__all__ = ["follow_calibration", "sparse_inside"]


def follow_calibration(inp: Any, cal: Any, opts: DiagnoseOptions) -> None:
    """A twin whose ranges follow its calibrated state (``follow_calibration(est, val) -> (twin, notes)``: the
    mechanisms inside a model's equations) gets them set before the rounds; ``cal.twin`` and ``inp.ranges`` are
    updated in place."""
    follow = getattr(cal.twin, "follow_calibration", None)
    if opts.follow_ranges and callable(follow):
        cal.twin, notes = follow(inp.est, inp.val)
        inp.ranges += notes
        for note in notes:
            opts.say(note)


def sparse_inside(
    inp: Any, stage: Stage, base: Stage, verdict: str, causes: list[dict[str, Any]], opts: DiagnoseOptions
) -> tuple[dict[str, Any] | None, Any]:
    """With an ``unexplained`` verdict, a twin that can look inside its equations (``sparse_term``) fits a sparse
    term there (:mod:`twins.equations.sparse`), added to the final configuration and, where causes were named, to
    the calibrated configuration as given (a named mechanism can be a mimic of what lies outside the catalog: the
    term found on its residual is then a patch of the mimic's error); the one with the smaller validation error is
    kept. A significant term goes into the evidence of the ``unexplained`` cause (no physical name is claimed, the
    verdict stays); where it was found without the named causes and fits better than they do, each of them says
    so and its confidence is capped at ½. Returns the block and the term itself."""
    find = getattr(stage.twin, "sparse_term", None)
    if verdict != "unexplained" or not callable(find):
        return None, None
    opts.say("looking for a sparse term inside the equations (forward regression on the equation residual)")
    block, term = find(inp.est, inp.val, opts.skip, opts.alpha)
    block["added_to"] = "the final configuration"
    named = [c for c in causes if c["effect"] != "unexplained" and c.get("round", 1)]
    if named and base.twin is not stage.twin:
        alt, alt_term = base.twin.sparse_term(inp.est, inp.val, opts.skip, opts.alpha)  # type: ignore[attr-defined]
        if alt.get("fitted") and alt["nrmse_val_after"] < block.get("nrmse_val_after", float("inf")):
            block, term = {**alt, "added_to": "the calibrated model as given"}, alt_term
            if block["significant"] and block["nrmse_val_after"] < stage.nrmse_val:
                for c in named:
                    c["confidence"] = min(float(c["confidence"]), 0.5)
                    c["evidence"] += (
                        f"; a sparse term without it ({block['text']}) fits the validation record better "
                        f"(NRMSE {block['nrmse_val_after']:.4g} against {stage.nrmse_val:.4g}): it may be a mimic"
                    )
    if block.get("significant"):
        text = (
            f"inside the equations a sparse term {block['text']} lowers the validation NRMSE "
            f"{block['nrmse_val_before']:.4g} → {block['nrmse_val_after']:.4g} (F-test p = {block['p_value']:.2g}, "
            f"{block['n_params']} terms counted, added to {block['added_to']}); no catalog mechanism has this form"
        )
        cause = next((c for c in causes if c["effect"] == "unexplained"), None)
        if cause is None:
            causes.append(
                {"effect": "unexplained", "confidence": 0.5 * (1 - block["p_value"]), "evidence": text, "params": {}}
            )
        else:
            cause["evidence"] += "; " + text
    return block, term
