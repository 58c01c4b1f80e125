"""The catalog of mechanisms the diagnosis can add inside a model's equations.

A :class:`Mechanism` names a physical phenomenon, the roles of the states it can act on, where its term enters
(the state's own rate; the rate of the velocity paired with a position; the input; a bound on the state), its
parameters with the ranges the records give them (:func:`param_ranges`, from the calibrated model's state
amplitudes) and its law (:mod:`.laws`). A model gets one effect ``KIND@STATE`` per entry and state of a role it
takes (``cubic_spring@x``, :mod:`.twin`), which the diagnosis tries beside the generic effects.

Roles: a position and the velocity whose value is its rate form a pair (found from the model's Jacobian,
:mod:`.model`); a friction or a damping acts on a velocity, a restoring force or a hysteresis on a position and
enters its velocity's rate; a bound, a leak or an orifice on a stored quantity (a level, a charge, a
temperature ...); a dead zone, a backlash and a static nonlinearity act on the input before the equations.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

__all__ = ["ROLES", "PAIRS", "Mechanism", "MParam", "MECHANISMS", "Scales", "param_ranges"]

#: role → what a state of that role is (a model's STATES name one per state)
ROLES: dict[str, str] = {
    "position": "a displacement (its rate is a velocity state)",
    "velocity": "a velocity (its rate is an acceleration: force per mass)",
    "angle": "a rotation angle (its rate is an angular-velocity state)",
    "angular_velocity": "an angular velocity (its rate: torque per inertia)",
    "level": "a liquid level or stored volume (flows in and out)",
    "charge": "an electric charge or a capacitor voltage",
    "current": "an electric current (an inductor's)",
    "flux": "a magnetic flux",
    "temperature": "a temperature (heat stored)",
    "pressure": "a pressure (fluid stored in a volume)",
    "concentration": "a concentration",
    "other": "any other state (only the mechanisms that need no role: the sparse term)",
}
#: position-like role → the role of the state that is its rate
PAIRS: dict[str, str] = {"position": "velocity", "angle": "angular_velocity"}
_STORED = ("level", "charge", "temperature", "pressure", "concentration")


@dataclasses.dataclass(frozen=True)
class Scales:
    """What the ranges are made from (the calibrated model on the estimation record): ``x`` the peak |value| of
    the state acted on, ``x_lo`` its 5th percentile, ``v`` the peak |value| of its velocity (a position's pair),
    ``a`` the peak |rate| of the state the term enters, ``rate_x`` the peak |rate| of the state acted on, ``u``
    the peak |input|, ``u_span`` the input's range, ``ratio`` the transfer ratio −J[j,i]/J[i,i] of a spill."""

    x: float = 1.0
    x_lo: float = 0.0
    v: float = 1.0
    a: float = 1.0
    rate_x: float = 1.0
    u: float = 1.0
    u_span: float = 1.0
    ratio: float = 1.0


@dataclasses.dataclass(frozen=True)
class MParam:
    """A mechanism parameter: short key, description, unit (``{x}``, ``{a}``, ``{u}`` stand for the units of the
    state acted on, of the rate entered and of the input), default, and its range from the :class:`Scales`."""

    key: str
    doc: str
    unit: str
    default: float
    span: Callable[[Scales], tuple[float, float]]


@dataclasses.dataclass(frozen=True)
class Mechanism:
    """One catalog entry (module docstring). ``enters``: ``self`` (the rate of the state acted on), ``pair`` (the
    rate of a position's velocity), ``input`` (the input before the equations) or ``bound`` (a bound on the state,
    spilling into the state it flows to). ``added_states``: states the mechanism adds (a hysteresis). ``nests``:
    kinds it contains as a special case (Stribeck friction contains Coulomb friction); ``nest_contrast``: weights
    (key, w) of the parameters' combination that is 0 in that special case (Stribeck: fs = 0; a weight 0 lists
    a parameter only for the contrast's scale, :mod:`twins.discrepancy.nesting`). ``refit_core``: the term changes
    what the model's own parameters stand for (a power-law outflow bends the model's outflow law), so its trials
    refit the core with it, as a restoring force's, a hysteresis's and a bound's do."""

    kind: str
    title: str
    meaning: str
    law: str
    signature: str
    roles: tuple[str, ...]
    enters: str
    params: tuple[MParam, ...]
    family: str
    added_states: int = 0
    nests: tuple[str, ...] = ()
    nest_contrast: tuple[tuple[str, float], ...] = ()
    refit_core: bool = False


def _pos(lo: float, hi: float) -> Callable[[Scales], tuple[float, float]]:
    return lambda s: (lo * s.a, hi * s.a)


def _sym(power_of: str, power: int, size: float = 1.0) -> Callable[[Scales], tuple[float, float]]:
    def span(s: Scales) -> tuple[float, float]:
        ref = {"x": s.x, "v": s.v}[power_of] ** power
        return (-size * s.a / ref, size * s.a / ref)

    return span


_FRICTION = ("velocity", "angular_velocity")
_POSITION = ("position", "angle")
MECHANISMS: dict[str, Mechanism] = {
    m.kind: m
    for m in (
        Mechanism(
            "coulomb",
            "Coulomb friction",
            "dry friction of constant size against the motion",
            "d{x}/dt −= Fc·sign({x})",
            "residual jumps where the velocity changes sign; flattened velocity reversals",
            _FRICTION,
            "self",
            (MParam("fc", "Coulomb friction level (force per mass)", "{a}", 0.0, _pos(0.0, 0.5)),),
            "friction",
        ),
        Mechanism(
            "stribeck",
            "Stribeck friction",
            "dry friction higher at rest than in motion (static level Fc + Fs, falling to Fc over the speed vs)",
            "d{x}/dt −= (Fc + Fs·exp(−({x}/vs)²))·sign({x})",
            "stick at reversals, a friction peak at low speed",
            _FRICTION,
            "self",
            (
                MParam("fc", "Coulomb friction level (force per mass)", "{a}", 0.0, _pos(0.0, 0.5)),
                MParam("fs", "static friction above the Coulomb level", "{a}", 0.0, _pos(0.0, 0.5)),
                MParam("vs", "Stribeck velocity", "{x}", 1.0, lambda s: (1e-3 * s.x, s.x)),
            ),
            "friction",
            nests=("coulomb",),
            nest_contrast=(("fs", 1.0), ("fc", 0.0)),
        ),
        Mechanism(
            "asymmetric_coulomb",
            "asymmetric Coulomb friction",
            "dry friction of different sizes in the two directions of motion",
            "d{x}/dt −= F₊ (for {x} > 0) or +F₋ (for {x} < 0)",
            "residual jumps of different sizes at the two kinds of reversal",
            _FRICTION,
            "self",
            (
                MParam("f_pos", "friction level in the positive direction", "{a}", 0.0, _pos(0.0, 0.5)),
                MParam("f_neg", "friction level in the negative direction", "{a}", 0.0, _pos(0.0, 0.5)),
            ),
            "friction",
            nests=("coulomb",),
            nest_contrast=(("f_pos", 1.0), ("f_neg", -1.0)),
        ),
        Mechanism(
            "quadratic_damping",
            "quadratic damping",
            "damping that grows with the square of the speed (drag, turbulent flow)",
            "d{x}/dt −= c2·{x}·|{x}|",
            "residual grows with the speed squared, in phase with the velocity",
            _FRICTION,
            "self",
            (MParam("c2", "quadratic damping coefficient", "{a}/({x})^2", 0.0, _sym("x", 2, 0.5)),),
            "damping",
        ),
        Mechanism(
            "cubic_damping",
            "cubic damping",
            "damping that grows with the cube of the speed",
            "d{x}/dt −= c3·{x}³",
            "odd residual at high speeds, in phase with the velocity",
            _FRICTION,
            "self",
            (MParam("c3", "cubic damping coefficient", "{a}/({x})^3", 0.0, _sym("x", 3, 0.5)),),
            "damping",
        ),
        Mechanism(
            "cubic_spring",
            "cubic restoring force",
            "a spring that hardens (k3 > 0) or softens (k3 < 0) with the displacement (Duffing)",
            "d{v}/dt −= k3·{x}³",
            "resonance shifting with amplitude, odd harmonics, residual ∝ x³",
            _POSITION,
            "pair",
            (MParam("k3", "cubic stiffness (per mass)", "{a}/({x})^3", 0.0, _sym("x", 3, 10.0)),),
            "restoring",
        ),
        Mechanism(
            "quadratic_spring",
            "quadratic restoring force",
            "a spring stiffer on one side than on the other",
            "d{v}/dt −= k2·{x}²",
            "even harmonics, a shift of the mean position with amplitude",
            _POSITION,
            "pair",
            (MParam("k2", "quadratic stiffness (per mass)", "{a}/({x})^2", 0.0, _sym("x", 2, 10.0)),),
            "restoring",
        ),
        Mechanism(
            "clearance_spring",
            "clearance (gap) spring",
            "a spring or stop that engages beyond a gap",
            "d{v}/dt −= kc·sign({x})·max(|{x}| − gap, 0)",
            "residual only at the largest displacements, a kink in the restoring force",
            _POSITION,
            "pair",
            (
                MParam("gap", "clearance", "{x}", 0.5, lambda s: (0.0, s.x)),
                MParam("kc", "stiffness beyond the gap (per mass)", "{a}/{x}", 0.0, _sym("x", 1, 5.0)),
            ),
            "restoring",
        ),
        Mechanism(
            "bouc_wen",
            "Bouc–Wen hysteresis",
            "a restoring force with memory (friction in joints, plasticity): an added state z",
            "dz/dt = d{x}/dt − b1·|d{x}/dt|·z − b2·d{x}/dt·|z|;  d{v}/dt −= κ·z",
            "loops in the residual against the position, a shift after each reversal",
            _POSITION,
            "pair",
            (
                MParam(
                    "kappa",
                    "hysteretic stiffness (per mass)",
                    "{a}/{x}",
                    0.0,
                    lambda s: (1e-3 * s.a / s.x, 10 * s.a / s.x),
                ),
                MParam("b1", "loop shape β·γ", "1/{x}", 0.0, lambda s: (-50.0 / s.x, 50.0 / s.x)),
                MParam("b2", "loop shape β·δ", "1/{x}", 0.0, lambda s: (-50.0 / s.x, 50.0 / s.x)),
            ),
            "hysteresis",
            added_states=1,
        ),
        Mechanism(
            "prandtl_ishlinskii",
            "Prandtl–Ishlinskii hysteresis",
            "a rate-independent hysteresis: four play operators of thresholds r/8, 3r/8, 5r/8, 7r/8 (added states)",
            "dp_q/dt = play(d{x}/dt; {x} − p_q, r_q);  d{v}/dt −= w·mean(p_q)",
            "loops in the residual against the position, flat after each reversal",
            _POSITION,
            "pair",
            (
                MParam(
                    "w", "hysteretic stiffness (per mass)", "{a}/{x}", 0.0, lambda s: (1e-3 * s.a / s.x, 10 * s.a / s.x)
                ),
                MParam("r", "largest play threshold", "{x}", 1.0, lambda s: (1e-3 * s.x, 2 * s.x)),
            ),
            "hysteresis",
            added_states=4,
        ),
        Mechanism(
            "leak",
            "leak",
            "a loss proportional to the stored quantity (a leak, a discharge, a heat loss)",
            "d{x}/dt −= c·{x}",
            "slow decay of the residual where the stored quantity is large",
            _STORED,
            "self",
            (MParam("c", "leak rate", "1/s", 0.0, lambda s: (1e-4 * s.rate_x / s.x, s.rate_x / s.x)),),
            "leak",
        ),
        Mechanism(
            "orifice_leak",
            "orifice leak",
            "an outflow through an opening, by Torricelli's law",
            "d{x}/dt −= c·√{x}",
            "outflow growing with the square root of the level",
            ("level", "pressure"),
            "self",
            (
                MParam(
                    "c",
                    "orifice coefficient",
                    "{a}/({x})^0.5",
                    0.0,
                    lambda s: (1e-4 * s.rate_x / s.x**0.5, s.rate_x / s.x**0.5),
                ),
            ),
            "leak",
        ),
        Mechanism(
            "power_outflow",
            "power-law outflow",
            "an outflow whose flow follows the stored quantity to a power β other than the model's law (a partly "
            "laminar or throttled outlet, a pipe whose losses change with the flow); c < 0 takes back part of the "
            "model's own outflow",
            "d{x}/dt −= c·{x}^β",
            "residual growing with the level where the model's outflow law is too steep or too flat",
            ("level", "pressure"),
            "self",
            (
                MParam(
                    "c",
                    "outflow coefficient",
                    "{a}/({x})^β",
                    0.0,
                    lambda s: (-s.rate_x / min(1.0, s.x**1.5), s.rate_x / min(1.0, s.x**1.5)),
                ),
                MParam("beta", "exponent of the outflow law", "1", 0.5, lambda s: (0.0, 1.5)),
            ),
            "leak",
            refit_core=True,
        ),
        Mechanism(
            "overflow",
            "bounded state with spill (overflow)",
            "the state cannot exceed a level; what flows in beyond it spills, a share into the state it flows to",
            "at {x} ≥ L with rising {x}: d{x}/dt = 0, the spill s·d{x}/dt into the next state",
            "residual after the largest inputs: the model's state rises above where the measured one stays",
            _STORED,
            "bound",
            (
                MParam("level", "bound of the state", "{x}", 1.0, lambda s: (s.x_lo, 1.2 * s.x)),
                MParam(
                    "share",
                    "spill into the next state per unit of the rate cut",
                    "{a}/({x}/s)",
                    0.0,
                    lambda s: (0.0, 1.5 * s.ratio),
                ),
            ),
            "bound",
        ),
        Mechanism(
            "dead_zone",
            "dead zone",
            "no effect of the input within ±d (a valve, a motor's start voltage)",
            "u → sign(u)·max(|u| − d, 0)",
            "no response to small inputs, residual ∝ sign(u) at small |u|",
            ("input",),
            "input",
            (MParam("d", "half-width of the dead zone", "{u}", 0.0, lambda s: (0.0, 0.5 * s.u)),),
            "input",
        ),
        Mechanism(
            "backlash",
            "backlash",
            "play between the input and the equations (gears, a loose linkage)",
            "u → play(u; r)",
            "delayed response after each input reversal",
            ("input",),
            "input",
            (MParam("r", "half-width of the play", "{u}", 0.0, lambda s: (0.0, 0.25 * s.u_span)),),
            "input",
        ),
        Mechanism(
            "input_polynomial",
            "static input nonlinearity",
            "a curved input characteristic (an actuator's gain changing with the drive)",
            "u → u + a2·u² + a3·u³",
            "even and odd harmonics of the drive",
            ("input",),
            "input",
            (
                MParam("a2", "quadratic coefficient", "1/{u}", 0.0, lambda s: (-1.0 / s.u, 1.0 / s.u)),
                MParam("a3", "cubic coefficient", "1/({u})^2", 0.0, lambda s: (-1.0 / s.u**2, 1.0 / s.u**2)),
            ),
            "input",
        ),
    )
}


def param_ranges(mech: Mechanism, scales: Scales) -> dict[str, tuple[float, float]]:
    """Key → (lo, hi) of each parameter of ``mech`` for the :class:`Scales` of the state it acts on."""
    out = {}
    for mp in mech.params:
        lo, hi = mp.span(scales)
        if not hi > lo:
            hi = lo + max(abs(lo), 1.0)
        out[mp.key] = (float(lo), float(hi))
    return out


def units_of(template: str, units: Mapping[str, str]) -> str:
    """A parameter's unit with the state's, the rate's and the input's units put in."""
    return (
        template.replace("{x}", units.get("x") or "1")
        .replace("{a}", units.get("a") or "1/s")
        .replace("{u}", units.get("u") or "1")
    )
