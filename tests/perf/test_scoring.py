"""Speed of the benchmark suite itself: loading the vendored lab data, and one identifier fitted and scored on
a real benchmark beside SysIdentPy's FROLS on the same data and structure ("FROLS versus SysIdentPy
in one run", here end-to-end on Silverbox: fit on the 65 062 estimation samples + free run of the 21 688-sample
multisine test).

Run: ``make bench``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from benchmarks.datasets import lab, load_dataset

STRUCT = {"ny": 2, "nu": 2, "degree": 2}


def test_load_all_lab_datasets(benchmark):
    benchmark.extra_info["target_s"] = 0.5
    out = benchmark.pedantic(lambda: [load_dataset(n) for n in lab.LAB_SPECS], rounds=5, iterations=1)
    assert len(out) == len(lab.LAB_SPECS)


@pytest.fixture(scope="module")
def silverbox():
    return load_dataset("silverbox")


def test_silverbox_frols_fit_and_free_run(benchmark, silverbox):
    from sysid.registry import get_identifier

    cls = get_identifier("narx-poly")
    ms = silverbox.tests["multisine"]
    benchmark.extra_info["reference"] = "test_silverbox_sysidentpy_frols_fit_and_free_run"
    benchmark.extra_info["items"] = len(silverbox.est) + len(ms)

    def work():
        m = cls(criterion="aic", **STRUCT).fit(silverbox.est)
        return m.predict(ms, horizon=None)

    y = benchmark.pedantic(work, rounds=3, iterations=1)
    assert np.isfinite(y).all()


def test_silverbox_sysidentpy_frols_fit_and_free_run(benchmark, silverbox):
    pytest.importorskip("sysidentpy", reason="SysIdentPy not installed")
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS
    from sysidentpy.parameter_estimation import LeastSquares

    ms = silverbox.tests["multisine"]
    benchmark.extra_info["items"] = len(silverbox.est) + len(ms)
    x, y = silverbox.est.u.reshape(-1, 1), silverbox.est.y.reshape(-1, 1)

    def work():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = FROLS(
                order_selection=True,
                n_info_values=15,
                ylag=STRUCT["ny"],
                xlag=STRUCT["nu"],
                info_criteria="aic",
                estimator=LeastSquares(),
                basis_function=Polynomial(degree=STRUCT["degree"]),
            )
            m.fit(X=x, y=y)
            return m.predict(X=ms.u.reshape(-1, 1), y=ms.y.reshape(-1, 1)[: m.max_lag])

    out = benchmark.pedantic(work, rounds=1, iterations=1)
    assert np.isfinite(out).all()
