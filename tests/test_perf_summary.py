"""The speed-suite summary pairs benchmarks with their references and targets and prints ratios."""

from __future__ import annotations

import json

from tests.perf.summarise import main, pair_references, summarise


def _b(module, name, mean, **extra):
    return {
        "name": name,
        "fullname": f"tests/perf/{module}.py::{name}",
        "stats": {"mean": mean, "min": mean * 0.9},
        "extra_info": extra,
    }


DATA = {
    "machine_info": {"cpu": {"brand_raw": "TestCPU", "count": 2}, "python_version": "3.11"},
    "datetime": "2026-01-01T00:00:00",
    "benchmarks": [
        _b("test_signals", "test_decimate_10M_points", 0.5),
        _b("test_signals", "test_decimate_scipy_reference", 2.0),
        _b("test_signals", "test_chirp_10M_points", 0.1, target_s=0.05, note="N=10 at 1 Hz; load 0.5"),
        _b("test_frols", "test_ours", 1.0, reference="test_theirs", items=1_000_000),
        _b("test_frols", "test_theirs", 30.0),
        _b("test_signals", "test_decimate_busy", 0.7, reference=None),
    ],
}


def test_pairs_and_ratios(tmp_path):
    refs = pair_references(DATA["benchmarks"])
    assert refs["tests/perf/test_signals.py::test_decimate_10M_points"].endswith("test_decimate_scipy_reference")
    assert refs["tests/perf/test_frols.py::test_ours"].endswith("test_theirs")
    assert "tests/perf/test_signals.py::test_chirp_10M_points" not in refs
    assert "tests/perf/test_signals.py::test_decimate_busy" not in refs  # reference=None: stated none
    text = summarise(DATA)
    assert "| signals: decimate_10M_points | 500.0 ms |" in text and "| 4× |" in text
    assert "| 30× |" in text and "1 M/s" in text
    assert "no (2× over)" in text  # the chirp misses its 0.05 s target
    assert "| no (2× over) | N=10 at 1 Hz; load 0.5 |" in text  # the note in the last column
    assert "| signals: decimate_busy | 700.0 ms | 630.0 ms |  |  |  |" in text  # reference=None: not paired
    p = tmp_path / "bench.json"
    p.write_text(json.dumps(DATA))
    assert main([str(p), "-o", str(tmp_path / "s.md")]) == 0
    assert (tmp_path / "s.md").read_text() == text
    assert main([str(tmp_path / "missing.json")]) == 2
