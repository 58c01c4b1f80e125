"""One Optuna study run by several `piezotwin search` processes.

Real parts: a PostgreSQL server started by the fixture (tests/_postgres.py), `piezotwin search` processes,
SIGKILL. Checked on the study itself: exactly the requested number of COMPLETE trials, each configuration
once, none lost when a process is killed in the middle of a trial.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("optuna")
pytest.importorskip("psycopg2")

from sysid.data.io import write_record  # noqa: E402
from tests._postgres import postgres_url  # noqa: E402,F401  (fixture)
from tests.neural_systems import bouc_wen_record, multisine_input  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
GRID = "lags=1,2,3,4,5,6"  # 6 configurations of narx-mlp, about 2 s each here


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("search")
    write_record(bouc_wen_record(multisine_input(1500, 1000.0, 100.0, seed=1), 1000.0, f0=100.0), d / "est.npz")
    write_record(bouc_wen_record(multisine_input(600, 1000.0, 100.0, seed=2), 1000.0, f0=100.0), d / "val.npz")
    return d


def _search(files: Path, storage: str, study: str, *extra: str, grace: int = 30) -> subprocess.Popen:
    """A search process; heartbeat every second, grace ``grace`` s (long by default: on a loaded machine a
    starved heartbeat thread must not make a live trial look dead; a killed process on this host is
    detected by its pid at once)."""
    env = {
        **os.environ,
        "PYTHONPATH": str(REPO),
        "OPENBLAS_NUM_THREADS": "1",
        "PIEZOTWIN_HEARTBEAT_S": "1",
        "PIEZOTWIN_GRACE_S": str(grace),
    }
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.cli",
        "search",
        "narx-mlp",
        "--est",
        str(files / "est.npz"),
        "--val",
        str(files / "val.npz"),
        "--grid",
        GRID,
        "--set",
        "epochs=150,hidden=16-16,device=cpu",
        "--storage",
        storage,
        "--study",
        study,
        "--no-progress",
        "--json",
        *extra,
    ]
    return subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=files)


_STORAGES: dict = {}


def _trials(storage: str, study: str):
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    if storage not in _STORAGES:
        _STORAGES[storage] = optuna.storages.RDBStorage(storage)
    return optuna.load_study(study_name=study, storage=_STORAGES[storage]).get_trials(deepcopy=False)


def _complete_keys(storage: str, study: str) -> list[str]:
    from optuna.trial import TrialState

    return [t.user_attrs["config_key"] for t in _trials(storage, study) if t.state == TrialState.COMPLETE]


def _kill_in_trial(victim: subprocess.Popen, storage: str, study: str, timeout: float = 240) -> str:
    """SIGKILL ``victim`` once it has finished a trial and has just (< half a trial ago) started another whose claim
    stood (user attribute ``claimed``: it is fitting, not about to give way), so that the kill lands in the
    middle of that trial (one takes seconds); returns the key of the interrupted one."""
    from datetime import datetime

    from optuna.trial import TrialState

    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        try:
            mine = [t for t in _trials(storage, study) if t.user_attrs.get("pid") == victim.pid]
        except Exception:  # the study does not exist yet
            mine = []
        done = [
            (t.datetime_complete - t.datetime_start).total_seconds()
            for t in mine
            if t.state == TrialState.COMPLETE and t.datetime_complete and t.datetime_start
        ]
        # "just started": younger than half the shortest trial it finished, so the kill lands before its end
        now = datetime.now()
        young = [
            t
            for t in mine
            if done
            and t.state == TrialState.RUNNING
            and t.user_attrs.get("claimed")
            and t.datetime_start is not None
            and (now - t.datetime_start).total_seconds() < min(done) / 2
        ]
        if young:
            victim.send_signal(signal.SIGKILL)
            victim.wait()
            return young[0].user_attrs["config_key"]
        if victim.poll() is not None:
            pytest.fail(f"the process to kill ended by itself: {victim.stderr.read()[-500:]}")
        time.sleep(0.02)
    victim.kill()
    pytest.fail("the process never had a finished and a running trial at the same time")


def test_two_processes_on_postgres_finish_exactly_the_grid_and_survive_sigkill(files, postgres_url):  # noqa: F811
    """Two processes on one PostgreSQL study; one is SIGKILLed mid-trial; the other finishes every
    configuration exactly once (the killed trial is taken over), and exits 0."""
    a = _search(files, postgres_url, "pg")
    b = _search(files, postgres_url, "pg")
    interrupted = _kill_in_trial(a, postgres_url, "pg")
    out, err = b.communicate(timeout=400)
    assert b.returncode == 0, err[-2000:]
    keys = _complete_keys(postgres_url, "pg")
    assert sorted(keys) == sorted(f"lags={i}" for i in range(1, 7))  # all six, none twice
    summary = json.loads(out)
    assert summary["missing"] == 0 and summary["complete"] == 6 and summary["n_runs"] == 6
    from optuna.trial import TrialState

    trials = _trials(postgres_url, "pg")
    killed = [
        t
        for t in trials
        if t.user_attrs.get("pid") == a.pid
        and t.user_attrs.get("config_key") == interrupted
        and t.state != TrialState.COMPLETE
    ]
    # a claim of the same configuration that gave way earlier (both processes yielding at once) ends PRUNED;
    # the claim that stood and was killed mid-fit is the interrupted trial: failed, not left RUNNING
    assert all(t.state == TrialState.PRUNED for t in killed if not t.user_attrs.get("claimed"))
    assert [t.state for t in killed if t.user_attrs.get("claimed")] == [TrialState.FAIL]
    # and its configuration was finished by the other process
    assert [
        t.user_attrs["pid"]
        for t in trials
        if t.state == TrialState.COMPLETE and t.user_attrs["config_key"] == interrupted
    ] == [b.pid]


@pytest.mark.slow
def test_sqlite_search_killed_then_rerun_completes_exactly_the_requested_trials(files, tmp_path):
    """SIGKILL after the first finished trial, then the same command again: exactly the
    requested COMPLETE trials, exit 0 (measured before: 5 of 6, exit 0)."""
    db = f"sqlite:///{tmp_path / 's.db'}"
    a = _search(files, db, "s", "--trials", "5")
    _kill_in_trial(a, db, "s")
    again = _search(files, db, "s", "--trials", "5")
    out, err = again.communicate(timeout=400)
    assert again.returncode == 0, err[-2000:]
    keys = _complete_keys(db, "s")
    assert len(keys) == 5 and len(set(keys)) == 5
    assert json.loads(out)["missing"] == 0


@pytest.mark.slow
def test_two_processes_on_postgres_random_sampler_no_overshoot(files, postgres_url):  # noqa: F811
    """Random draws from the same seed in two processes: exactly --trials distinct COMPLETE configurations."""
    a = _search(files, postgres_url, "rnd", "--sampler", "random", "--trials", "4")
    b = _search(files, postgres_url, "rnd", "--sampler", "random", "--trials", "4")
    for p in (a, b):
        _, err = p.communicate(timeout=400)
        assert p.returncode == 0, err[-2000:]
    keys = _complete_keys(postgres_url, "rnd")
    assert len(keys) == 4 and len(set(keys)) == 4


@pytest.mark.slow
def test_trial_of_a_dead_process_on_another_host_is_taken_over_after_the_heartbeat_grace(files, tmp_path):
    """The heartbeat path (Optuna's fail_stale_trials + retry callback): a RUNNING trial whose owner is on
    another host cannot be checked by pid; it is failed once its heartbeat is older than the grace period."""
    from optuna.trial import TrialState

    db = f"sqlite:///{tmp_path / 'h.db'}"
    a = _search(files, db, "h", "--trials", "3")
    _kill_in_trial(a, db, "h")
    running = [t for t in _trials(db, "h") if t.state == TrialState.RUNNING]
    assert len(running) == 1
    _STORAGES[db].set_trial_user_attr(running[0]._trial_id, "host", "another-host")
    t0 = time.monotonic()
    again = _search(files, db, "h", "--trials", "3", grace=8)
    out, err = again.communicate(timeout=400)
    assert again.returncode == 0, err[-2000:]
    keys = _complete_keys(db, "h")
    assert len(keys) == 3 and len(set(keys)) == 3
    assert running[0].user_attrs["config_key"] in keys
    assert time.monotonic() - t0 > 8  # it had to wait for the grace period (PIEZOTWIN_GRACE_S=8)


def test_search_that_cannot_complete_says_how_many_are_missing_and_exits_1(tmp_path, monkeypatch, capsys):
    """A configuration whose fit raises every time is given up after two tries: exit 1, and a line naming
    the number of missing configurations; the others complete."""
    import numpy as np

    import sysid.search.sweep as S  # run_config looks run_one up here
    from benchmarks.cli import main
    from sysid.data.record import Record

    rng = np.random.default_rng(0)
    u = rng.standard_normal(400)
    y = np.convolve(u, [0.0, 0.5, 0.25], mode="full")[:400]
    write_record(Record(u=u, y=y, fs=1.0), tmp_path / "e.npz")
    real = S.run_one

    def broken(spec, config, *args):
        if config.get("ny") == "2":
            raise RuntimeError("fit failed")
        return real(spec, config, *args)

    monkeypatch.setattr(S, "run_one", broken)
    code = main(
        [
            "search",
            "arx",
            "--est",
            str(tmp_path / "e.npz"),
            "--val",
            str(tmp_path / "e.npz"),
            "--grid",
            "ny=1,2,3",
            "--storage",
            str(tmp_path / "m.db"),
            "--no-progress",
            "--json",
        ]
    )
    captured = capsys.readouterr()
    assert code == 1
    assert "search: 1 of 3 requested configurations did not complete" in captured.err
    summary = json.loads(captured.out)
    assert summary["missing"] == 1 and summary["complete"] == 2
    assert sorted(_complete_keys(f"sqlite:///{tmp_path / 'm.db'}", "piezotwin-search")) == ["ny=1", "ny=3"]


@pytest.mark.slow
def test_two_processes_create_one_new_sqlite_store_at_once(files, tmp_path):
    """Two processes started together on a store that does not exist yet: neither crashes,
    and between them they finish the grid, each configuration once."""
    db = f"sqlite:///{tmp_path / 'new.db'}"
    procs = [_search(files, db, "n") for _ in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=400)
        assert p.returncode == 0, err[-2000:]
    keys = _complete_keys(db, "n")
    assert sorted(keys) == sorted(f"lags={i}" for i in range(1, 7))
