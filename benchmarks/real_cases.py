"""The real cases of the missing-physics diagnosis (docs/diagnosis.md, "Real cases"): each benchmark's measured
records diagnosed with the example model a user would write first (``benchmarks/examples/``), then the model as
given (calibrated) and the extended model scored on the benchmark's test records, which the diagnosis never sees.

``python -m benchmarks.real_cases bouc-wen [--rounds 3] [--json]`` runs one case with the diagnosis's defaults
(``--starts``, ``--pairs``, ``--trial-nfev`` as in ``piezotwin diagnose``; the cascaded tanks with ``pairs``: a
slow, strongly correlated residual of a few dozen effective samples, on which mechanisms that mask each other are
found only together), prints a progress line per round on
stderr and reports the test RMSE before and after with the user CPU seconds of the process.

How each test is scored is the benchmark's protocol: from its initialisation window on (Silverbox 50 samples,
cascaded tanks 4 and 50 for ``test-official``), and the Bouc–Wen multisine from the periodic steady state
(:meth:`twins.equations.twin.EquationTwin.simulate_periodic`): that record is one period of the response after
its transient (its true model scores 4.6·10⁻⁵ m from rest, 2.6·10⁻⁷ m from the steady state), while its sine
sweep starts at rest.
"""

from __future__ import annotations

import argparse
import json
import logging
import resource
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CASES", "RealCase", "run_case", "score_tests"]

EXAMPLES = Path(__file__).resolve().parent / "examples"
#: the progress line of each round (INFO; ``main`` shows it on stderr)
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RealCase:
    """One real case: the dataset, the example model, whether the diagnosis validates on the benchmark's test
    record (cascaded tanks, as the benchmark defines its validation) and the tests scored from steady state."""

    dataset: str
    model: str
    validate_on: str | None = None
    periodic_tests: tuple[str, ...] = ()
    options: dict[str, Any] = field(default_factory=dict)


CASES = {
    "silverbox": RealCase("silverbox", "silverbox.py"),
    # every leader that is not significant alone tried jointly (``pairs``): the tanks' masked mechanisms
    "cascaded-tanks": RealCase("cascaded-tanks", "torricelli_tanks.py", validate_on="test", options={"pairs": True}),
    "bouc-wen": RealCase("bouc-wen", "bouc_wen_oscillator.py", periodic_tests=("multisine",)),
}


def _user_cpu() -> float:
    return float(resource.getrusage(resource.RUSAGE_SELF).ru_utime)


def score_tests(twin: Any, case: RealCase, data: Any) -> dict[str, float]:
    """Free-run RMSE of ``twin`` on each test record of the case's dataset, scored as the module docstring says."""
    out = {}
    for name, rec in data.tests.items():
        u = np.asarray(rec.u, float)
        y = twin.simulate_periodic(u, rec.fs) if name in case.periodic_tests else twin.simulate(u, rec.fs)
        k = data.init_for(name)
        e = np.asarray(rec.y, float)[k:] - np.asarray(y, float)[k:]
        out[name] = float(np.sqrt(np.mean(e**2))) if np.all(np.isfinite(e)) else float("nan")
    return out


def run_case(name: str, rounds: int = 3, progress: bool = True, hybrid: bool = False, **options: Any) -> dict[str, Any]:
    """Diagnose case ``name`` (:data:`CASES`) with :class:`twins.discrepancy.DiagnoseOptions` ``options`` over the
    defaults, and score the configuration as given and the extended one on the tests; with ``hybrid``, also the
    extended one plus a black-box remainder fitted on the estimation record (:class:`twins.hybrid.HybridTwin`,
    its structure chosen on that record too)."""
    from benchmarks.datasets import load_dataset
    from twins.discrepancy import DiagnoseOptions, run_diagnosis
    from twins.external import load_model

    case = CASES[name]
    data = load_dataset(case.dataset)
    cpu0 = _user_cpu()
    twin = load_model(str(EXAMPLES / case.model))()

    def say(msg: str) -> None:
        log.info("[%s] %s", name, msg)

    opts = DiagnoseOptions(**{"on_round": say if progress else None, **case.options, **options})
    val = data.tests[case.validate_on] if case.validate_on else None
    diag = run_diagnosis(twin, data.est_records[0], val, max_rounds=rounds, options=opts)
    before = score_tests(diag.baseline.twin, case, data)
    after = score_tests(diag.extended.twin, case, data)
    extra: dict[str, Any] = {}
    if hybrid:
        from twins.discrepancy.prediction import deterministic
        from twins.hybrid import HybridTwin

        hy = HybridTwin(deterministic(diag.extended.twin)).fit(data.est_records[0])
        extra = {"test_rmse_hybrid": score_tests(hy, case, data), "hybrid_remainder": hy.identifier_}
    return {
        "case": name,
        "model": case.model,
        "verdict": diag.verdict,
        "named": [c["effect"] for c in diag.causes],
        "params": {k: v for c in diag.causes for k, v in c.get("params", {}).items()},
        "test_rmse_before": before,
        "test_rmse_after": after,
        "nrmse_val": [diag.baseline.nrmse_val, diag.extended.nrmse_val],
        "rounds": rounds,
        **extra,
        "cpu_user_s": _user_cpu() - cpu0,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.real_cases", description=__doc__.splitlines()[0])
    ap.add_argument("case", choices=sorted(CASES))
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--starts", type=int, default=None)
    ap.add_argument("--pairs", action="store_true")
    ap.add_argument("--trial-nfev", type=int, default=None)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--hybrid", action="store_true", help="also score the extended model plus a black-box remainder")
    args = ap.parse_args(argv)
    logging.basicConfig(stream=sys.stderr, level=logging.INFO, format="%(message)s")
    extra: dict[str, Any] = {"pairs": True} if args.pairs else {}
    if args.starts is not None:
        extra["starts"] = args.starts
    if args.trial_nfev is not None:
        extra["trial_nfev"] = args.trial_nfev
    res = run_case(args.case, rounds=args.rounds, hybrid=args.hybrid, **extra)
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        for key, val in res.items():
            print(f"{key}: {val}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
