"""Shared set-up of the speed suite (``make bench``): pytest-benchmark files of every team live here.

Conventions read by the summary (``python -m tests.perf.summarise``):

- a benchmark compared with another one in the same run names it in ``benchmark.extra_info["reference"]``
  (e.g. our FROLS against SysIdentPy's); without that, a benchmark whose name contains ``reference``,
  ``sysidentpy`` or ``scipy`` is taken as the reference of the other benchmarks of its module that share its
  leading name word(s) (``test_decimate_10M_points`` ↔ ``test_decimate_scipy_reference``);
- a speed goal of the issues is ``benchmark.extra_info["target_s"]`` (seconds per call) and, for throughput,
  ``extra_info["items"]`` (samples per call) so the summary can print samples/s.

Results: ``make bench`` writes ``docs/perf/bench.json`` (pytest-benchmark's JSON with machine info)
and ``docs/perf/summary.md`` (the ratios table for the README).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "perf"


def pytest_configure(config) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)


@pytest.fixture(scope="session")
def machine() -> str:
    """The machine line a benchmark prints beside its figures: CPU model (``/proc/cpuinfo``) and logical cores."""
    try:
        text = Path("/proc/cpuinfo").read_text()
        model = next(line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("model name"))
    except (OSError, StopIteration):
        model = "CPU"
    return f"{model}, {os.cpu_count()} logical cores"
