import os
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

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
