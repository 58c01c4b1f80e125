"""The extended model handed back: a model given by its equations written out with what the diagnosis added.

:func:`write_model` writes a Python model file (``piezotwin diagnose --model FILE.py --save-model OUT.py``) that
reproduces the diagnosis's final configuration: the user's file verbatim, then a section that keeps its functions
under new names (``rates_as_given`` …) and defines

- ``Params`` with the calibrated values as defaults and a field for every parameter of an added mechanism,
- ``rates(x, u, p)`` calling the given rates and adding each mechanism's term by its law (:mod:`.laws`), with the
  states a hysteresis adds appended to ``STATES``,
- ``BOUNDS`` for a bounded state (its bound is a parameter), ``SUBSTEPS`` as chosen for the records,
- ``input_map``/``output_map`` for the effects around the equations (a delay, a sensor, an offset ...), applied by
  the project's own code (:mod:`twins.generic_effects`),
- a sparse term, when the diagnosis fitted a significant one, as its monomials.

The file loads with :func:`twins.external.load_model` like any model and simulates as the diagnosis's twin did
(to rounding), so it can be diagnosed again or exported (``piezotwin export-fmu --model OUT.py``). Written
atomically (:func:`sysid.data.safeio.atomic_path`).
"""

from __future__ import annotations

import dataclasses
import datetime
from pathlib import Path
from typing import Any

from sysid.data.safeio import atomic_path
from sysid.errors import ConfigError
from twins.generic_effects import GENERIC_EFFECTS, GENERIC_FIELDS, INPUT_SIDE
from twins.paramfields import param_info

from .kernel import N_PLAY
from .model import SUBSTEPS_FIELD, MechanismSlot
from .sparse import term_text

__all__ = ["write_model", "extended_source"]

GENERIC_EFFECTS_FIELDS = tuple(GENERIC_FIELDS)


def write_model(twin: Any, path: str | Path, summary: str = "", sparse: Any = None, sparse_text: str = "") -> Path:
    """Write the extended model of ``twin`` (an :class:`.twin.EquationTwin` as the diagnosis left it) to ``path``;
    ``summary`` goes into its docstring, ``sparse`` is the sparse term to include (:mod:`.sparse`)."""
    text = extended_source(twin, summary, sparse, sparse_text)
    path = Path(path)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return path


def _source(twin: Any) -> tuple[str, Path]:
    src = twin.SPEC.source
    if src is None:
        raise ConfigError(f"model {twin.name}: only a model defined at the top of a .py file can be written back")
    return Path(src).read_text(encoding="utf-8"), Path(src)


def extended_source(twin: Any, summary: str = "", sparse: Any = None, sparse_text: str = "") -> str:
    """The text of the extended model file (module docstring)."""
    spec = twin.SPEC
    text, src = _source(twin)
    future = [ln for ln in text.splitlines() if ln.startswith("from __future__")]
    body = "\n".join(ln for ln in text.splitlines() if not ln.startswith("from __future__")).strip("\n")
    slots = spec.active(twin.effects)
    generic = sorted(e for e in twin.effects if e in GENERIC_EFFECTS)
    added: list[str] = [f"{s.effect}: {s.mech.title} on {s.state}" for s in slots]
    added += [f"{e}: {GENERIC_EFFECTS[e].description}" for e in generic]
    if sparse is not None:
        added.append(f"a sparse term (no catalog mechanism): {sparse_text}")
    doc = [
        f'"""{spec.name.removeprefix("model:")}, extended by ``piezotwin diagnose`` on {datetime.date.today()}.',
        "",
        f"The model as given in {src.name} (reproduced unchanged below), calibrated, with what the diagnosis added:",
        "",
        *[f"- {a}" for a in added],
    ]
    if summary:
        doc += ["", *_wrap(summary)]
    doc.append('"""')
    out = [*doc, "", *future, "", "# " + "-" * 40 + f" the model as given ({src.name})", body, ""]
    out += ["", "# " + "-" * 40 + " added by the diagnosis", *_section(twin, slots, generic, sparse)]
    return "\n".join(out).rstrip() + "\n"


def _wrap(text: str, width: int = 110) -> list[str]:
    words, lines, cur = text.split(), [], ""
    for w in words:
        if len(cur) + len(w) + 1 > width:
            lines.append(cur)
            cur = w
        else:
            cur = f"{cur} {w}".strip()
    return [*lines, cur] if cur else lines


