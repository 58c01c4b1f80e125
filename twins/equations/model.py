"""A user's model given by its equations: states with roles, ``rates(x, u, p)`` and ``output(x, u, p)``.

The model file (:func:`twins.external.load_model`) defines, besides ``Params``:

``STATES``
    ``{"x": "position", "v": "velocity"}`` (name → role, or name → (role, unit)), in the order of ``x``; the
    roles are those of :data:`.catalog.ROLES`.
``rates(x, u, p)``
    the time derivatives of the states (a tuple, in the order of ``STATES``) for the state ``x`` (an array),
    the input ``u`` (a float) and the parameters ``p`` (read by name: ``p.k``); compiled by numba, so written
    with ``math``/``numpy`` functions and float arithmetic (helper functions of the same file are compiled too).
``output(x, u, p)``
    the measured output (a float).

and optionally ``initial_state(p, u0)`` (the state at the first sample; default zeros), ``INPUT`` (``"hold"``:
the input held over each sample, the default; ``"linear"`` or ``"cubic"``: interpolated between samples, for a
sampled smooth signal), ``SUBSTEPS``
(Runge–Kutta steps per sample; default chosen from the records), ``BOUNDS`` (state → (lo, hi), numbers or
parameter names: a state held within them, e.g. a level that cannot be negative) and ``input_map(u, fs, p)`` /
``output_map(y, u, fs, p)`` (vectorised, around the equations: an actuator, a sensor). :class:`EquationSpec`
checks and compiles all of it (a model that does not compile, returns NaN at its initial state or names an
unknown role is refused with one line) and runs it with the mechanisms of :mod:`.catalog` switched in
(:mod:`.kernel`).
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import math
import types
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np

from sysid.errors import ConfigError

from .catalog import MECHANISMS, PAIRS, ROLES, Mechanism
from .kernel import KIND, MECH_COLS, N_PLAY, apply_input, build_integrator, stage_inputs

__all__ = ["EquationSpec", "MechanismSlot", "is_equation_model", "compile_function", "SUBSTEPS_FIELD", "digest"]

#: the twin's parameter holding the Runge–Kutta steps per sample
SUBSTEPS_FIELD = "ode_substeps"
#: how the input goes on between samples (:func:`.kernel.stage_inputs`)
INPUT_MODES = ("hold", "linear", "cubic")
#: inputs at the RK4 stages kept per model (:meth:`EquationSpec.stage_inputs`)
STAGE_MEMO = 8
#: a periodic steady state is reached when one more period moves no state by more than this share of its range
PERIODIC_TOL = 1e-7
#: most periods simulated in the search for the periodic steady state
PERIODIC_PASSES = 60


def is_equation_model(obj: Any) -> bool:
    """The model gives its equations (``STATES`` and ``rates``) rather than ``simulate`` or ``step``."""
    return hasattr(obj, "STATES") or callable(getattr(obj, "rates", None))


@dataclasses.dataclass(frozen=True)
class MechanismSlot:
    """One catalog mechanism placed in a model: its effect id ``KIND@STATE``, the state it acts on (index, or
    -1 for the input), the state its term enters, and its parameter fields (key → field of the twin's Params)."""

    effect: str
    mech: Mechanism
    state: str
    acts: int
    enters: int
    fields: Mapping[str, str]


def _first_line(exc: BaseException) -> str:
    """The informative line of a numba error (its first lines only name the compiler pass)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    skip = ("Failed in", "During:", "Use of unsupported", "<source", "^", "File ")
    useful = [ln for ln in lines if not ln.startswith(skip)]
    where = next((ln for ln in lines if ln.startswith("File ")), "")
    text = useful[0] if useful else (lines[0] if lines else type(exc).__name__)
    return f"{text} ({where})" if where else text


def compile_function(fn: Callable, what: str) -> Any:
    """``fn`` compiled by numba, with the plain functions of its own module that it calls compiled as well."""
    from numba import njit
    from numba.core.registry import CPUDispatcher

    if isinstance(fn, CPUDispatcher):
        return fn
    if not isinstance(fn, types.FunctionType):
        raise ConfigError(f"{what} must be a plain Python function, got {type(fn).__name__}")
    _compile_helpers(fn, set())
    return njit(cache=False)(fn)


def _compile_helpers(fn: types.FunctionType, seen: set[int]) -> None:
    from numba import njit

    glb = fn.__globals__
    for name in fn.__code__.co_names:
        g = glb.get(name)
        if isinstance(g, types.FunctionType) and g.__module__ == fn.__module__ and id(g) not in seen:
            seen.add(id(g))
            _compile_helpers(g, seen)
            glb[name] = njit(cache=False)(g)


class EquationSpec:
    """The checked, compiled equations of a model and the mechanisms the catalog places in them."""

    def __init__(self, obj: Any, name: str, params_cls: type):
        self.name = name
        self.states, self.roles, self.units = _states(obj, name)
        self.n = len(self.states)
        self.params_cls = params_cls
        self.user_fields = [f.name for f in dataclasses.fields(params_cls) if _numeric(f.default)]
        self.ptuple = collections.namedtuple(f"{params_cls.__name__}Values", self.user_fields)  # type: ignore[misc]
        self.rates = compile_function(_need(obj, "rates", name), f"model {name}: rates")
        self.output = compile_function(_need(obj, "output", name), f"model {name}: output")
        self.init = getattr(obj, "initial_state", None)
        self.input_mode = str(getattr(obj, "INPUT", "hold"))
        if self.input_mode not in INPUT_MODES:
            raise ConfigError(f"model {name}: INPUT must be one of {', '.join(INPUT_MODES)}, got {self.input_mode!r}")
        sub = getattr(obj, "SUBSTEPS", None)
        self.auto_substeps = sub is None
        self.substeps = 1 if sub is None else _positive_int(sub, f"model {name}: SUBSTEPS")
        self.bounds = _bounds(obj, name, self.states, params_cls)
        self.input_map = _optional(obj, "input_map", name)
        self.output_map = _optional(obj, "output_map", name)
        self.source = _source_file(obj)
        calib = getattr(obj, "CALIBRATION_PARAMS", None)
        self.calib = tuple(calib) if calib is not None else tuple(self.user_fields)
        self._integrators: dict[Any, Any] = {}
        self.memo: dict[str, Any] = {}  # the last results kept by the twin (:mod:`.twin`)
        p0 = params_cls()
        x0 = self.initial(p0, 0.0)
        self.jac = self._check(p0, x0)
        self.slots = self._place()

    # ------------------------------------------------------------------ checks at load
    def _check(self, p: Any, x0: np.ndarray) -> np.ndarray:
        """Call the compiled rates and output once (compile errors and NaN refused with one line) and return the
        Jacobian of the rates, taken where it is finite near the initial state."""
        from numba.core.errors import NumbaError

        pt = self.values(p)
        try:
            d = np.asarray(self.rates(x0, 0.0, pt), dtype=float).ravel()
            y0 = float(self.output(x0, 0.0, pt))
        except NumbaError as exc:
            raise ConfigError(
                f"model {self.name}: rates()/output() do not compile with numba: {_first_line(exc)}"
            ) from None
        except Exception as exc:  # noqa: BLE001 — the user's code may raise anything; one line says what
            raise ConfigError(f"model {self.name}: rates()/output() failed ({type(exc).__name__}: {exc})") from None
        if d.size != self.n:
            raise ConfigError(f"model {self.name}: rates() returns {d.size} values for the {self.n} states of STATES")
        if not (np.all(np.isfinite(d)) and math.isfinite(y0)):
            raise ConfigError(
                f"model {self.name}: rates()/output() return NaN or inf at the initial state {x0.tolist()} with the "
                "default parameters"
            )
        for x in (x0, x0 + 0.1 * np.maximum(np.abs(x0), 1.0)):
            jac = self.jacobian(x, 0.0, pt)
            if np.all(np.isfinite(jac)):
                return jac
        return np.zeros((self.n, self.n))

    def jacobian(self, x: np.ndarray, u: float, pt: Any) -> np.ndarray:
        """∂rates/∂x by central differences at ``x``."""
        jac = np.empty((self.n, self.n))
        for j in range(self.n):
            h = 1e-6 * max(abs(float(x[j])), 1e-3)
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            jac[:, j] = (np.asarray(self.rates(xp, u, pt)) - np.asarray(self.rates(xm, u, pt))) / (2 * h)
        return jac

    def _place(self) -> list[MechanismSlot]:
        """Every catalog mechanism in every state whose role it takes (module :mod:`.catalog`)."""
        slots = []
        for mech in MECHANISMS.values():
            if mech.enters == "input":
                slots.append(self._slot(mech, "u", -1, -1))
                continue
            for i, (state, role) in enumerate(zip(self.states, self.roles)):
                if role not in mech.roles:
                    continue
                if mech.enters == "pair":
                    j = self._pair(i, role)
                    if j < 0:
                        continue
                elif mech.enters == "bound":
                    j = self._downstream(i)
                else:
                    j = i
                slots.append(self._slot(mech, state, i, j))
        return slots

    def _slot(self, mech: Mechanism, state: str, i: int, j: int) -> MechanismSlot:
        fields = {p.key: f"{mech.kind}_{state}_{p.key}" for p in mech.params}
        if mech.enters == "bound" and j < 0:
            fields.pop("share")
        return MechanismSlot(f"{mech.kind}@{state}", mech, state, i, j, fields)

    def _pair(self, i: int, role: str) -> int:
        """The velocity state whose value drives the rate of position ``i`` (largest |∂ẋ_i/∂v|), or -1."""
        cands = [j for j, r in enumerate(self.roles) if r == PAIRS[role]]
        if not cands:
            return -1
        j = max(cands, key=lambda c: abs(self.jac[i, c]))
        return j if abs(self.jac[i, j]) > 0 else -1

    def _downstream(self, i: int) -> int:
        """The state that state ``i`` flows into (largest ∂ẋ_j/∂x_i > 0, j ≠ i), or -1."""
        cands = [j for j in range(self.n) if j != i and self.jac[j, i] > 0]
        return max(cands, key=lambda c: self.jac[c, i]) if cands else -1

    # ------------------------------------------------------------------ running
    def values(self, p: Any) -> Any:
        """The model's own numeric parameters as the compiled functions read them (a named tuple)."""
        return self.ptuple(*[_typed(getattr(p, f), getattr(self.params_cls, f, None)) for f in self.user_fields])

    def initial(self, p: Any, u0: float) -> np.ndarray:
        """The model's state at the first sample (``initial_state(p, u0)``, default zeros)."""
        if self.init is None:
            return np.zeros(self.n)
        try:
            x0 = np.asarray(self.init(p, float(u0)), dtype=float).ravel()
        except Exception as exc:  # noqa: BLE001
            raise ConfigError(f"model {self.name}: initial_state() failed ({type(exc).__name__}: {exc})") from None
        if x0.size != self.n:
            raise ConfigError(f"model {self.name}: initial_state() returns {x0.size} values for {self.n} states")
        return x0

    def active(self, effects: Iterable[str]) -> list[MechanismSlot]:
        on = set(effects)
        return [s for s in self.slots if s.effect in on]

    def mech_table(self, slots: list[MechanismSlot], p: Any) -> tuple[np.ndarray, int]:
        """The kernel's rows for the active ``slots`` (:mod:`.kernel`) and the number of added states."""
        rows = np.zeros((len(slots), MECH_COLS))
        extra = 0
        for r, s in enumerate(slots):
            e = -1
            if s.mech.added_states:
                e, extra = self.n + extra, extra + (N_PLAY if s.mech.kind == "prandtl_ishlinskii" else 1)
            vals = [float(getattr(p, s.fields[mp.key])) if mp.key in s.fields else 0.0 for mp in s.mech.params]
            rows[r, :4] = (KIND[s.mech.kind], s.acts, s.enters, e)
            rows[r, 4 : 4 + len(vals)] = vals
        return rows, extra

    def integrator(self, sparse: bool = False) -> Any:
        if sparse not in self._integrators:
            self._integrators[sparse] = build_integrator(self.rates, self.output, sparse)
        return self._integrators[sparse]

    def sensitivities(
        self, u: np.ndarray, fs: float, p: Any, effects: Iterable[str], phi: np.ndarray, rows: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(y, S)``: the output and its sensitivity to each forcing column of ``phi`` (samples × C) added to the
        rate of state ``rows[c]`` (:mod:`.tangent`)."""
        from .tangent import build_tangent

        if "tangent" not in self._integrators:
            self._integrators["tangent"] = build_tangent(self.rates, self.output)
        slots = self.active(effects)
        mech, extra = self.mech_table(slots, p)
        u = apply_input(self.mapped_input(np.ascontiguousarray(u, dtype=np.float64), fs, p), mech)
        x0 = np.concatenate([self.initial(p, float(u[0]) if u.size else 0.0), np.zeros(extra)])
        lo, hi = self._limits(slots, mech, extra, p)
        sub = int(getattr(p, SUBSTEPS_FIELD, self.substeps))
        args = (self.values(p), x0, self.stage_inputs(u, sub), 1.0 / float(fs), mech, lo, hi)
        return self._integrators["tangent"](*args, np.ascontiguousarray(phi, np.float64), np.asarray(rows, np.int64))

    def stage_inputs(self, u: np.ndarray, substeps: int) -> np.ndarray:
        """The input at the RK4 stages (:func:`.kernel.stage_inputs`), the :data:`STAGE_MEMO` last used kept (a trial
        simulates the same records again and again; a trial of an input effect, a delay, makes a new input at every
        evaluation, which should not push the records' own out first)."""
        key = (digest(u), substeps)
        memo = self.memo.setdefault("stage_inputs", collections.OrderedDict())
        if key in memo:
            memo.move_to_end(key)
            return memo[key]
        memo[key] = out = stage_inputs(u, substeps, self.input_mode)
        if len(memo) > STAGE_MEMO:
            memo.popitem(last=False)
        return out

    def _limits(
        self, slots: list[MechanismSlot], mech: np.ndarray, extra: int, p: Any
    ) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = np.full(self.n + extra, -np.inf), np.full(self.n + extra, np.inf)
        for i, (a, b) in self.bounds.items():
            lo[i] = -np.inf if a is None else float(getattr(p, a) if isinstance(a, str) else a)
            hi[i] = np.inf if b is None else float(getattr(p, b) if isinstance(b, str) else b)
        for r, s in enumerate(slots):
            if s.mech.kind == "overflow":
                hi[s.acts] = min(hi[s.acts], mech[r, 4])
        return lo, hi

    def run(
        self,
        u: np.ndarray,
        fs: float,
        p: Any,
        effects: Iterable[str] = (),
        keep: bool = False,
        sparse: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        force: np.ndarray | None = None,
        x0: np.ndarray | str | None = None,
        mode: str | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(y, X)``: the output for the input samples ``u`` at ``fs`` [Hz] with the mechanisms ``effects`` on, and
        the states at every sample when ``keep`` (the added states after the model's own); ``x0`` a start other than
        the initial state (augmented), or ``"periodic"``: the periodic steady state of the record
        (:meth:`periodic_state`); ``mode`` an input interpolation other than the model's (a stepper's)."""
        if isinstance(x0, str):
            if x0 != "periodic":
                raise ConfigError(f"model {self.name}: initial state {x0!r}: give an array or 'periodic'")
            x0 = self.periodic_state(u, fs, p, effects, mode=mode)
        slots = self.active(effects)
        mech, extra = self.mech_table(slots, p)
        u_given = np.ascontiguousarray(u, dtype=np.float64)
        u = apply_input(self.mapped_input(u_given, fs, p), mech)
        if x0 is None:
            x0 = np.concatenate([self.initial(p, float(u[0]) if u.size else 0.0), np.zeros(extra)])
        lo, hi = self._limits(slots, mech, extra, p)
        sub = int(getattr(p, SUBSTEPS_FIELD, self.substeps))
        with_sparse = sparse is not None or force is not None
        sp_exp, sp_row, sp_coef = sparse or (np.zeros((0, self.n + 1), np.int64), np.zeros(0, np.int64), np.zeros(0))
        frc = np.zeros((0, self.n)) if force is None else np.ascontiguousarray(force, dtype=np.float64)
        uf = self.stage_inputs(u, sub) if mode is None else stage_inputs(u, sub, mode)
        args = (self.values(p), np.asarray(x0, dtype=np.float64), uf, 1.0 / float(fs), mech, lo, hi)
        y, X = self.integrator(with_sparse)(*args, sp_exp, sp_row, sp_coef, frc, keep)
        if self.output_map is not None:
            y = np.asarray(self.output_map(y, u_given, float(fs), p), dtype=float)
        return y, X

    def periodic_state(
        self, u: np.ndarray, fs: float, p: Any, effects: Iterable[str] = (), mode: str | None = None
    ) -> np.ndarray:
        """The (augmented) state at the first sample of a record that is whole periods of a periodic input in steady
        state: a period of a multisine recorded after its transient died out, as benchmarks give their test records
        (the Bouc–Wen benchmark's multisine test: its true model scores 4.6·10⁻⁵ m from rest, 2.6·10⁻⁷ m from this
        state). It is the fixed point of the period map x(t_0) → x(t_0 + N/fs), iterated from the model's initial
        state over the record closed on itself (the input after the last sample runs on to the first) until one
        more period moves no state by more than :data:`PERIODIC_TOL` of its range over the period, at most
        :data:`PERIODIC_PASSES` periods (then the last iterate: a state that drifts has no steady state). A run that
        turns non-finite gives the initial state back."""
        u = np.ascontiguousarray(u, dtype=np.float64)
        closed = np.append(u, u[:1])
        x: np.ndarray | None = None
        for _ in range(PERIODIC_PASSES):
            y, X = self.run(closed, fs, p, effects, keep=True, x0=x, mode=mode)
            if not (np.all(np.isfinite(y)) and np.all(np.isfinite(X[-1]))):
                break
            end = X[-1].copy()
            span = np.ptp(X, axis=0) + 1e-300
            if x is not None and np.all(np.abs(end - x) <= PERIODIC_TOL * span):
                return end
            x = end
        if x is not None and np.all(np.isfinite(x)):
            return x
        slots = self.active(effects)
        extra = self.mech_table(slots, p)[1]
        return np.concatenate([self.initial(p, float(u[0]) if u.size else 0.0), np.zeros(extra)])

    def mapped_input(self, u: np.ndarray, fs: float, p: Any) -> np.ndarray:
        """The input through the model's own ``input_map`` (the input as it reaches the equations)."""
        if self.input_map is None:
            return u
        return np.ascontiguousarray(self.input_map(u, float(fs), p), dtype=np.float64)


def digest(a: np.ndarray) -> bytes:
    """A short digest of an array's values and shape (the key of the results kept)."""
    b = np.ascontiguousarray(a, dtype=np.float64)
    buf = memoryview(b).cast("B")  # type: ignore[arg-type]  # an ndarray exports the buffer protocol
    return hashlib.blake2b(buf, digest_size=16).digest() + str(b.shape).encode()


def _need(obj: Any, attr: str, name: str) -> Callable:
    fn = getattr(obj, attr, None)
    if not callable(fn):
        raise ConfigError(f"model {name}: a model with STATES needs {attr}(x, u, p)")
    return fn


def _states(obj: Any, name: str) -> tuple[list[str], list[str], list[str]]:
    raw = getattr(obj, "STATES", None)
    if isinstance(raw, Mapping):
        items = list(raw.items())
    elif isinstance(raw, (list, tuple)) and all(isinstance(it, (list, tuple)) and len(it) >= 2 for it in raw):
        items = [(it[0], tuple(it[1:]) if len(it) > 2 else it[1]) for it in raw]
    else:
        raise ConfigError(f"model {name}: STATES must map each state's name to its role, e.g. {{'x': 'position'}}")
    if not items:
        raise ConfigError(f"model {name}: STATES is empty")
    states, roles, units = [], [], []
    for key, val in items:
        role, unit = (val[0], str(val[1])) if isinstance(val, (list, tuple)) else (val, "")
        if not (isinstance(key, str) and key.isidentifier()) or key in states:
            raise ConfigError(f"model {name}: state name {key!r} must be a unique Python identifier")
        if role not in ROLES:
            raise ConfigError(
                f"model {name}: state {key!r} has role {role!r}, not a known role; valid: {', '.join(ROLES)}"
            )
        states.append(key)
        roles.append(str(role))
        units.append(unit)
    return states, roles, units


def _bounds(obj: Any, name: str, states: list[str], params_cls: type) -> dict[int, tuple[Any, Any]]:
    """State index → (lo, hi), each a number, None or the name of a parameter (read at every run)."""
    own = {f.name for f in dataclasses.fields(params_cls)}
    out: dict[int, tuple[Any, Any]] = {}
    for key, pair in dict(getattr(obj, "BOUNDS", {}) or {}).items():
        if key not in states:
            raise ConfigError(f"model {name}: BOUNDS names {key!r}, not a state; valid: {', '.join(states)}")
        try:
            a, b = pair
        except (TypeError, ValueError):
            raise ConfigError(f"model {name}: BOUNDS[{key!r}] must be (lo, hi), got {pair!r}") from None
        for v in (a, b):
            if isinstance(v, str) and v not in own:
                raise ConfigError(f"model {name}: BOUNDS[{key!r}] names {v!r}, not a parameter of Params")
            if v is not None and not isinstance(v, (str, int, float)):
                raise ConfigError(f"model {name}: BOUNDS[{key!r}] must hold numbers, None or parameter names")
        out[states.index(key)] = (a, b)
    return out


def _optional(obj: Any, attr: str, name: str) -> Callable | None:
    fn = getattr(obj, attr, None)
    if fn is not None and not callable(fn):
        raise ConfigError(f"model {name}: {attr} must be a function")
    return fn


def _source_file(obj: Any) -> str | None:
    """The .py file a model module came from (None for a model that is an object inside a module)."""
    import inspect

    if not isinstance(obj, types.ModuleType):
        return None
    try:
        return inspect.getsourcefile(obj)
    except TypeError:
        return None


def _numeric(v: Any) -> bool:
    return isinstance(v, (int, float, bool)) and not isinstance(v, complex)


def _typed(v: Any, like: Any) -> Any:
    """``v`` as the type of the field's default (numba compiles one version per type)."""
    if isinstance(like, bool):
        return bool(v)
    if isinstance(like, int):
        return int(v)
    return float(v)


def _positive_int(v: Any, what: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ConfigError(f"{what} must be a positive integer, got {v!r}")
    return int(v)
