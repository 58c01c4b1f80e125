"""Exit-abort stress test of the exported FMUs run in-process with FMPy (README section "fmu").

Runs N fresh Python processes, each with its own ``PYTHONHASHSEED``. Each one simulates the cantilever FMU
in-process, either as a plain FMPy script (``--mode fmpy``: the project is not imported, the code shipped
in the FMU runs) or through ``twins.fmu.check.fmu_simulate`` (``--mode project``: the host's ``twins``
package, from ``--pythonpath``, runs the slave), (two instances: default and a changed parameter), then the two FMI
error cases (a refused parameter value, a communication step that is not a whole number of periods), then exits
normally. A process that aborts at exit (glibc "corrupted double-linked list", status 134) is counted. The child's
stdout goes to /dev/null: that layout of libgfortran's unit buffers made the abort most frequent.

    python tests/perf/fmu_exit_stress.py -n 30                 # FMU built from the current code
    python tests/perf/fmu_exit_stress.py -n 30 --fmu fmus/cantilever.fmu --mode project

Prints one line per failing process and a JSON summary (``runs``, ``aborts``, ``failures``, ``fmu``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

CHILD = r"""
import sys
import numpy as np, fmpy
path = sys.argv[1]
fs = 10e3
n = 200
sig = np.zeros(n + 1, dtype=[("time", float), ("u", float)])
sig["time"] = np.arange(n + 1) / fs
sig["u"] = 50 * np.sin(2 * np.pi * 20 * sig["time"])
if sys.argv[2] == "project":  # the project's helper: the host's twins package runs the slave
    from twins.fmu.check import fmu_simulate
    def run(**start):
        return fmu_simulate(path, sig["u"][:n], fs, start_values=start)
else:  # a plain FMPy script: the code shipped in the FMU runs
    def run(**start):
        return fmpy.simulate_fmu(path, stop_time=n / fs, output_interval=1 / fs, input=sig, output=["y"],
                                 start_values=start)["y"]
y, y2 = run(), run(bw_alpha=0.45)
assert np.all(np.isfinite(y)) and np.abs(y).max() > 1 and not np.array_equal(y, y2)
if sys.argv[2] != "project":
    assert "resources" in sys.modules["twins"].__file__  # the FMU's own code ran
refused = 0
for kw in (dict(start_values={"hysteresis": "honey"}, output_interval=1e-4), dict(output_interval=1.5e-4)):
    try:
        fmpy.simulate_fmu(path, stop_time=0.002, **kw)
    except Exception:
        refused += 1
assert refused == 2, refused
print("ok")
"""


def build(folder: Path) -> Path:
    sys.path.insert(0, str(REPO))
    from twins.cantilever import CantileverTwin
    from twins.fmu import export_fmu

    return export_fmu(CantileverTwin(), folder / "cantilever.fmu")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-n", type=int, default=30, help="number of fresh processes (default 30)")
    ap.add_argument("--fmu", help="FMU to run (default: build the cantilever FMU from the current code)")
    ap.add_argument(
        "--mode",
        choices=("fmpy", "project"),
        default="fmpy",
        help="plain FMPy script, or the project's fmu_simulate (default fmpy)",
    )
    ap.add_argument("--pythonpath", default=str(REPO), help="where the project is imported from (--mode project)")
    ap.add_argument("--seed0", type=int, default=1, help="first PYTHONHASHSEED (default 1)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="fmu_stress_") as tmp:
        path = Path(args.fmu).resolve() if args.fmu else build(Path(tmp))
        script = Path(tmp) / "fmu_exit_child.py"  # run as a script file, as a user's script would be
        script.write_text(CHILD)
        aborts, failures = 0, 0
        for k in range(args.n):
            seed = args.seed0 + k
            env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
            env["PYTHONHASHSEED"] = str(seed)
            if args.mode == "project":
                env["PYTHONPATH"] = args.pythonpath
            proc = subprocess.run(
                [sys.executable, str(script), str(path), args.mode],
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
                timeout=600,
            )
            if proc.returncode == -6 or proc.returncode == 134:
                aborts += 1
                print(f"seed {seed}: abort ({proc.stderr.strip().splitlines()[-1:]})", flush=True)
            elif proc.returncode != 0:
                failures += 1
                print(f"seed {seed}: exit status {proc.returncode}: {proc.stderr[-500:]}", flush=True)
        print(json.dumps({"runs": args.n, "aborts": aborts, "failures": failures, "fmu": str(path), "mode": args.mode}))
    return 0 if aborts == 0 and failures == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
