"""Blocked k-fold cross-validation of a sweep (``piezotwin search --folds K``): the folds tile the record in order,
each run's scores are the means of its folds' scores on the blocks they did not see, a noise-free ARX system is
recovered in every fold, and bad combinations of options are refused with one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("optuna")

from benchmarks.cli import main  # noqa: E402
from sysid.data.io import write_record  # noqa: E402
from sysid.data.record import Record  # noqa: E402
from sysid.errors import ConfigError, DataError  # noqa: E402
from sysid.evaluation.evaluate import evaluate  # noqa: E402
from sysid.registry import get_identifier  # noqa: E402
from sysid.search import SweepSpec, run_one  # noqa: E402
from sysid.search.folds import evaluate_folds  # noqa: E402
from sysid.search.sweep import _spec_dict  # noqa: E402


def _arx_record(n=900, noise=0.0, seed=0):
    """y(k) = 1.5 y(k−1) − 0.7 y(k−2) + 0.5 u(k−1) (+ white output noise), a white input."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + 0.5 * u[k - 1]
    return Record(u=u, y=y + noise * rng.standard_normal(n), fs=100.0, source="arx")


def test_blocked_folds_tile_the_record_in_order():
    rec = Record(u=np.arange(10.0), y=np.arange(10.0) * 2, fs=1.0, source="r")
    folds = rec.blocked_folds(3)
    blocks = [b.u.tolist() for _, b in folds]
    assert blocks == [[0, 1, 2], [3, 4, 5, 6], [7, 8, 9]]  # lengths differ by at most one sample
    assert [[p.u.tolist() for p in parts] for parts, _ in folds] == [
        [[3, 4, 5, 6, 7, 8, 9]],
        [[0, 1, 2], [7, 8, 9]],
        [[0, 1, 2, 3, 4, 5, 6]],
    ]
    for parts, block in folds:  # each fold's estimation and validation samples are the whole record, once
        assert sorted(np.concatenate([p.u for p in parts] + [block.u]).tolist()) == list(range(10))


@pytest.mark.parametrize("k", [1, 0, 2.5, True])
def test_blocked_folds_refuse_a_bad_k(k):
    with pytest.raises(DataError, match="at least 2"):
        Record(u=np.zeros(10), y=np.zeros(10), fs=1.0).blocked_folds(k)


def test_blocked_folds_refuse_a_record_too_short():
    with pytest.raises(DataError, match="too few"):
        Record(u=np.zeros(7), y=np.zeros(7), fs=1.0).blocked_folds(4)


def test_scores_are_the_means_of_the_folds_on_the_held_out_blocks():
    """Each fold refitted by hand on the samples around its block and scored on the block: the run's validation
    R² are the means of those, its estimation R² the means on the fitted samples."""
    rec = _arx_record(noise=0.05)
    make = lambda: get_identifier("arx").from_assignments({"ny": "2", "nu": "1"})  # noqa: E731
    got = evaluate_folds(make, rec, 4)
    val, est = [], []
    for parts, block in rec.blocked_folds(4):
        m = make().fit(parts[0] if len(parts) == 1 else parts)
        val.append(evaluate(m, block))
        est.append(evaluate(m, parts))
    for mode in ("one_step", "free_run"):
        assert got["validation"][mode]["r2"] == pytest.approx(np.mean([v[mode]["r2"] for v in val]), rel=1e-12)
        assert got["estimation"][mode]["r2"] == pytest.approx(np.mean([v[mode]["r2"] for v in est]), rel=1e-12)
    assert [f["held_out"] for f in got["folds"]] == [[0, 225], [225, 450], [450, 675], [675, 900]]
    assert got["n_parameters"] == 3


def test_a_noise_free_arx_system_is_recovered_in_every_fold():
    spec = SweepSpec(identifier="arx", grid={"ny": ["2"]}, fixed={"nu": "1"}, folds=5)
    run = run_one(spec, {"ny": "2"}, 0, _arx_record(), None)
    assert len(run["folds"]) == 5
    for fold in run["folds"]:
        assert fold["validation"]["free_run"]["r2"] == pytest.approx(1.0, abs=1e-9)
    assert run["validation"]["free_run"]["r2"] == pytest.approx(1.0, abs=1e-9)


def test_a_validation_record_sweep_stores_its_spec_as_before():
    """A study made before ``folds`` existed resumes: a sweep without folds stores no ``folds`` key."""
    assert "folds" not in _spec_dict(SweepSpec(identifier="arx", grid={"ny": ["2"]}))
    assert _spec_dict(SweepSpec(identifier="arx", grid={"ny": ["2"]}, folds=3))["folds"] == 3
    with pytest.raises(ConfigError, match="at least 2"):
        SweepSpec(identifier="arx", grid={"ny": ["2"]}, folds=1)


def test_cli_folds_sweep_ranks_the_true_order_first(tmp_path, capsys):
    write_record(_arx_record(noise=0.02), tmp_path / "est.npz")
    args = ["search", "arx", "--est", str(tmp_path / "est.npz"), "--folds", "4", "--grid", "ny=1,2", "--set", "nu=1"]
    code = main(
        args + ["--storage", str(tmp_path / "s.db"), "--no-progress", "--export", str(tmp_path / "r.jsonl"), "--json"]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["best"]["config"] == {"ny": "2"} and "4-fold" in out["validated_on"]
    rows = [json.loads(line) for line in (tmp_path / "r.jsonl").read_text().splitlines()]
    assert all(len(r["folds"]) == 4 for r in rows)


@pytest.mark.parametrize(
    "extra, message",
    [
        ([], "exactly one of --val FILE and --folds K"),
        (["--val", "EST", "--folds", "3"], "exactly one of --val FILE and --folds K"),
        (["--folds", "1"], "--folds must be an integer of at least 2"),
        (["--folds", "3", "--est", "EST"], "one estimation record"),
    ],
)
def test_cli_refuses_bad_fold_options_with_one_line(tmp_path, capsys, extra, message):
    est = tmp_path / "est.npz"
    write_record(_arx_record(n=100), est)
    extra = [str(est) if a == "EST" else a for a in extra]
    code = main(["search", "arx", "--est", str(est), "--grid", "ny=1", "--storage", str(tmp_path / "s.db"), *extra])
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert code == 2 and len(err) == 1 and message in err[0]
    assert not (tmp_path / "s.db").exists()  # refused before any storage is made
