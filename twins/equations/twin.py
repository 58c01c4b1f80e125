"""The twin of a model given by its equations: the mechanisms of the catalog as the model's own effects.

:func:`equation_twin_class` builds an :class:`twins.external.ExternalTwin` whose core integrates the model
(:class:`.model.EquationSpec`) and whose catalog holds, besides the generic effects around the model, one effect
``KIND@STATE`` per mechanism the model's states can take (:mod:`.catalog`), with its parameters as fields of the
twin's ``Params``. So the diagnosis tries mechanisms inside the equations with the same trials, ranking and
F-test as every other effect. Their ranges follow the records: before the calibration from the model as given,
after it (:meth:`EquationTwin.follow_calibration`, a hook of :func:`twins.discrepancy.run_diagnosis`) from the
calibrated model's state amplitudes; the Runge–Kutta steps per sample are chosen there too (:func:`choose_substeps`).
"""

from __future__ import annotations

import collections
import dataclasses
import inspect
from pathlib import Path
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import ConfigError
from twins.base import EffectSpec
from twins.external.twin import ExternalTwin, _Renamed, external_twin_class, start_declarations
from twins.generic_effects import apply_input, apply_output, sensor_lowpass
from twins.paramfields import param_info, pfield, with_ranges

from .catalog import Scales, param_ranges, units_of
from .model import SUBSTEPS_FIELD, EquationSpec, MechanismSlot, digest
from .starts import best_start, direct_start, spread_starts, start_values

__all__ = ["EquationTwin", "equation_twin_class", "choose_substeps", "scales_of"]

#: most Runge–Kutta steps per sample the automatic choice takes
MAX_SUBSTEPS = 64
#: the step is fine enough when halving it moves the output by less than this share of its RMS
SUBSTEP_TOL = 1e-3
#: where in its range a bound's refits with the core start (:meth:`EquationTwin.core_starts`)
BOUND_STARTS = (0.25, 0.45, 0.65)
#: outputs of the equations kept per model (the estimation, validation and joined records of a few configurations)
CORE_MEMO = 6


