"""The public names of ``sysid``: importable from the package and from each family, loaded on first use, and the
module paths of the flat layout still importable (with a DeprecationWarning) as the same modules."""

import importlib
import json
import pkgutil
import subprocess
import sys
import warnings

import pytest

import sysid
from sysid._exports import MOVED

FAMILIES = [m.name for m in pkgutil.iter_modules(sysid.__path__) if m.ispkg]


def test_the_families_are_the_documented_ones():
    assert sorted(FAMILIES) == [
        "data",
        "evaluation",
        "linear",
        "neural",
        "nonlinear",
        "polynomial",
        "report",
        "search",
        "signals",
    ]


@pytest.mark.parametrize("package", ["sysid"] + [f"sysid.{f}" for f in FAMILIES if f != "search"])
def test_every_exported_name_resolves_to_its_definition(package):
    pkg = importlib.import_module(package)
    assert pkg.__all__, package
    for name in pkg.__all__:
        value = getattr(pkg, name)
        assert value is not None, f"{package}.{name}"
        home = getattr(value, "__module__", None)
        if home is not None and callable(value):  # a class or function: defined under sysid
            assert home.startswith("sysid."), f"{package}.{name} comes from {home}"
    assert set(pkg.__all__) <= set(dir(pkg))


@pytest.mark.parametrize("package", ["sysid"] + [f"sysid.{f}" for f in FAMILIES])
def test_no_exported_name_is_also_a_submodule(package):
    """``sysid.signals.prbs`` must stay the function: once a submodule of that name is imported, Python binds the
    module to the package's attribute and the export would change meaning mid-run."""
    pkg = importlib.import_module(package)
    submodules = {m.name for m in pkgutil.iter_modules(pkg.__path__)}
    if package == "sysid":
        submodules |= {old.split(".")[1] for old in MOVED}  # an old path imported later binds the same way
    assert sorted(set(pkg.__all__) & submodules) == []


@pytest.mark.parametrize("old", sorted(MOVED))
def test_old_module_paths_still_import_with_a_warning(old):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        module = importlib.import_module(old)
    assert module is importlib.import_module(MOVED[old])
    assert module.__spec__.name == MOVED[old]  # the real module's spec is left as it was
    assert any(issubclass(w.category, DeprecationWarning) and MOVED[old] in str(w.message) for w in caught) or (
        old in sys.modules  # imported earlier in this process: no second warning
    )


def test_old_names_of_modules_that_became_packages_still_resolve():
    from sysid.linear import ARMAX, ARX
    from sysid.polynomial import NARMAXPoly, NARXPoly, PolynomialModel
    from sysid.report import REPORT_CSS, write_page
    from sysid.signals import aprbs, multisine, prbs

    assert callable(prbs) and callable(multisine) and callable(aprbs) and callable(write_page)
    assert issubclass(ARX, PolynomialModel) and issubclass(NARXPoly, PolynomialModel)
    assert ARMAX.name == "armax" and NARMAXPoly.name == "narmax-poly" and "table" in REPORT_CSS


def test_importing_sysid_and_its_families_loads_no_heavy_library():
    code = (
        "import json, sys, sysid, sysid.linear, sysid.neural, sysid.polynomial, sysid.report, sysid.signals\n"
        "sysid.Record; sysid.linear.__all__\n"
        "print(json.dumps(sorted(m for m in ('scipy', 'torch', 'numba', 'matplotlib', 'optuna') if m in sys.modules)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out) == []
