"""The verdict's noise level judged on the benchmark's cases: what a perfect model's residual scores against it.

The ``unexplained`` verdict compares the validation residual with the noise level measured from the data
(:func:`twins.discrepancy.unexplained.records_noise`; R = mean(e²)/σ² above
:data:`~twins.discrepancy.unexplained.EXCESS_LIMIT`). A model that is exactly right leaves the added noise as its
residual, so R of that noise is the excess the verdict sees from the noise estimate alone: near 1 when the
estimate is right, above the limit a false ``unexplained``, far below it a margin in which a real discrepancy
goes unseen. The noise estimators assume white noise; the generator colours half the cases with an AR(1) pole
0.5–0.95, for which the high-frequency floor sees the variance times (1 − ρ)/(1 + ρ).

``python -m benchmarks.diagnosis_bench.noise_check [--cases A:B] [--json]`` builds the records of the seeds
(no diagnosis: seconds per case) and prints R per case and a table per noise colour.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np

__all__ = ["perfect_excess", "summarise"]

#: noise-colour strata of the table: (label, lowest AR(1) pole, highest)
COLOURS = (
    ("white", 0.0, 0.0),
    ("AR(1) 0.50–0.70", 0.5, 0.7),
    ("AR(1) 0.70–0.85", 0.7, 0.85),
    ("AR(1) 0.85–0.95", 0.85, 1.0),
)


def perfect_excess(seed: int) -> dict[str, Any]:
    """R of the validation record's own noise against the noise level of the case's two records (module
    docstring), with the case's noise colour and the estimator the level came from."""
    from twins.discrepancy.unexplained import records_noise

    from .cases import draw_case
    from .truth import make_records

    case = draw_case(seed)
    b = make_records(case)
    nl = records_noise(b["est"], b["val"])
    p_noise = float(np.mean(np.asarray(b["noise"][1], float) ** 2))
    return {
        "seed": seed,
        "family": case.family,
        "mechanism": case.mechanism,
        "kinds": [case.est_kind, case.val_kind],
        "noise_ar": case.noise_ar,
        "excess": p_noise / nl["sigma2"] if nl["sigma2"] > 0 else float("inf"),
        "source": nl["source"],
    }


def summarise(rows: list[dict[str, Any]], limit: float) -> list[dict[str, Any]]:
    """Per noise colour: cases, median and largest R, and the share above ``limit``. Quantised cases are left
    out (their noise-free lattice makes σ² the value spacing's, not the noise's)."""
    out = []
    for label, lo, hi in COLOURS:
        r = [
            x["excess"]
            for x in rows
            if x["mechanism"] != "quantization" and (lo <= x["noise_ar"] < hi if hi > lo else x["noise_ar"] == 0.0)
        ]
        if r:
            above = sum(v > limit for v in r)
            out.append(
                {
                    "noise": label,
                    "cases": len(r),
                    "median": float(np.median(r)),
                    "max": float(np.max(r)),
                    "above_limit": above,
                }
            )
    return out


def main(argv: list[str] | None = None) -> int:
    from twins.discrepancy.unexplained import EXCESS_LIMIT

    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.diagnosis_bench.noise_check", description=__doc__.splitlines()[0]
    )
    ap.add_argument("--cases", default="0:100", help="seeds A:B (B excluded); default 0:100")
    ap.add_argument("--json", action="store_true", help="print the rows and the table as JSON")
    args = ap.parse_args(argv)
    try:
        a, b = (int(x) for x in args.cases.split(":"))
    except ValueError:
        print(f"--cases {args.cases!r}: give two seeds A:B", file=sys.stderr)
        return 2
    rows = [perfect_excess(s) for s in range(a, b)]
    table = summarise(rows, EXCESS_LIMIT)
    if args.json:
        print(json.dumps({"limit": EXCESS_LIMIT, "rows": rows, "table": table}, indent=1))
        return 0
    print(f"| noise | cases | median R | largest R | R > {EXCESS_LIMIT:g} |")
    print("|---|---|---|---|---|")
    for t in table:
        print(f"| {t['noise']} | {t['cases']} | {t['median']:.2f} | {t['max']:.1f} | {t['above_limit']} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