def _section(twin: Any, slots: list[MechanismSlot], generic: list[str], sparse: Any) -> list[str]:
    spec = twin.SPEC
    p = twin.params
    info = param_info(type(p))
    n = spec.n
    lines = [
        "import dataclasses as _dataclasses",
        "",
        "from twins import generic_effects as _generic",
        "from twins.base import pfield as _pfield",
        "from twins.equations import laws",
        "",
        "ParamsAsGiven = Params",
        "rates_as_given = rates",
        "output_as_given = output",
    ]
    has_init = spec.init is not None
    if has_init:
        lines.append("initial_state_as_given = initial_state")
    # (name in the written Params, field of the twin): the generic effects' fields under their own names
    rename = _written_names(spec, slots)
    fields = [(f, f) for f in spec.user_fields] + [(rename[f], f) for s in slots for f in s.fields.values()]
    fields += [(g, twin.GENERIC_NAMES.get(g, g)) for e in generic for g in GENERIC_EFFECTS[e].params.values()]
    lines += ["", "", "@_dataclasses.dataclass", "class Params(ParamsAsGiven):"]
    for name, field in fields:
        i = info[field]
        value = getattr(p, field)
        lo, hi = i.range
        lines.append(f"    {name}: {type(value).__name__} = _pfield({value!r}, {i.unit!r}, {lo!r}, {hi!r}, {i.doc!r})")
    extra = [(s, k) for s in slots for k in range(_added(s))]
    names = list(spec.states) + [f"{s.mech.kind}_{s.state}_{k}" for s, k in extra]
    lines += ["", ""]
    if extra:
        lines.append(
            "STATES = {**STATES, "
            + ", ".join(f'"{nm}": ("other", {spec.units[s.acts]!r})' for nm, (s, _k) in zip(names[n:], extra))
            + "}"
        )
        if has_init:
            zeros = ", ".join("0.0" for _ in extra)
            lines += ["", "", "def initial_state(p, u0):", f"    return (*initial_state_as_given(p, u0), {zeros})"]
    lines += ["", f"SUBSTEPS = {int(getattr(p, SUBSTEPS_FIELD))}  # Runge-Kutta steps per sample, as the diagnosis ran"]
    bounds = [s for s in slots if s.mech.kind == "overflow"]
    if bounds:
        entries = ", ".join(f'"{s.state}": (None, "{rename[s.fields["level"]]}")' for s in bounds)
        lines.append(f"BOUNDS = {{**globals().get('BOUNDS', {{}}), {entries}}}")
    calib = ", ".join(repr(name) for name, _f in fields if name in spec.calib or name not in spec.user_fields)
    lines.append(f"CALIBRATION_PARAMS = ({calib},)")
    if type(twin).INITIAL_CONDITION_PARAMS:  # what the model declared, kept
        lines.append(f"INITIAL_CONDITION_PARAMS = {tuple(type(twin).INITIAL_CONDITION_PARAMS)!r}")
    if type(twin).INPUT_HELD:
        lines.append('INPUT_BEFORE = "held"')
    lines.append("")
    written = [dataclasses.replace(s, fields={k: rename[f] for k, f in s.fields.items()}) for s in slots]
    # an offset and a crosstalk of the input as given act sample by sample: written into output() (an FMU steps
    # them); other effects around the equations act on the whole record (input_map / output_map)
    static = (
        set(generic) <= {"sensor_offset", "input_crosstalk"}
        and spec.input_map is None
        and not any(s.mech.kind == "backlash" for s in slots)
    )
    lines += _rates_code(spec, written, names, sparse)
    lines += _output_code(spec, written, generic if static else [])
    lines += _maps_code(twin, written, [] if static else generic)
    return lines


def _added(s: MechanismSlot) -> int:
    return N_PLAY if s.mech.kind == "prandtl_ishlinskii" else s.mech.added_states


def _written_names(spec: Any, slots: list[MechanismSlot]) -> dict[str, str]:
    """Twin field → its name in the written Params: ``k3_x`` (``KEY_STATE``), so that the catalog placed in the
    written model again (its own ``cubic_spring_x_k3``) does not clash with it."""
    taken = set(spec.user_fields) | set(GENERIC_EFFECTS_FIELDS)
    out = {}
    for s in slots:
        for key, f in s.fields.items():
            name = f"{key}_{s.state}"
            while name in taken:
                name += "_added"
            taken.add(name)
            out[f] = name
    return out


def _drive(slots: list[MechanismSlot]) -> list[str]:
    out = []
    for s in slots:
        f = s.fields
        if s.mech.kind == "dead_zone":
            out.append(f"    u = laws.dead_zone(u, p.{f['d']})")
        elif s.mech.kind == "input_polynomial":
            out.append(f"    u = laws.input_polynomial(u, p.{f['a2']}, p.{f['a3']})")
    return out


