import os
import sys
from pathlib import Path

import pytest

import benchmarks  # noqa: F401  the project's own packages are imported first: an FMU run in this process puts
import sysid  # noqa: F401  its bundled copy of sysid/ and twins/ first on sys.path (pythonfmu), and a package
import twins  # noqa: F401  already imported keeps its own modules

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(autouse=True)
def _restore_sys_path():
    """sys.path as it was before each test: an FMU instantiated in this process (pythonfmu) puts its resources
    folder first, and worker processes started later (Dask's nannies, multiprocessing's spawn) inherit sys.path and
    would import the FMU's bundled, older copy of the project (seen: two-worker make test, test_execution after
    test_fmu on one xdist worker)."""
    saved = list(sys.path)
    yield
    sys.path[:] = saved


REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"


@pytest.fixture
def shared_data() -> Path:
    """../shared/data beside the checkout (CI provides it)."""
    path = SHARED / "data"
    if not path.exists():
        pytest.skip("../shared/data is not beside this checkout")
    return path


PERF = REPO / "tests" / "perf"


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items) -> None:
    """The speed suite (tests/perf, ``make bench``) carries the ``perf`` marker, so that ``make test`` and
    ``make test-all`` (``-m 'not perf'``) leave it out and ``make bench`` (``-m perf``) runs only it."""
    for item in items:
        if PERF in Path(str(item.path)).parents:
            item.add_marker(pytest.mark.perf)
