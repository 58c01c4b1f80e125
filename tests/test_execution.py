"""The Dask execution backend (benchmarks/execution.py) on a real distributed.LocalCluster of 2 worker processes.

Checked against the serial (in-process) run of the same code: identical JSON for score (timings aside),
bit-identical HDF5 collections for generate --grid, the identical complete sweep when a worker process is
SIGKILLed in the middle of it (Dask re-runs the lost task).
"""

from __future__ import annotations

import json
import os
import signal
import threading
import time

import numpy as np
import pytest

pytest.importorskip("distributed")

from benchmarks.execution import Executor, make_executor  # noqa: E402
from benchmarks.scoring import strip_timing  # noqa: E402


@pytest.fixture(scope="module")
def cluster():
    """A real LocalCluster: 2 worker processes, 1 thread each (what --workers 2 starts)."""
    with make_executor(workers=2) as ex:
        yield ex


def test_serial_is_the_default_and_bad_options_are_refused(monkeypatch):
    from sysid.errors import ConfigError

    monkeypatch.delenv("PIEZOTWIN_SCHEDULER", raising=False)
    with make_executor() as ex:
        assert ex.kind == "serial" and ex.client is None
        assert ex.map(divmod, [(7, 2), (9, 4)]) == [(3, 1), (2, 1)]
    with pytest.raises(ConfigError):
        make_executor(workers=0)
    with pytest.raises(ConfigError):
        make_executor(workers=2, scheduler="tcp://127.0.0.1:1")


def test_score_on_two_workers_equals_the_serial_run(cluster):
    """4 identifier x dataset pairs, and a seeded one, on the cluster: the same rows, numbers and order as
    in-process."""
    from benchmarks import scoring

    assert cluster.kind == "dask" and cluster.n_workers == 2
    args = dict(
        identifiers=["arx", "narx-poly"], datasets=["cascaded-tanks", "piezo-tue"], quick=True, sysidentpy=False
    )
    serial = scoring._clean(scoring.score(**args).to_dict())
    parallel = scoring._clean(scoring.score(**args, executor=cluster).to_dict())
    assert len(serial["rows"]) == 4
    assert json.dumps(strip_timing(parallel)) == json.dumps(strip_timing(serial))
    # a seeded identifier: its five training seeds are five tasks, assembled into the same median row
    args = dict(identifiers=["narx-mlp"], datasets=["cascaded-tanks"], quick=True, sysidentpy=False)
    serial = scoring._clean(scoring.score(**args).to_dict())
    parallel = scoring._clean(scoring.score(**args, executor=cluster).to_dict())
    assert serial["rows"][0]["seeds"] == [0, 1, 2, 3, 4]
    assert json.dumps(strip_timing(parallel)) == json.dumps(strip_timing(serial))
    pids = cluster.client.run(os.getpid)
    assert len(set(pids.values())) == 2 and os.getpid() not in pids.values()  # really other processes
    # workers run BLAS single-threaded, and without Dask's MALLOC_TRIM_THRESHOLD_ (2x CPU on numpy temporaries)
    env = cluster.client.run(lambda: (os.environ.get("OPENBLAS_NUM_THREADS"), os.environ.get("MALLOC_TRIM_THRESHOLD_")))
    assert set(env.values()) == {("1", None)}


