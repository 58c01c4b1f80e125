"""A twin from a small Python model: a parameter dataclass and a ``simulate`` or ``step`` function.

The model is a module (a ``.py`` file or an importable name), or an object in it (``FILE.py:NAME`` or
``module:NAME``: a class or namespace with the same attributes). It defines

``Params``
    a dataclass; each field made with :func:`twins.base.pfield` (default, unit, range [lo, hi], description).
    Fields with a range are what the diagnosis calibrates (all numeric ones, unless ``CALIBRATION_PARAMS``
    names some).
``simulate(u, fs, p)`` *or* ``step(x, u_k, dt, p) -> (x_next, y_k)`` with ``initial_state(p, u0)``
    the output samples for the input samples ``u`` [the record's units] at ``fs`` [Hz] for the parameters
    ``p`` (a ``Params``); or one sample at a time from the state ``x`` (any value the function understands).
    Either may take a keyword ``effects``: the set of the model's own effects (``EFFECTS``) that are on.

and optionally ``NAME`` (the twin's name, default the file's), ``UNITS`` (``{"u": "V", "y": "V"}``),
``CALIBRATION_PARAMS`` (field names), ``INITIAL_CONDITION_PARAMS`` (the fields that are a record's start state,
e.g. the initial levels: fitted on the estimation record, they do not carry to a separate validation record),
``INPUT_BEFORE`` (``"zero"``, the default: the model starts at rest; ``"held"``: the input before a record was its
first value, for a model that starts at an operating point) and
``EFFECTS``: effects the model knows itself, id → ``EffectSpec`` or a dict with ``description``, ``signature`` and
``params`` (key → field of ``Params``). The generic effects (:mod:`twins.generic_effects`) are added around the
model in any case.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from sysid.errors import ConfigError
from twins.base import EffectSpec

from .twin import ExternalTwin, external_twin_class, start_declarations

__all__ = ["load_model", "model_twin_class"]


def load_model(spec: str) -> type[ExternalTwin]:
    """The twin class of the model at ``spec`` (``path/model.py``, ``path/model.py:NAME``, ``pkg.module`` or
    ``pkg.module:NAME``); refused with one line when it cannot be loaded or lacks what it must define."""
    target, _, attr = str(spec).partition(":") if not _is_windows_drive(spec) else (spec, "", "")
    path = Path(target)
    if target.endswith(".py") or path.exists():
        if not path.is_file():
            raise ConfigError(f"{target}: model file not found")
        mod_name = f"piezotwin_user_model_{path.stem}"
        loader_spec = importlib.util.spec_from_file_location(mod_name, path)
        if loader_spec is None or loader_spec.loader is None:
            raise ConfigError(f"{target}: not a Python file")
        module = importlib.util.module_from_spec(loader_spec)
        sys.modules[mod_name] = module  # dataclasses look their module up while the class is made
        try:
            loader_spec.loader.exec_module(module)
        except Exception as exc:  # noqa: BLE001 — the user's code may raise anything; one line says what
            sys.modules.pop(mod_name, None)
            raise ConfigError(f"{target}: the model failed to load ({type(exc).__name__}: {exc})") from None
        default_name = path.stem
    else:
        try:
            module = importlib.import_module(target)
        except Exception as exc:  # noqa: BLE001
            raise ConfigError(f"model {target!r}: cannot import it ({type(exc).__name__}: {exc})") from None
        default_name = target.rsplit(".", 1)[-1]
    obj: Any = module
    if attr:
        if not hasattr(module, attr):
            raise ConfigError(f"model {spec}: {target} defines no {attr!r}")
        obj = getattr(module, attr)
        default_name = attr
    return model_twin_class(obj, default_name)


def _is_windows_drive(spec: str) -> bool:
    return len(spec) > 2 and spec[1] == ":" and spec[0].isalpha() and spec[2] in "\\/"


def model_twin_class(obj: Any, default_name: str = "model") -> type[ExternalTwin]:
    """The twin class of a model object (module, class or namespace with ``Params`` and ``simulate`` or ``step``)."""
    from twins.equations.model import is_equation_model

    if is_equation_model(obj):  # STATES, rates(x, u, p), output(x, u, p): the catalog's mechanisms inside
        from twins.equations.twin import equation_twin_class

        return equation_twin_class(obj, default_name)
    name = f"model:{getattr(obj, 'NAME', default_name)}"  # prefixed: never mistaken for a shipped twin
    params_cls = getattr(obj, "Params", None)
    if params_cls is None:
        raise ConfigError(f"model {name}: defines no Params (a dataclass of its parameters)")
    sim = getattr(obj, "simulate", None)
    step = getattr(obj, "step", None)
    if callable(sim):
        core = _simulate_core(name, sim)
    elif callable(step):
        init = getattr(obj, "initial_state", None)
        if not callable(init):
            raise ConfigError(f"model {name}: a step() model needs initial_state(p, u0) too")
        core = _step_core(name, step, init)
    else:
        raise ConfigError(f"model {name}: defines neither simulate(u, fs, p) nor step(x, u, dt, p)")
    effects = {k: _effect_spec(name, k, v) for k, v in dict(getattr(obj, "EFFECTS", {}) or {}).items()}
    calib = getattr(obj, "CALIBRATION_PARAMS", None)
    return external_twin_class(
        name,
        core,
        params_cls,
        effects,
        calib,
        getattr(obj, "UNITS", None),
        doc=inspect.getdoc(obj) or "",
        **start_declarations(obj),
    )


def _effect_spec(model: str, eid: str, v: Any) -> EffectSpec:
    if isinstance(v, EffectSpec):
        return v
    if not isinstance(v, dict):
        raise ConfigError(f"model {model}: effect {eid!r} must be an EffectSpec or a dict, got {type(v).__name__}")
    params = v.get("params", {})
    if isinstance(params, (list, tuple)):
        params = {p: p for p in params}
    return EffectSpec(
        eid,
        model,
        str(v.get("description", eid)),
        str(v.get("signature", "")),
        dict(params),
        default_on=bool(v.get("default_on", False)),
        group=str(v.get("group", "")),
    )


def _takes_effects(fn: Callable) -> bool:
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):
        return False
    return "effects" in sig.parameters or any(p.kind is inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values())


def _simulate_core(name: str, sim: Callable) -> Callable:
    with_effects = _takes_effects(sim)

    def core(u: np.ndarray, fs: float, p: Any, effects: frozenset) -> np.ndarray:
        return sim(u, fs, p, effects=effects) if with_effects else sim(u, fs, p)

    return core


def _step_core(name: str, step: Callable, init: Callable) -> Callable:
    with_effects = _takes_effects(step)

    def core(u: np.ndarray, fs: float, p: Any, effects: frozenset) -> np.ndarray:
        dt = 1.0 / fs
        x = init(p, float(u[0]))
        y = np.empty(len(u))
        kw = {"effects": effects} if with_effects else {}
        for k, uk in enumerate(u.tolist()):
            x, y[k] = step(x, uk, dt, p, **kw)
        return y

    return core
