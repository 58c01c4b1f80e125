"""Running a sweep's Optuna study from one or many processes so that it ends with exactly the requested trials.

One Optuna trial is one configuration (all its repeats). Any number of processes — local ones started by
``workers``, or ``piezotwin search`` run by hand on several machines against one PostgreSQL database — run
:func:`worker_loop` on the same study, and between them finish each requested configuration exactly once:

* **Claim.** A trial writes its configuration key as a user attribute (``config_key``) before it fits
  anything, then reads the study: if another trial already finished that configuration or is running it, or
  if the configurations finished or running would exceed the requested number, it gives way (ends PRUNED,
  which is not counted) and the process tries again after a short random pause. Two processes that claim at
  the same moment both see both claims, so at most one of any two claims survives; either may yield, never
  neither.
* **Dead workers.** Every running trial sends a heartbeat (Optuna's ``RDBStorage(heartbeat_interval,
  grace_period)``); a trial whose heartbeat is older than the grace period is failed by Optuna's
  ``fail_stale_trials`` and re-queued by ``RetryHeartbeatStaleTrialCallback`` (formerly
  ``RetryFailedTrialCallback``). A trial of a process that died on *this* host (its pid is gone) is failed at
  once, so that a local resume after ``kill -9`` does not wait for the grace period. While the rest of the
  requested configurations is running elsewhere, a process waits (polling) instead of exiting: if the other
  process dies, its configuration is taken over when its heartbeat goes stale.
* **Counting.** The sweep is done when the study holds ``target`` COMPLETE trials with distinct
  configurations; :func:`run_sweep` reports how many are missing otherwise (a configuration whose fit raised
  twice in this process is given up), and ``piezotwin search`` exits 1 with that number.

Heartbeat settings: ``PIEZOTWIN_HEARTBEAT_S`` (default 20 s) and ``PIEZOTWIN_GRACE_S`` (default 3 heartbeats).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import random
import socket
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict
from typing import Any

from sysid.errors import ConfigError
from sysid.search.sweep import (
    SweepSpec,
    _grid_configs,
    _make_objective,
    _make_sampler,
    _requeue_failed,
    config_key,
    heartbeat_settings,
    open_study,
    storage_url,
)
from sysid.search.sweep_results import collect, summarise

HOST = socket.gethostname()
MAX_FAILURES = 2  # a configuration whose fit raised this often in one process is given up (reported missing)


def _pid_alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[-1].split()[0] not in ("Z", "X")  # a zombie is dead
    except FileNotFoundError:
        return False
    except OSError:  # no /proc: ask the kernel
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True


def done_keys(study) -> set[str]:
    from optuna.trial import TrialState

    return {
        t.user_attrs["config_key"]
        for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE,))
        if "config_key" in t.user_attrs
    }


def _snapshot(study) -> tuple[set[str], set[str]]:
    """(configurations finished, configurations claimed by RUNNING trials), from one read of the study."""
    from optuna.trial import TrialState

    trials = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.RUNNING))
    done = {t.user_attrs.get("config_key") for t in trials if t.state == TrialState.COMPLETE} - {None}
    running = {t.user_attrs.get("config_key") for t in trials if t.state == TrialState.RUNNING} - {None}
    return done, running


def reap(study, spec) -> None:
    """Fail the RUNNING trials of dead processes: stale heartbeats (any host), vanished pids (this host)."""
    from optuna.storages import fail_stale_trials
    from optuna.trial import TrialState

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Optuna marks the heartbeat API experimental
        fail_stale_trials(study)
    me = os.getpid()
    for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):
        pid, host = t.user_attrs.get("pid"), t.user_attrs.get("host")
        if host == HOST and isinstance(pid, int) and pid != me and not _pid_alive(pid):
            try:
                study._storage.set_trial_state_values(t._trial_id, state=TrialState.FAIL)
            except Exception:  # another process failed it first
                pass
    if spec.sampler != "grid":
        _requeue_failed(study, spec)  # grid sweeps pick up unfinished configurations by themselves


def claim(trial, key: str, target: int) -> str | None:
    """Record the claim of ``key`` on ``trial``; the reason to give way, or None when the trial may run."""
    trial.set_user_attr("config_key", key)
    trial.set_user_attr("host", HOST)
    trial.set_user_attr("pid", os.getpid())
    from optuna.trial import TrialState

    # one read of the study, so that a trial finishing between two reads cannot hide from both of them
    trials = trial.study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.RUNNING))
    done = {t.user_attrs.get("config_key") for t in trials if t.state == TrialState.COMPLETE} - {None}
    if key in done:
        return "configuration already done"
    others = {
        t.user_attrs.get("config_key")
        for t in trials
        if t.state == TrialState.RUNNING and t._trial_id != trial._trial_id
    } - {None}
    if key in others:
        return "configuration running in another process"
    if len(done | others | {key}) > target:
        return "the requested number of configurations is finished or running"
    return None


def _next_grid_config(
    taken: set[str], spec, target: int, worker: int, n_workers: int, failed: dict[str, int], rng: random.Random | None
) -> dict[str, str] | None:
    """A configuration among the first ``target`` grid points that is not ``taken`` (finished or running, from the
    caller's one read of the study, the same read that tells it whether anything is still running) nor given up
    here: this worker's share (index mod n_workers) first; a random one after a clash."""
    missing = [
        (i, c)
        for i, c in enumerate(_grid_configs(spec)[:target])
        if config_key(c) not in taken and failed.get(config_key(c), 0) < MAX_FAILURES
    ]
    if not missing:
        return None
    if rng is not None:
        return rng.choice(missing)[1]
    own = [c for i, c in missing if i % n_workers == worker]
    return (own or [c for _, c in missing])[0]


def worker_loop(
    spec,
    url: str,
    study_name: str,
    est,
    val,
    target: int,
    on_trial: Callable[[], None] | None = None,
    barrier=None,
    worker: int = 0,
    n_workers: int = 1,
    executor=None,
) -> None:
    """Run configurations until the study holds ``target`` finished ones, or nothing is left to try here."""
    import optuna
    from optuna.trial import TrialState

    study = open_study(spec, url, study_name, create=False)
    failed: dict[str, int] = {}
    state: dict[str, Any] = {"clash": False}
    objective = _make_objective(spec, est, val, claim, target=target, executor=executor, state=state)
    base = _make_sampler(spec)
    rng = random.Random(f"{HOST}:{os.getpid()}:{time.time_ns()}")
    beat, _ = heartbeat_settings()
    if barrier is not None:
        barrier.wait(timeout=300)
    draws = 0
    while True:
        reap(study, spec)
        done, running = _snapshot(study)
        if len(done) >= target:
            return
        live = running - done
        waiting = study.get_trials(deepcopy=False, states=(TrialState.WAITING,))
        if spec.sampler == "grid":
            cfg = (
                None
                if waiting
                else _next_grid_config(
                    done | running, spec, target, worker, n_workers, failed, rng if state["clash"] else None
                )
            )
            if cfg is None and not waiting:
                if not live:
                    return  # nothing running anywhere and nothing left that may be tried here
                time.sleep(min(2.0, beat / 2))  # the rest runs elsewhere: wait for it, or for its heartbeat to stop
                continue
            if cfg is not None:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                    study.sampler = optuna.samplers.PartialFixedSampler(cfg, base)
        else:
            if len(done | live) >= target and not waiting:
                time.sleep(min(2.0, beat / 2))
                continue
            draws += 1
            if draws > 50 * max(target, 1) + 50:
                return  # the sampler keeps drawing finished configurations
        state["clash"] = False
        try:
            study.optimize(objective, n_trials=1, catch=(Exception,), gc_after_trial=False)
        except optuna.exceptions.UpdateFinishedTrialError:
            pass  # this trial was failed meanwhile as stale (a starved heartbeat); its configuration is re-run
        except ValueError as exc:  # another client finished the same (retried) trial first: its result stands
            if "Cannot tell" not in str(exc):
                raise
        key = state.pop("failed_key", None)
        if key is not None:  # the fit raised (the trial is FAIL, its error in the user attribute "error")
            failed[key] = failed.get(key, 0) + 1
        if state["clash"]:
            time.sleep(rng.uniform(0.05, 0.5))
        if on_trial is not None:
            on_trial()


def _worker_main(
    spec_d: dict, url: str, study_name: str, est, val, target: int, barrier, worker: int, n_workers: int
) -> None:
    from sysid.neural.device import configure_threads

    configure_threads(1)
    worker_loop(
        SweepSpec(**spec_d), url, study_name, est, val, target, barrier=barrier, worker=worker, n_workers=n_workers
    )


def run_sweep(
    spec,
    est,
    val,
    storage: str | None = None,
    study: str = "piezotwin-search",
    trials: int | None = None,
    workers: int = 1,
    progress: bool = True,
    executor=None,
) -> dict[str, Any]:
    """Run (or resume) a sweep; returns :func:`~sysid.search.summarise` of everything the study holds,
    plus ``requested``, ``complete`` and ``missing`` (configurations)."""
    from sysid.progress import progress as progress_bar

    url = storage_url(storage, study)
    st = open_study(spec, url, study)
    n_all = spec.n_configs
    target = n_all if trials is None else int(trials)
    if target < 1:
        raise ConfigError(f"--trials must be ≥ 1, got {trials}")
    target = min(target, n_all)
    reap(st, spec)
    bar = progress_bar(
        total=target,
        initial=min(len(done_keys(st)), target),
        unit="config",
        desc=f"{spec.identifier} sweep",
        show=progress,
        leave=True,
    )

    def tick() -> None:
        bar.n = min(len(done_keys(st)), target)
        bar.refresh()

    try:
        if workers <= 1:
            worker_loop(spec, url, study, est, val, target, on_trial=tick, executor=executor)
        else:
            ctx = mp.get_context("spawn")
            barrier = ctx.Barrier(int(workers))
            procs = [
                ctx.Process(
                    target=_worker_main,
                    args=(asdict(spec), url, study, est, val, target, barrier, w, int(workers)),
                    daemon=False,
                )
                for w in range(int(workers))
            ]
            for p in procs:
                p.start()
            try:
                while any(p.is_alive() for p in procs):
                    time.sleep(1.0)
                    tick()
            except KeyboardInterrupt:
                for p in procs:
                    p.terminate()
                raise
            for p in procs:
                p.join()
            bad = [p.exitcode for p in procs if p.exitcode != 0]
            if bad:
                raise RuntimeError(f"search: {len(bad)} worker process(es) failed (exit codes {bad}); rerun to resume")
        tick()
    finally:
        bar.close()
    out = summarise(collect(url, study))
    complete = len(done_keys(st))
    out.update({"requested": target, "complete": min(complete, target), "missing": max(0, target - complete)})
    return out
