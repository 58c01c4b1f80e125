"""sysid._blas.blas_threads: inside the block every loaded BLAS runs the asked number of threads
(PIEZOTWIN_BLAS_THREADS by default, else 1); afterwards each has its own count back."""

from __future__ import annotations

import pytest

threadpoolctl = pytest.importorskip("threadpoolctl")

from sysid._blas import blas_threads  # noqa: E402


def _counts() -> list[int]:
    return [d["num_threads"] for d in threadpoolctl.threadpool_info() if d["user_api"] == "blas"]


def test_blas_threads_limits_every_blas_and_restores(monkeypatch):
    if not _counts():
        pytest.skip("no BLAS library that threadpoolctl knows is loaded")
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        before = _counts()
        monkeypatch.delenv("PIEZOTWIN_BLAS_THREADS", raising=False)
        with blas_threads():
            assert _counts() == [1] * len(before)
        assert _counts() == before
        monkeypatch.setenv("PIEZOTWIN_BLAS_THREADS", "2")
        with threadpoolctl.threadpool_limits(limits=1, user_api="blas"):
            with blas_threads():
                assert _counts() == [2] * len(before)
            assert _counts() == [1] * len(before)
