"""The experiment that separates effects whose residual signatures the data cannot tell apart (a sound-speed and a
distance change both move the time of flight): one sentence per group of evidence families
(:data:`twins.discrepancy.evidence.FAMILIES`), reported beside an ambiguity group.
"""

from __future__ import annotations

__all__ = ["SEPARATING_EXPERIMENTS", "separating_experiment"]

#: experiments that separate effects with the same signature (by family pair, order-free)
SEPARATING_EXPERIMENTS: dict[frozenset, str] = {
    frozenset({"time_of_flight"}): (
        "measure the time of flight at two distances and two temperatures: a distance "
        "offset adds a constant path, a sound-speed (temperature/fluid) change scales "
        "the whole time of flight with distance"
    ),
    frozenset({"time_of_flight", "delay"}): (
        "measure the time of flight at two distances: an electronic delay is the "
        "same at both, a sound-speed or distance change is not"
    ),
    frozenset({"delay", "lowpass"}): (
        "excite beyond the band edge (or measure the phase at two frequencies): a pure "
        "delay has linear phase and flat magnitude, a low-pass attenuates"
    ),
    frozenset({"creep", "drift"}): (
        "hold the input at zero for as long as the record: thermal drift continues, creep "
        "after a step decays logarithmically and scales with the step"
    ),
    frozenset({"odd_nl"}): (
        "drive at several amplitudes: hard saturation leaves small signals untouched, a smooth "
        "compression bends them already"
    ),
    frozenset({"odd_nl", "even_nl"}): (
        "use an odd multisine: odd-order distortion lands on the odd detection lines, even-order on the even lines"
    ),
    frozenset({"echo", "crosstalk"}): (
        "change the distance: an acoustic echo moves with it, electrical crosstalk stays at the excitation time"
    ),
    frozenset({"resonance", "lowpass"}): (
        "sweep a sine through the suspected band: a resonance has a phase jump of "
        "180°, a low-pass only a gradual roll-off"
    ),
    frozenset({"rate_hysteresis", "lowpass"}): (
        "measure loops at several frequencies with a small amplitude: "
        "rate-dependent hysteresis widens with amplitude and frequency, a "
        "linear lag only with frequency"
    ),
}


def separating_experiment(families: list[str]) -> str:
    fams = frozenset(families)
    if fams in SEPARATING_EXPERIMENTS:
        return SEPARATING_EXPERIMENTS[fams]
    for k, v in SEPARATING_EXPERIMENTS.items():
        if k <= fams and len(k) > 1:
            return v
    if len(fams) == 1:
        fam = next(iter(fams))
        if frozenset({fam}) in SEPARATING_EXPERIMENTS:
            return SEPARATING_EXPERIMENTS[frozenset({fam})]
    return (
        "repeat the experiment while changing one quantity that only one of these effects depends on "
        "(amplitude, frequency, distance, temperature or hold time)"
    )
