"""Structure sweeps (sysid.search / `piezotwin search`): grid parsing, repeats, resume, two workers."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("optuna")
pytest.importorskip("torch")

from benchmarks.cli import main  # noqa: E402
from sysid.data.io import write_record  # noqa: E402
from sysid.errors import ConfigError  # noqa: E402
from sysid.search import SweepSpec, collect, parse_grid, run_sweep, storage_url  # noqa: E402
from tests.neural_systems import bouc_wen_record, multisine_input  # noqa: E402

FIXED = {"epochs": "2", "lr": "1e-3", "device": "cpu"}


@pytest.fixture(scope="module")
def data():
    est = bouc_wen_record(multisine_input(1200, 1000.0, 100.0, seed=1), 1000.0, f0=100.0)
    val = bouc_wen_record(multisine_input(600, 1000.0, 100.0, seed=2), 1000.0, f0=100.0)
    return est, val


def test_parse_grid():
    g = parse_grid("lags=2..4;hidden=25-25,25-25-25-25;activation=relu,tanh", "narx-mlp")
    assert g == {"lags": ["2", "3", "4"], "hidden": ["25-25", "25-25-25-25"], "activation": ["relu", "tanh"]}
    spec = SweepSpec("narx-mlp", g, repeats=3, fixed={"epochs": "5"})
    assert spec.n_configs == 12
    a = spec.assignments({"lags": "3", "hidden": "25-25", "activation": "tanh"}, seed=7)
    assert a == {"epochs": "5", "ny": "3", "nu": "3", "hidden": "25-25", "activation": "tanh", "seed": "7"}
    for bad in ("nosuch=1", "lags=a", "hidden", "lags=5..2", ""):
        with pytest.raises(ConfigError):
            parse_grid(bad, "narx-mlp")
    with pytest.raises(ConfigError):
        SweepSpec("narx-mlp", g, fixed={"ny": "3"})  # conflicts with lags in the grid


def test_grid_sweep_repeats_and_resume(tmp_path, data):
    est, val = data
    spec = SweepSpec("narx-mlp", parse_grid("lags=2,3;hidden=4,6", "narx-mlp"), repeats=2, fixed=FIXED)
    db = tmp_path / "s.db"
    first = run_sweep(spec, est, val, storage=str(db), study="t", trials=2, progress=False)
    assert first["n_configs"] == 2 and first["n_runs"] == 4
    done_first = {c["config_key"] for c in first["configs"]}
    # "resume": the same sweep without the trial limit runs only the two missing configurations
    second = run_sweep(spec, est, val, storage=str(db), study="t", progress=False)
    assert second["n_configs"] == 4 and second["n_runs"] == 8
    runs = collect(storage_url(str(db), "t"), "t")
    trials_of = {}
    for r in runs:
        trials_of.setdefault(r["config_key"], set()).add(r["trial"])
    assert all(len(v) == 1 for v in trials_of.values())  # no configuration ran twice
    assert done_first <= set(trials_of)
    for c in second["configs"]:
        assert c["runs"] == 2 and c["n_parameters"] > 0
        assert c["r2_est_osa_mean"] is not None and c["r2_est_osa_sd"] is not None
    # parameter count follows the structure: lags 3, widths 6 → 6 inputs, 6 hidden, 1 output
    c = next(c for c in second["configs"] if c["config"] == {"lags": "3", "hidden": "6"})
    assert c["n_parameters"] == 6 * 6 + 6 + 6 + 1
    # a different sweep may not reuse the study
    with pytest.raises(ConfigError):
        run_sweep(
            SweepSpec("narx-mlp", parse_grid("lags=5", "narx-mlp"), fixed=FIXED),
            est,
            val,
            storage=str(db),
            study="t",
            progress=False,
        )


def test_two_worker_processes_share_one_sqlite_storage(tmp_path, data):
    est, val = data
    spec = SweepSpec("narx-mlp", parse_grid("lags=2,3;hidden=4,5", "narx-mlp"), repeats=1, fixed=FIXED)
    res = run_sweep(spec, est, val, storage=str(tmp_path / "w.db"), study="w", workers=2, progress=False)
    assert res["n_configs"] == 4 and res["n_runs"] == 4
    runs = collect(storage_url(str(tmp_path / "w.db"), "w"), "w")
    assert len({r["pid"] for r in runs}) == 2  # both workers ran configurations


def test_a_claim_made_just_after_a_workers_read_does_not_end_it_with_a_configuration_missing(
    tmp_path, data, monkeypatch
):
    """A worker decides from one read of the study per pass what is left and whether anything still runs. When its
    decisions came from two reads, a claim made between them (here by a process that then died) showed nothing
    running in the first and hid the last configuration from the second: the worker ended with it missing, and
    `piezotwin search` exited 1 ("1 of 6 requested configurations did not complete")."""
    import subprocess
    import sys
    import warnings

    import sysid.search.study as st
    from sysid.search.sweep import open_study

    est, val = data
    spec = SweepSpec("narx-mlp", parse_grid("lags=2,3", "narx-mlp"), repeats=1, fixed=FIXED)
    url = storage_url(str(tmp_path / "r.db"), "r")
    open_study(spec, url, "r")
    st.worker_loop(spec, url, "r", est, val, target=1)  # lags=2 finished
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(gone.stdout)
    real, reads = st._snapshot, []

    def read(study):
        reads.append(1)
        if len(reads) == 2:  # another process claims lags=3 right after the worker's first read, then dies
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # Optuna: heartbeats are meant for Study.optimize
                t = study.ask()
            for k, v in (("config_key", "lags=3"), ("host", st.HOST), ("pid", dead_pid)):
                t.set_user_attr(k, v)
        return real(study)

    monkeypatch.setattr(st, "_snapshot", read)
    st.worker_loop(spec, url, "r", est, val, target=2)
    keys = [r["config_key"] for r in collect(url, "r")]
    assert sorted(keys) == ["lags=2", "lags=3"]


def test_cli_search_json_and_export(tmp_path, data, capsys):
    est, val = data
    write_record(est, tmp_path / "est.npz")
    write_record(val, tmp_path / "val.npz")
    code = main(
        [
            "search",
            "narx-mlp",
            "--est",
            str(tmp_path / "est.npz"),
            "--val",
            str(tmp_path / "val.npz"),
            "--grid",
            "lags=2;activation=relu,tanh",
            "--repeats",
            "2",
            "--set",
            "epochs=1,hidden=4,device=cpu",
            "--storage",
            str(tmp_path / "c.db"),
            "--sampler",
            "random",
            "--trials",
            "2",
            "--no-progress",
            "--export",
            str(tmp_path / "runs.jsonl"),
            "--plot",
            str(tmp_path / "r2.png"),
            "--json",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["n_configs"] == 2 and out["n_runs"] == 4 and len(out["best_runs"]) == 2
    lines = (tmp_path / "runs.jsonl").read_text().splitlines()
    assert len(lines) == 4
    row = json.loads(lines[0])
    for part in ("estimation", "validation"):
        assert set(row[part]) == {"one_step", "free_run"}
    assert (tmp_path / "r2.png").stat().st_size > 1000
    assert (
        main(
            [
                "search",
                "narx-mlp",
                "--est",
                str(tmp_path / "est.npz"),
                "--val",
                str(tmp_path / "val.npz"),
                "--grid",
                "bogus=1",
                "--storage",
                str(tmp_path / "c2.db"),
            ]
        )
        == 2
    )


def test_interrupted_sweep_resumes(tmp_path, data, monkeypatch):
    """Ctrl-C in the middle of the second configuration: the rerun keeps the finished one, reruns the
    interrupted one and runs the rest."""
    import sysid.search as S
    import sysid.search.sweep as W  # where the objective looks run_config up

    est, val = data
    spec = SweepSpec("narx-mlp", parse_grid("lags=2,3,4", "narx-mlp"), repeats=1, fixed=FIXED)
    real = S.run_config
    calls = []

    def flaky(*args, **kwargs):
        calls.append(args[1])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(W, "run_config", flaky)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec, est, val, storage=str(tmp_path / "i.db"), study="i", progress=False)
    monkeypatch.setattr(W, "run_config", real)
    res = run_sweep(spec, est, val, storage=str(tmp_path / "i.db"), study="i", progress=False)
    assert res["n_configs"] == 3 and res["n_runs"] == 3
    runs = collect(storage_url(str(tmp_path / "i.db"), "i"), "i")
    first = S.config_key(calls[0])
    assert sum(r["config_key"] == first for r in runs) == 1  # the finished configuration was not rerun
    assert S.config_key(calls[1]) in {r["config_key"] for r in runs}  # the interrupted one was
