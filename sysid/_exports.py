"""Lazy re-exports of a package's public names, and the module paths of the flat layout that still import.

A package of ``sysid`` lists its public names once, as imports under ``if TYPE_CHECKING:`` (what type checkers
and IDEs read). :func:`attach` reads that block from the package's own source and loads each name from its module
on first access (PEP 562), so ``import sysid.linear`` costs nothing until a name is used and never pulls scipy,
numba or torch in before then (the CLI's start-up depends on it).

:data:`MOVED` maps the module paths of the flat layout (every module directly in ``sysid/``, until 0.1) to their
homes in the family sub-packages; :func:`install_aliases` makes ``import sysid.pem`` return ``sysid.linear.pem``
with a :class:`DeprecationWarning`, so users' scripts keep working. Modules whose name became a package
(``sysid.signals``, ``sysid.linear``, ``sysid.polynomial``, ``sysid.report``) need no alias: the package exports
what the module did.
"""

from __future__ import annotations

import ast
import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = ["attach", "MOVED", "install_aliases"]

#: old module path -> new one (the flat layout -> the family sub-packages)
MOVED: dict[str, str] = {
    **{f"sysid.{m}": f"sysid.data.{m}" for m in ("record", "io", "csvread", "jsonio", "safeio", "modelfile")},
    **{f"sysid.{m}": f"sysid.signals.{m}" for m in ("preprocess", "cleaning", "filters", "sampling", "checks")},
    "sysid.prbs": "sysid.signals.pseudorandom",
    **{f"sysid.{m}": f"sysid.evaluation.{m}" for m in ("metrics", "residuals", "evaluate", "advice")},
    **{f"sysid.{m}": f"sysid.report.{m}" for m in ("plots", "linplots", "provenance", "compare")},
    **{f"sysid.{m}": f"sysid.polynomial.{m}" for m in ("frols", "simulate", "polysim")},
    **{
        f"sysid.{m}": f"sysid.linear.{m}"
        for m in (
            "fir",
            "frf",
            "bla",
            "bla_model",
            "tfest",
            "pem",
            "pem_init",
            "subspace",
            "order",
            "uncertainty",
            "echo_oe",
        )
    },
    **{f"sysid.{m}": f"sysid.nonlinear.{m}" for m in ("pnlss", "pnlss_sim", "wiener_hammerstein", "wh_blocks")},
}


def _type_checking_imports(init_file: str, package: str) -> dict[str, tuple[str, str]]:
    """``{public name: (module, attribute)}`` from the ``if TYPE_CHECKING:`` block of a package's source."""
    tree = ast.parse(Path(init_file).read_text(encoding="utf-8"))
    table: dict[str, tuple[str, str]] = {}
    for node in tree.body:
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for stmt in node.body:
                if isinstance(stmt, ast.ImportFrom):
                    module = importlib.util.resolve_name("." * stmt.level + (stmt.module or ""), package)
                    for alias in stmt.names:
                        table[alias.asname or alias.name] = (module, alias.name)
    return table


def attach(package: str, init_file: str) -> tuple[Callable[[str], Any], Callable[[], list[str]], list[str]]:
    """``(__getattr__, __dir__, __all__)`` for ``package``, whose names are the imports of its TYPE_CHECKING block.

    A name that is a submodule (``from sysid.linear import pem``) is imported as a module. Each value is cached
    in the package's namespace on first use.
    """
    table = _type_checking_imports(init_file, package)

    def __getattr__(name: str) -> Any:
        try:
            module, attr = table[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        parent = importlib.import_module(module)
        value = parent.__dict__.get(attr)
        if value is None:
            value = (
                importlib.import_module(f"{module}.{attr}")
                if importlib.util.find_spec(f"{module}.{attr}") is not None
                else getattr(parent, attr)
            )
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(table))

    return __getattr__, __dir__, list(table)


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old module paths of :data:`MOVED` and returns the module at its new path."""

    def __init__(self) -> None:
        self._specs: dict[str, importlib.machinery.ModuleSpec | None] = {}

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        return importlib.util.spec_from_loader(fullname, self) if fullname in MOVED else None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        warnings.warn(
            f"{spec.name} moved to {MOVED[spec.name]}; import it from there (or from sysid)",
            DeprecationWarning,
            stacklevel=2,
        )
        module = importlib.import_module(MOVED[spec.name])
        self._specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        """The module already ran under its new name; give it back the spec the import system replaced."""
        module.__spec__ = self._specs[module.__spec__.name] if module.__spec__ else None


def install_aliases() -> None:
    """Let the old module paths import (once per process)."""
    if not any(isinstance(f, _MovedModules) for f in sys.meta_path):
        sys.meta_path.append(_MovedModules())
