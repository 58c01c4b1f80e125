"""Where the embarrassingly parallel work of the benchmark commands runs: here, or on Dask workers.

``score`` (identifier × dataset pairs), ``sweep`` (one task per parameter value), ``generate --grid`` (one
task per grid point × seed) and ``search`` (the repeats of one configuration) hand their tasks to an
:class:`Executor`:

* default: in this process, one task after the other (nothing changes for a single user);
* ``--workers N``: a ``distributed.LocalCluster`` of N worker processes with one thread each, started for
  the command and closed after it;
* ``--scheduler ADDRESS`` (or the environment variable ``PIEZOTWIN_SCHEDULER``): a running Dask scheduler
  (``dask scheduler`` on one machine, ``dask worker ADDRESS`` on each of the others).

Every task is a pure function of its arguments (identifier, dataset, settings, seed ...) and the results are
put back in the order of the tasks, so the output does not depend on where or in which order the tasks ran:
the same JSON as the serial run, timings aside. A worker that dies mid-task (killed, out of memory) loses the
task to the scheduler, which runs it again on another worker (Dask's ``allowed-failures``, 3 by default).
Progress: a tqdm bar over the completed tasks on stderr (:func:`sysid.progress.progress`), shown only on a terminal.

Dask starts its worker processes with ``OMP/MKL/OPENBLAS_NUM_THREADS=1``; the serial path gives the same
numbers when BLAS runs one thread too (``OPENBLAS_NUM_THREADS=1``, as CI sets it). Neural training sets
torch's threads itself (:func:`sysid.neural.device.configure_threads`).
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Sequence
from typing import Any

from sysid.errors import ConfigError

SCHEDULER_ENV = "PIEZOTWIN_SCHEDULER"

__all__ = ["SCHEDULER_ENV", "Executor", "add_execution_args", "executor_from_args", "make_executor"]


def add_execution_args(p: argparse.ArgumentParser, workers: bool = True) -> None:
    """``--workers N`` and ``--scheduler ADDRESS`` (the same on every command that fans out)."""
    g = p.add_argument_group("execution (Dask)")
    if workers:
        g.add_argument(
            "--workers",
            type=int,
            metavar="N",
            help="run the tasks on a local Dask cluster of N worker processes (default: in this process)",
        )
    g.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help=f"run the tasks on a running Dask scheduler, e.g. tcp://host:8786 (default ${SCHEDULER_ENV})",
    )


class Executor:
    """Runs tasks in this process (``client=None``) or on a Dask cluster; results in task order.

    Use as a context manager: a local cluster started here is closed on exit; a cluster reached through
    ``--scheduler`` is only disconnected from.
    """

    def __init__(self, client=None, cluster=None):
        self.client, self.cluster = client, cluster

    @property
    def kind(self) -> str:
        return "serial" if self.client is None else "dask"

    @property
    def n_workers(self) -> int:
        if self.client is None:
            return 1
        return max(1, len(self.client.scheduler_info().get("workers", {})))

    def share(self, obj: Any) -> Any:
        """A handle on ``obj`` for task arguments: sent once to the cluster (Dask scatter), not once per task.

        Sent as plain pickle bytes and unpickled once per worker process: Dask's own zero-copy transfer hands
        numpy arrays over as views into its message frames, which need not be 8-byte aligned, and numpy's
        loops on unaligned float64 data round differently in the last bit (docs/running-at-scale.md). Unpickled
        arrays are fresh, aligned allocations, so the task sees the same bytes at the same alignment as the
        serial run.
        """
        if self.client is None:
            return obj
        return self.client.scatter(_Blob(obj), broadcast=False, hash=False)

    def map(
        self,
        fn: Callable[..., Any],
        tasks: Sequence[tuple],
        desc: str = "tasks",
        progress: bool = True,
        on_result: Callable[[int, Any], None] | None = None,
        keep: bool = True,
        priorities: Sequence[float] | None = None,
    ) -> list[Any]:
        """``[fn(*task) for task in tasks]``, wherever it runs.

        ``on_result(index, result)`` is called in the order the tasks finish (to log a line per task); the
        ``priorities`` (one per task, larger first) orders the tasks on a cluster, e.g. the expected cost, so
        that the long ones start first and the short ones fill the end (no idle worker while the last long task
        runs); in this process the tasks run in their given order. The
        returned list is in the order of ``tasks`` (all None with ``keep=False``, for results that
        ``on_result`` stores elsewhere, e.g. records written to a file as they come). An exception raised by
        a task is raised here (the other tasks are cancelled): tasks that can fail as a result must catch and
        return their errors.
        """
        from sysid.progress import progress as progress_bar

        tasks = list(tasks)
        results: list[Any] = [None] * len(tasks)
        with progress_bar(total=len(tasks), desc=desc, show=bool(progress)) as bar:
            if self.client is None:
                for i, task in enumerate(tasks):
                    res = fn(*task)
                    if on_result is not None:
                        on_result(i, res)
                    if keep:
                        results[i] = res
                    bar.update(1)
                return results
            from distributed import as_completed

            prio = [0.0] * len(tasks) if priorities is None else [float(p) for p in priorities]
            futures = [
                self.client.submit(_call, fn, *task, pure=False, priority=p)
                for task, p in zip(tasks, prio, strict=True)
            ]
            index = {f.key: i for i, f in enumerate(futures)}
            try:
                for fut in as_completed(futures):
                    i = index[fut.key]
                    res = fut.result()
                    fut.release()
                    if on_result is not None:
                        on_result(i, res)
                    if keep:
                        results[i] = res
                    bar.update(1)
            except BaseException:
                self.client.cancel(futures)
                raise
        return results

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        self.client = self.cluster = None

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _Blob:
    """A shared object as pickle bytes (see :meth:`Executor.share`)."""

    def __init__(self, obj: Any):
        import pickle
        import uuid

        self.token, self.data = uuid.uuid4().hex, pickle.dumps(obj, protocol=4)


_UNPICKLED: dict[str, Any] = {}  # per worker process: the last few shared objects, by token


def _resolve(arg: Any) -> Any:
    if not isinstance(arg, _Blob):
        return arg
    if arg.token not in _UNPICKLED:
        import pickle

        while len(_UNPICKLED) >= 8:
            _UNPICKLED.pop(next(iter(_UNPICKLED)))
        _UNPICKLED[arg.token] = pickle.loads(arg.data)
    return _UNPICKLED[arg.token]


def _call(fn: Callable[..., Any], *args: Any) -> Any:
    """Run one task on a worker: shared objects unpickled (once per process), then ``fn(*args)``."""
    return fn(*(_resolve(a) for a in args))


def make_executor(workers: int | None = None, scheduler: str | None = None) -> Executor:
    """An :class:`Executor`: a Dask client of ``scheduler`` (or ``$PIEZOTWIN_SCHEDULER``), else a local
    cluster of ``workers`` processes, else (both unset) in-process."""
    if workers is not None and int(workers) < 1:
        raise ConfigError(f"--workers must be ≥ 1, got {workers}")
    if scheduler and workers is not None:
        raise ConfigError("--workers starts a local cluster and --scheduler names a running one: give one of them")
    scheduler = scheduler or (None if workers is not None else os.environ.get(SCHEDULER_ENV) or None)
    if not scheduler and workers is None:
        return Executor()
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise ConfigError(f"Dask distributed is not installed ({exc}); pip install distributed") from None
    if scheduler:
        try:
            return Executor(Client(scheduler, timeout="20s"))
        except (OSError, TimeoutError) as exc:
            raise ConfigError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None
    import logging
    import warnings

    import dask

    # Dask starts its workers with MALLOC_TRIM_THRESHOLD_=65536; setting it switches off glibc's dynamic mmap
    # threshold, so every numpy temporary above 128 KiB is mmapped and page-faulted afresh: measured here, the
    # same numpy task took 0.85 CPU s in such a worker, 0.35 s without the variable (and 0.78 s in this process
    # with it). Unset for the workers started here (see docs/running-at-scale.md for `dask worker`). The
    # workers' statistical profiler (a thread sampling the task's stack every 10 ms, for the dashboard, which
    # is not started here) is switched off too.
    settings = {
        "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
        "distributed.worker.profile.enabled": False,
    }
    with warnings.catch_warnings(), dask.config.set(settings):
        # "Port 8787 is already in use ... Hosting the HTTP server on port N instead": another cluster on this
        # machine; harmless (no dashboard is started)
        warnings.filterwarnings("ignore", message="Port .* is already in use", category=UserWarning)
        cluster = LocalCluster(
            n_workers=int(workers or 1),
            processes=True,
            threads_per_worker=1,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
    return Executor(Client(cluster), cluster)


def executor_from_args(args: argparse.Namespace) -> Executor:
    return make_executor(getattr(args, "workers", None), getattr(args, "scheduler", None))