def test_generate_grid_hdf5_reads_back_bit_identical_with_h5py_alone(cluster, tmp_path):
    """generate --grid on the cluster: h5py alone reads back the in-memory records exactly, plus their
    attributes; the index table lists every record; the serial run writes the same samples."""
    import csv

    import h5py

    from benchmarks.collection import generate_collection, generate_point, parse_grid_spec, parse_seeds
    from twins.registry import get_twin

    twin = get_twin("cantilever").from_options()
    grid = parse_grid_spec("gain_um_per_v=0.2-0.3,bw_alpha=0.3", type(twin.params))
    seeds = parse_seeds("0-1")
    out = generate_collection(twin, "steps", grid, seeds, tmp_path / "c.h5", executor=cluster, progress=False)
    assert out["records"] == 4
    expected = [
        (p, s, generate_point(twin, p, s, "steps", {}))
        for p in ({"gain_um_per_v": 0.2, "bw_alpha": 0.3}, {"gain_um_per_v": 0.3, "bw_alpha": 0.3})
        for s in (0, 1)
    ]
    with h5py.File(tmp_path / "c.h5", "r") as f:
        assert f.attrs["format"] == "piezotwin-collection/1" and f.attrs["twin"] == "cantilever"
        names = sorted(f["records"])
        assert len(names) == 4
        for name, (point, seed, rec) in zip(names, expected):
            g = f["records"][name]
            assert g["u"].dtype == np.float64 and g["u"][()].tobytes() == rec.u.tobytes()
            assert g["y"][()].tobytes() == rec.y.tobytes()
            assert g.attrs["fs"] == rec.fs and g.attrs["seed"] == seed
            assert g.attrs["units_y"] == rec.units["y"] and g.attrs["twin"] == "cantilever"
            assert json.loads(g.attrs["grid_point"]) == point
            params = json.loads(g.attrs["parameters"])
            assert params["gain_um_per_v"] == point["gain_um_per_v"]
            assert json.loads(g.attrs["effects"]) == sorted(twin.effects)
    # noise seeds matter: the two seeds of one grid point differ; the grid values matter too
    assert not np.array_equal(expected[0][2].y, expected[1][2].y)
    assert not np.array_equal(expected[0][2].y, expected[2][2].y)
    with open(tmp_path / "c_index.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["record"] for r in rows] == [f"records/{n}" for n in names]
    assert [(float(r["gain_um_per_v"]), int(r["seed"])) for r in rows] == [(0.2, 0), (0.2, 1), (0.3, 0), (0.3, 1)]
    # the serial run writes the same samples
    generate_collection(twin, "steps", grid, seeds, tmp_path / "s.h5", executor=Executor(), progress=False)
    with h5py.File(tmp_path / "c.h5", "r") as a, h5py.File(tmp_path / "s.h5", "r") as b:
        for name in names:
            assert a["records"][name]["y"][()].tobytes() == b["records"][name]["y"][()].tobytes()
    assert not list(tmp_path.glob(".*tmp*"))  # no temporary file left behind


def test_generate_grid_cli_writes_the_collection(tmp_path):
    from benchmarks.cli import main

    out = tmp_path / "grid.h5"
    assert (
        main(
            [
                "generate",
                "cantilever",
                "steps",
                "--grid",
                "gain_um_per_v=0.2-0.25",
                "--seeds",
                "3",
                "-o",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    import h5py

    with h5py.File(out, "r") as f:
        assert sorted(f["records"]) == ["r00000", "r00001"]
        assert [int(f["records"][n].attrs["seed"]) for n in sorted(f["records"])] == [3, 3]
    assert main(["generate", "cantilever", "steps", "--grid", "gain_um_per_v=0.2", "-o", str(tmp_path / "x.npz")]) == 2
    assert main(["generate", "cantilever", "steps", "--grid", "bogus=1", "-o", str(out)]) == 2


@pytest.mark.slow
def test_sweep_survives_a_worker_killed_mid_task(tmp_path):
    """SIGKILL one worker process while the sweep's tasks run: the lost task is re-run and the result is
    complete and identical to the serial run."""
    from benchmarks.sweep import public, sweep
    from sysid.data.jsonio import clean_json
    from twins.registry import get_twin

    twin = get_twin("acoustic").from_options()
    values = [0.02, 0.04, 0.06, 0.08, 0.1, 0.12]
    serial = clean_json(public(sweep(twin, "distance_m", values)))
    with make_executor(workers=2) as ex:
        pids = ex.client.run(os.getpid)
        killed = []

        def kill_one() -> None:
            # wait until a task is executing on the first worker, then kill that worker's process
            addr = sorted(pids)[0]
            t0 = time.monotonic()
            while time.monotonic() - t0 < 120:
                processing = ex.client.processing()
                if processing.get(addr):
                    time.sleep(0.5)
                    os.kill(pids[addr], signal.SIGKILL)
                    killed.append(pids[addr])
                    return
                time.sleep(0.05)

        th = threading.Thread(target=kill_one)
        th.start()
        parallel = clean_json(public(sweep(twin, "distance_m", values, executor=ex)))
        th.join()
    assert killed, "no worker was killed"
    assert parallel == serial


def test_search_repeats_on_the_cluster_equal_the_serial_sweep(cluster, tmp_path, monkeypatch, capsys):
    """search --scheduler: the repeats of each configuration run as Dask tasks; the stored runs equal the
    serial sweep's (timings and pids aside). Through PIEZOTWIN_SCHEDULER, as a user on a cluster would."""
    from benchmarks.cli import main
    from sysid.data.io import write_record
    from sysid.data.record import Record

    rng = np.random.default_rng(1)
    u = rng.standard_normal(600)
    y = np.convolve(u, [0.0, 0.6, -0.2, 0.1], mode="full")[:600] + 0.01 * rng.standard_normal(600)
    write_record(Record(u=u, y=y, fs=10.0), tmp_path / "e.npz")
    argv = [
        "search",
        "arx",
        "--est",
        str(tmp_path / "e.npz"),
        "--val",
        str(tmp_path / "e.npz"),
        "--grid",
        "ny=1,2;nu=1,3",
        "--repeats",
        "2",
        "--no-progress",
        "--json",
    ]
    monkeypatch.delenv("PIEZOTWIN_SCHEDULER", raising=False)
    assert main([*argv, "--storage", str(tmp_path / "serial.db")]) == 0
    serial = json.loads(capsys.readouterr().out)
    monkeypatch.setenv("PIEZOTWIN_SCHEDULER", cluster.client.scheduler.address)
    assert main([*argv, "--storage", str(tmp_path / "dask.db")]) == 0
    dask = json.loads(capsys.readouterr().out)
    assert dask["n_runs"] == serial["n_runs"] == 8
    drop = ("storage",)
    assert strip_timing({k: v for k, v in dask.items() if k not in drop}) == strip_timing(
        {k: v for k, v in serial.items() if k not in drop}
    )
    from sysid.search import collect, storage_url

    runs = collect(storage_url(str(tmp_path / "dask.db"), "piezotwin-search"), "piezotwin-search")
    assert os.getpid() not in {r["pid"] for r in runs}  # fitted on the workers


def test_score_spreads_the_training_seeds_of_a_pair_as_tasks():
    """Quick mode: one task per training seed (five for a seeded identifier, the extra four return nothing for
    an unseeded one), so a neural pair is not one long task that leaves the other workers idle."""
    from benchmarks import scoring
    from benchmarks.execution import Executor

    class Recording(Executor):
        def map(self, fn, tasks, **kw):
            self.tasks = list(tasks)
            return super().map(fn, self.tasks, **kw)

    ex = Recording()
    run = scoring.score(["arx"], ["cascaded-tanks"], quick=True, sysidentpy=False, executor=ex)
    assert [t[-1] for t in ex.tasks] == [0, 1, 2, 3, 4]
    assert len(run.rows) == 1 and "seeds" not in run.rows[0]  # one fit: arx has no training seed