def _rates_code(spec: Any, slots: list[MechanismSlot], names: list[str], sparse: Any) -> list[str]:
    n = spec.n
    d = [f"d_{nm}" for nm in names]
    lines = ["", "def rates(x, u, p):"]
    lines += _drive(slots)
    lines.append(f"    given = rates_as_given(x[:{n}], u, p)")
    lines += [f"    {d[i]} = given[{i}]" for i in range(n)]
    lines += [f"    {d[i]} = 0.0" for i in range(n, len(names))]
    e = n
    for s in slots:
        f, i, j = s.fields, s.acts, s.enters
        xi = f"x[{i}]"
        k = s.mech.kind
        law = {
            "coulomb": f"laws.coulomb({xi}, p.{f.get('fc')})",
            "stribeck": f"laws.stribeck({xi}, p.{f.get('fc')}, p.{f.get('fs')}, p.{f.get('vs')})",
            "asymmetric_coulomb": f"laws.asymmetric_coulomb({xi}, p.{f.get('f_pos')}, p.{f.get('f_neg')})",
            "quadratic_damping": f"laws.quadratic_damping({xi}, p.{f.get('c2')})",
            "cubic_damping": f"laws.cubic_damping({xi}, p.{f.get('c3')})",
            "leak": f"p.{f.get('c')} * {xi}",
            "orifice_leak": f"p.{f.get('c')} * math.sqrt(max({xi}, 0.0))",
            "power_outflow": f"laws.power_outflow({xi}, p.{f.get('c')}, p.{f.get('beta')})",
        }
        if k in law:
            lines.append(f"    {d[i]} -= {law[k]}  # {s.mech.title}")
        elif k in ("cubic_spring", "quadratic_spring", "clearance_spring"):
            args = {"cubic_spring": "k3", "quadratic_spring": "k2"}.get(k)
            call = f"laws.{k}({xi}, p.{f[args]})" if args else f"laws.clearance_spring({xi}, p.{f['gap']}, p.{f['kc']})"
            lines.append(f"    {d[j]} -= {call}  # {s.mech.title}")
        elif k == "bouc_wen":
            lines.append(f"    {d[e]} = laws.bouc_wen_rate({d[i]}, x[{e}], p.{f['b1']}, p.{f['b2']})  # {s.mech.title}")
            lines.append(f"    {d[j]} -= p.{f['kappa']} * x[{e}]")
            e += 1
        elif k == "prandtl_ishlinskii":
            for q in range(N_PLAY):
                r = f"p.{f['r']} * {(q + 0.5) / N_PLAY!r}"
                lines.append(f"    {d[e + q]} = laws.play_rate({d[i]}, {xi}, x[{e + q}], {r})  # {s.mech.title}")
            total = " + ".join(f"x[{e + q}]" for q in range(N_PLAY))
            lines.append(f"    {d[j]} -= p.{f['w']} * ({total}) / {N_PLAY}")
            e += N_PLAY
    for s in slots:  # a bound moves what is left of the rate (before a sparse term, as the integrator does)
        if s.mech.kind == "overflow":
            f, i, j = s.fields, s.acts, s.enters
            lines.append(f"    if x[{i}] >= p.{f['level']} and {d[i]} > 0.0:  # {s.mech.title}")
            if j >= 0:
                lines.append(f"        {d[j]} += p.{f['share']} * {d[i]}")
            lines.append(f"        {d[i]} = 0.0")
    if sparse is not None:
        exps, rows, coefs = sparse
        var = [f"x[{i}]" for i in range(n)] + ["u"]
        for ex, row, c in zip(exps, rows, coefs):
            mono = " * ".join(f"{v}**{int(a)}" if a > 1 else v for v, a in zip(var, ex) if a) or "1.0"
            lines.append(
                f"    {d[int(row)]} += {float(c)!r} * {mono}  # sparse term {term_text(tuple(ex), spec.states + ['u'])}"
            )
    lines.append(f"    return ({', '.join(d)}{',' if len(d) == 1 else ''})")
    return ["import math", "", *lines]


def _output_code(spec: Any, slots: list[MechanismSlot], static: list[str]) -> list[str]:
    drive = _drive(slots)
    terms = [f"output_as_given(x[:{spec.n}], u, p)"]
    if "input_crosstalk" in static:
        terms.append("p.crosstalk_gain * u_given")
    if "sensor_offset" in static:
        terms.append("p.sensor_offset")
    keep = ["    u_given = u"] if "input_crosstalk" in static and drive else []
    if "input_crosstalk" in static and not drive:
        terms[1] = "p.crosstalk_gain * u"
    return ["", "", "def output(x, u, p):", *keep, *drive, f"    return {' + '.join(terms)}"]


def _maps_code(twin: Any, slots: list[MechanismSlot], generic: list[str]) -> list[str]:
    lines: list[str] = []
    inputs = [e for e in generic if e in INPUT_SIDE]
    backlash = [s for s in slots if s.mech.kind == "backlash"]
    if inputs or backlash:
        lines += ["", "", "def input_map(u, fs, p):", '    """The input as it reaches the equations."""']
        if inputs:
            held = ", held=True" if type(twin).INPUT_HELD else ""
            lines.append(f"    u = _generic.apply_input(u, fs, {set(inputs)!r}, p{held})")
        for s in backlash:
            lines.append(f"    u = laws.backlash(u, p.{s.fields['r']})")
        lines.append("    return u")
    outputs = [e for e in generic if e not in INPUT_SIDE]
    if outputs:
        lines += [
            "",
            "",
            "def output_map(y, u, fs, p):",
            '    """The reading: the equations\' output through what lies between them and the sensor."""',
            f"    return _generic.apply_output(y, u, fs, {set(outputs)!r}, p)",
        ]
    return lines