class EquationTwin(ExternalTwin):
    """A model's equations with the generic effects around them and the catalog's mechanisms inside."""

    SPEC: Any = None  # the model's EquationSpec
    JOINT_TRIALS = True  # the diagnosis tries a sizeable leader that is not significant alone in pairs (.pairs)

    def states(self, u: np.ndarray, fs: float) -> np.ndarray:
        """The model's states (and the mechanisms' added states) at every sample of the input ``u`` at ``fs``."""
        return self.run(u, fs, keep=True)[1]

    def simulate_periodic(self, u: np.ndarray, fs: float) -> np.ndarray:
        """:meth:`simulate` of a record that is whole periods of a periodic input in steady state (a multisine test
        record taken after its transient): the equations start in their periodic steady state
        (:meth:`.model.EquationSpec.periodic_state`); the effects around them start as in :meth:`simulate`."""
        return self.run(u, fs, x0="periodic")[0]

    def run(
        self,
        u: np.ndarray,
        fs: float,
        keep: bool = False,
        force: np.ndarray | None = None,
        sparse: Any = None,
        x0: np.ndarray | str | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(y, X)``: :meth:`simulate` with the generic effects around the equations, the states X at every
        sample when ``keep``, an additive forcing of the rates (samples × states) when ``force`` is given, a sparse
        term (:mod:`.sparse`) when ``sparse`` is, the equations started at ``x0`` (an augmented state, or
        ``"periodic"``) when it is given."""
        gp = _Renamed(self.params, self.GENERIC_NAMES)
        u = np.asarray(u, float)
        v = apply_input(u, fs, self.effects, gp, self.INPUT_HELD)
        own = self.effects & self.MODEL_EFFECTS
        y, X = self.SPEC.run(v, fs, self.model_params(), own, keep=keep, force=force, sparse=sparse, x0=x0)
        return apply_output(y, u, fs, self.effects, gp), X

    def start_values(self, effect: str, est: Record, skip: int = 0) -> dict[str, float] | None:
        """Starting values of a mechanism's parameters from the equation residual (:mod:`.starts`), for the
        diagnosis's trials; None for an effect that is not a mechanism or that the residual cannot size."""
        found = self._starts(effect, est, skip, spread=False)
        return found[0] if found else None

    def _starts(self, effect: str, est: Record, skip: int, spread: bool) -> list[dict[str, float]]:
        """The start of ``effect`` (:meth:`start_values`), or with ``spread`` the starts of shapes spread over
        its grid (:func:`.starts.spread_starts`); empty where there is none."""
        slot = next((s for s in self.SPEC.slots if s.effect == effect), None)
        if slot is None:
            return []
        base = self.with_effects(self.effects - {effect})
        y0, X = base._baseline(est)
        if not (np.all(np.isfinite(y0)) and np.all(np.isfinite(X))):
            return []
        if slot.mech.kind in ("overflow", "dead_zone", "backlash", "input_polynomial"):

            def run(vals: dict[str, Any]) -> np.ndarray:
                if "_u" in vals:
                    return base.run(vals["_u"], est.fs)[0]
                return self.with_params(**vals).run(est.u, est.fs)[0]

            start = direct_start(slot, self.params, y0, est, skip, run)
            return [start] if start else []
        found = start_values(slot, self.params, X, y0, est, skip, lambda phi, rows: base.sensitivity(est, phi, rows))
        if spread:
            return spread_starts(found)
        start = best_start(found)
        return [start] if start else []

    def core_starts(self, effect: str, est: Record, skip: int = 0) -> list[dict[str, float]]:
        """Starts of a refit of ``effect`` together with the core, for a mechanism that changes what the core's
        parameters stand for (a hook of the diagnosis, which refits from each): a restoring force or a hysteresis
        adds stiffness the calibration has taken up (its start from the equation residual); a bound caps a flow the
        calibration has bent to (bounds at :data:`BOUND_STARTS` of the state's range, the spill at the middle of its
        range); a mechanism declared ``refit_core`` (a power-law outflow) from the equation-residual starts of its
        three best shapes. Empty for every other effect: rivals for the same residual are refitted alike."""
        slot = next((s for s in self.SPEC.slots if s.effect == effect), None)
        if slot is None or not (slot.mech.family in ("restoring", "hysteresis", "bound") or slot.mech.refit_core):
            return []
        tw = self.with_effects(set(self.effects) | {effect})
        if slot.mech.refit_core:
            return tw._starts(effect, est, skip, spread=True)
        if slot.mech.family != "bound":
            start = tw.start_values(effect, est, skip)
            return [start] if start else []
        info = param_info(type(tw.params))
        lo, hi = info[slot.fields["level"]].bounds()
        out = []
        for q in BOUND_STARTS:
            point = {slot.fields["level"]: lo + q * (hi - lo)}
            if "share" in slot.fields:
                point[slot.fields["share"]] = 0.5 * sum(info[slot.fields["share"]].bounds())
            out.append(point)
        return out

    def sensitivity(self, rec: Record, phi: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The output's sensitivity to forcings ``phi`` (samples × C) added to the rates ``rows`` (:mod:`.tangent`),
        through the generic output effects that are linear in the output (others are ignored: a start value)."""
        gp = _Renamed(self.params, self.GENERIC_NAMES)
        v = apply_input(np.asarray(rec.u, float), rec.fs, self.effects, gp, self.INPUT_HELD)
        own = self.effects & self.MODEL_EFFECTS
        S = self.SPEC.sensitivities(v, rec.fs, self.model_params(), own, phi, rows)[1]
        if "sensor_lowpass" in self.effects:
            S = np.column_stack(
                [sensor_lowpass(S[:, c], float(gp.sensor_bandwidth_hz), rec.fs) for c in range(S.shape[1])]
            )
        return S

    def sparse_term(self, est: Record, val: Record, skip: int, alpha: float) -> tuple[dict[str, Any], Any]:
        """The sparse term in the states and the input that the forward regression finds on the equation residual
        of this configuration (:func:`.sparse.sparse_block`): a hook of the diagnosis when it ends far above the
        noise."""
        from .sparse import sparse_block

        return sparse_block(self, est, val, skip, alpha)

    def _baseline(self, rec: Record) -> tuple[np.ndarray, np.ndarray]:
        """The output and states on ``rec`` (the last one kept: a round asks it once per candidate)."""
        key = (digest(rec.u), rec.fs, _values(self.params), self.effects)
        hit = self.SPEC.memo.get("baseline")
        if hit is None or hit[0] != key:
            hit = (key, self.run(rec.u, rec.fs, keep=True))
            self.SPEC.memo["baseline"] = hit
        return hit[1]

    def follow_records(self, est: Record, val: Record) -> tuple[ExternalTwin, list[str]]:
        """The generic effects' ranges (:meth:`ExternalTwin.follow_records`), then the steps per sample and the
        mechanisms' ranges from the model as given."""
        tw, notes = super().follow_records(est, val)
        assert isinstance(tw, EquationTwin)
        return tw._follow(est, notes)

    def follow_calibration(self, est: Record, val: Record) -> tuple[EquationTwin, list[str]]:
        """After the calibration: the steps per sample and the mechanisms' ranges from the calibrated model."""
        return self._follow(est, [])

    def make_stepper(self, fs: float) -> EquationStepper:
        """A per-sample stepper of this configuration at ``fs`` [Hz] (an FMU's core, :mod:`twins.fmu.cores`)."""
        return EquationStepper(self, fs)

    def finer_step(self, est: Record, val: Record) -> EquationTwin:
        """This configuration with its steps per sample re-chosen, only ever more (a hook of the diagnosis for every
        configuration it adopts: an added hysteresis can need a finer step than the model as given)."""
        if not self.SPEC.auto_substeps:
            return self
        m0 = int(getattr(self.params, SUBSTEPS_FIELD))
        m = choose_substeps(self, est, start=m0)
        return self.with_params(**{SUBSTEPS_FIELD: m}) if m > m0 else self

    def _follow(self, est: Record, notes: list[str]) -> tuple[EquationTwin, list[str]]:
        tw: EquationTwin = self
        if self.SPEC.auto_substeps:  # only ever finer: a step the records needed once stays
            m0 = int(getattr(self.params, SUBSTEPS_FIELD))
            m = choose_substeps(self, est, start=m0)
            if m != m0:
                tw = tw.with_params(**{SUBSTEPS_FIELD: m})
                notes.append(f"{SUBSTEPS_FIELD} {m0} -> {m}: Runge-Kutta steps per sample for this record")
        ranges, note = mechanism_ranges(tw, est)
        if note:
            notes.append(note)
        return tw._with_mechanism_ranges(ranges), notes

    def _with_mechanism_ranges(self, ranges: dict[str, tuple[float, float]]) -> EquationTwin:
        if not ranges:
            return self
        params = with_ranges(self.params, ranges, "mechanism ranges from the records")
        info = param_info(type(params))
        on = {f for s in self.SPEC.active(self.effects) for f in s.fields.values()}
        moved = {
            k: float(np.clip(getattr(params, k), *ranges[k])) if k in on else _start_value(k, info[k].range)
            for k in ranges
        }
        return type(self)(dataclasses.replace(params, **moved), self.effects, self.seed)


class EquationStepper:
    """``step(u_k) -> y_k``, one sample at a time, as :meth:`EquationTwin.simulate` gives them: the state advances
    over [t_k−1, t_k] with u_k−1 held or interpolated linearly to u_k (a cubic input is interpolated linearly: the
    next sample is not known yet), then y_k = output(x_k, u_k). Effects around the equations that act on the whole
    record (a delay, a sensor filter, a drift; a model's ``input_map``/``output_map``) cannot be stepped: refused
    with NotImplementedError, as :func:`twins.fmu.cores.choose_core` expects."""

    def __init__(self, twin: EquationTwin, fs: float):
        spec = twin.SPEC
        around = sorted(twin.effects - twin.MODEL_EFFECTS - STEPPABLE)
        maps = [m for m in ("input_map", "output_map") if getattr(spec, m) is not None]
        if around or maps or any(s.mech.kind == "backlash" for s in spec.active(twin.effects)):
            what = ", ".join(around + maps) or "backlash"
            raise NotImplementedError(f"{twin.name}: {what} act on the whole record and cannot be stepped per sample")
        self.twin, self.fs = twin, float(fs)
        self.reset()

    def reset(self) -> None:
        self.x: np.ndarray | None = None
        self.u_prev = 0.0

    def retune(self, twin: EquationTwin) -> None:
        self.twin = twin

    def step(self, u: float) -> float:
        tw, spec = self.twin, self.twin.SPEC
        p = tw.model_params()
        own = tw.effects & tw.MODEL_EFFECTS
        if self.x is None:
            y, X = spec.run(np.array([float(u)]), self.fs, p, own, keep=True)
        else:
            pair = np.array([self.u_prev, float(u)])
            mode = "hold" if spec.input_mode == "hold" else "linear"
            y, X = spec.run(pair, self.fs, p, own, keep=True, x0=self.x, mode=mode)
            y, X = y[1:], X[1:]
        self.x, self.u_prev = X[0].copy(), float(u)
        gp = _Renamed(tw.params, tw.GENERIC_NAMES)
        return float(apply_output(y, np.array([float(u)]), self.fs, tw.effects, gp)[0])


#: effects around the equations that act sample by sample (a stepper applies them)
STEPPABLE = frozenset({"sensor_offset", "input_crosstalk", "output_quantization"})


def _start_value(field: str, rng: tuple[Any, Any]) -> float:
    """Where an added mechanism's parameter starts: the value that makes it do nothing where the range has one
    (0, a bound above the record, a gap as wide as the motion), else the range's geometric middle."""
    lo, hi = float(rng[0]), float(rng[1])
    key = field.rsplit("_", 1)[-1]
    if (field.startswith("overflow_") and key == "level") or key == "gap":
        return hi
    if lo <= 0.0 <= hi:
        return 0.0
    return float(np.sqrt(lo * hi)) if lo > 0 else 0.5 * (lo + hi)


def scales_of(twin: EquationTwin, X: np.ndarray, u: np.ndarray, fs: float, slot: MechanismSlot) -> Scales:
    """The :class:`.catalog.Scales` of ``slot`` from the states ``X`` at every sample of the input ``u``."""
    spec = twin.SPEC

    def peak(a: np.ndarray) -> float:
        v = float(np.max(np.abs(a))) if a.size else 0.0
        return v if v > 0 and np.isfinite(v) else 1.0

    def rate(k: int) -> np.ndarray:
        return np.diff(X[:, k]) * fs

    umax, uspan = peak(u), float(np.ptp(u)) or 1.0
    if slot.acts < 0:
        return Scales(u=umax, u_span=uspan)
    i, j = slot.acts, slot.enters
    x = X[:, i]
    ratio = 1.0
    if slot.mech.enters == "bound" and j >= 0:
        xm = np.median(X[:, : spec.n], axis=0)
        jac = spec.jacobian(xm, float(np.median(u)), spec.values(twin.model_params()))
        ratio = float(-jac[j, i] / jac[i, i]) if jac[i, i] < 0 and jac[j, i] > 0 else 1.0
    a_state = j if slot.mech.enters == "pair" else i
    return Scales(
        x=peak(x),
        x_lo=float(np.percentile(x, 5)),
        v=peak(X[:, j]) if slot.mech.enters == "pair" else peak(x),
        a=peak(rate(a_state)),
        rate_x=peak(rate(i)),
        u=umax,
        u_span=uspan,
        ratio=abs(ratio) if np.isfinite(ratio) and ratio != 0 else 1.0,
    )


def mechanism_ranges(twin: EquationTwin, est: Record) -> tuple[dict[str, tuple[float, float]], str]:
    """Field → (lo, hi) for every mechanism parameter, from the model as it stands simulated on ``est``; empty
    (and a note) when that simulation fails."""
    X = twin.states(est.u, est.fs)
    if X.size == 0 or not np.all(np.isfinite(X)):
        return {}, "the mechanisms keep their ranges: the model's simulation of the record is not finite"
    out: dict[str, tuple[float, float]] = {}
    for slot in twin.SPEC.slots:
        r = param_ranges(slot.mech, scales_of(twin, X, np.asarray(est.u, float), est.fs, slot))
        out.update({slot.fields[k]: v for k, v in r.items() if k in slot.fields})
    return out, ""


def choose_substeps(twin: EquationTwin, est: Record, start: int = 1) -> int:
    """The fewest Runge–Kutta steps per sample (``start``, 2·``start`` … :data:`MAX_SUBSTEPS`) for which doubling
    them moves the simulated output of ``est`` by less than :data:`SUBSTEP_TOL` of its RMS (RK4's error falls 32×
    per halving, so the difference is the coarser step's error)."""
    spec, p = twin.SPEC, twin.model_params()
    own = twin.effects & twin.MODEL_EFFECTS
    u = np.asarray(est.u, float)

    def run(m: int) -> np.ndarray:
        return spec.run(u, est.fs, dataclasses.replace(p, **{SUBSTEPS_FIELD: m}), own)[0]

    m = max(int(start), 1)
    y = run(m)
    while m < MAX_SUBSTEPS:
        y2 = run(2 * m)
        scale = float(np.sqrt(np.mean(y2**2))) if np.all(np.isfinite(y2)) else 0.0
        if scale > 0 and np.all(np.isfinite(y)) and np.sqrt(np.mean((y - y2) ** 2)) <= SUBSTEP_TOL * scale:
            return m
        m, y = 2 * m, y2
    return m


def _values(p: Any) -> tuple[Any, ...]:
    return tuple(getattr(p, f.name) for f in dataclasses.fields(p))


def _mechanism_effects(spec: EquationSpec, name: str) -> tuple[list[tuple[str, type, Any]], dict[str, EffectSpec]]:
    """The Params fields and catalog entries of every mechanism slot of ``spec``."""
    fields: list[tuple[str, type, Any]] = []
    effects: dict[str, EffectSpec] = {}
    for s in spec.slots:
        units = _slot_units(spec, s)
        rng = param_ranges(s.mech, Scales())
        for mp in s.mech.params:
            if mp.key in s.fields:
                lo, hi = rng[mp.key]
                default = min(max(0.0, lo), hi)
                doc = f"{s.mech.title} on {s.state}: {mp.doc}"
                fields.append((s.fields[mp.key], float, pfield(default, units_of(mp.unit, units), lo, hi, doc)))
        target = f"the rate of {spec.states[s.enters]}" if s.enters >= 0 and s.mech.enters == "pair" else ""
        where = "the input" if s.acts < 0 else f"{s.state} ({spec.roles[s.acts]})"
        law = s.mech.law.replace("{x}", s.state).replace("{v}", spec.states[s.enters] if s.enters >= 0 else "")
        effects[s.effect] = EffectSpec(
            s.effect,
            name,
            f"{s.mech.title} on {where}: {s.mech.meaning}; {law}" + (f" (enters {target})" if target else ""),
            s.mech.signature,
            dict(s.fields),
            group=f"{s.mech.family}@{s.state}",
            nests=tuple(f"{k}@{s.state}" for k in s.mech.nests),
            nest_contrast=tuple((s.fields[k], w) for k, w in s.mech.nest_contrast if k in s.fields),
        )
    return fields, effects


def _slot_units(spec: EquationSpec, s: MechanismSlot) -> dict[str, str]:
    if s.acts < 0:
        return {}
    ux = spec.units[s.acts]
    ue = spec.units[s.enters] if s.enters >= 0 else ux
    return {"x": ux, "a": _per_second(ue)}


def _per_second(unit: str) -> str:
    """The unit of a state's rate: ``V`` → ``V/s``, ``m/s`` → ``m/s^2``."""
    if not unit:
        return ""
    return unit[:-2] + "/s^2" if unit.endswith("/s") else f"{unit}/s"


def equation_twin_class(obj: Any, default_name: str = "model") -> type[ExternalTwin]:
    """The twin class of a model given by its equations (:mod:`.model`); refused with one line when the equations
    do not compile, return NaN at the initial state or name an unknown role."""
    name = f"model:{getattr(obj, 'NAME', default_name)}"
    params_cls = getattr(obj, "Params", None)
    if not (isinstance(params_cls, type) and dataclasses.is_dataclass(params_cls)):
        raise ConfigError(f"model {name}: defines no Params (a dataclass of its parameters)")
    try:
        params_cls()
    except TypeError as exc:
        raise ConfigError(f"model {name}: every parameter needs a default value ({exc})") from None
    spec = EquationSpec(obj, name, params_cls)
    mfields, meffects = _mechanism_effects(spec, name)
    own = {f.name for f in dataclasses.fields(params_cls)}
    clash = sorted(own & ({f[0] for f in mfields} | {SUBSTEPS_FIELD}))
    if clash:
        raise ConfigError(f"model {name}: parameter {clash[0]!r} clashes with a catalog mechanism's; rename it")
    sub = pfield(spec.substeps, "1", 1, 1024, "Runge-Kutta steps per sample", source="twins.equations")
    extended = dataclasses.make_dataclass(
        params_cls.__name__, [*mfields, (SUBSTEPS_FIELD, int, sub)], bases=(params_cls,)
    )
    extended.__doc__ = params_cls.__doc__
    extended.__module__ = params_cls.__module__
    user_effects = getattr(obj, "EFFECTS", None)
    if user_effects:
        raise ConfigError(
            f"model {name}: a model with STATES declares no EFFECTS (the catalog's mechanisms are its effects)"
        )

    def core(u: np.ndarray, fs: float, p: Any, effects: frozenset) -> np.ndarray:
        # the last outputs kept: a trial of an effect on the output side (a sensor, an offset) with the equations'
        # parameters held scans its own parameters over one simulation of the equations
        key = (digest(u), float(fs), _values(p), frozenset(effects))
        memo = spec.memo.setdefault("core", collections.OrderedDict())
        if key in memo:
            memo.move_to_end(key)
            return memo[key]
        y = spec.run(u, fs, p, effects)[0]
        memo[key] = y
        if len(memo) > CORE_MEMO:
            memo.popitem(last=False)
        return y

    cls: Any = external_twin_class(
        name,
        core,
        extended,
        meffects,
        getattr(obj, "CALIBRATION_PARAMS", None),
        getattr(obj, "UNITS", None),
        doc=inspect.getdoc(obj) or "",
        base=EquationTwin,
        **start_declarations(obj),
    )
    cls.SPEC = spec
    if spec.source is not None:  # found again from its file, where an FMU ships it (:mod:`.loaded`)
        cls.__module__ = "twins.equations.loaded"
        cls.__qualname__ = Path(spec.source).stem
        cls.FMU_FILES = (spec.source,)
    return cls
