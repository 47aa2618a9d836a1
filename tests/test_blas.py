"""sospoly.blas: one BLAS thread inside the block, the caller's setting restored after."""
import numpy as np
import pytest

from sospoly.blas import single_threaded_blas, with_single_threaded_blas

threadpoolctl = pytest.importorskip("threadpoolctl", reason="threadpoolctl not installed (a core dependency)")


def _blas_threads():
    return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]


def test_limit_inside_and_restored_after():
    np.linalg.cholesky(np.eye(3))          # make sure the BLAS library is loaded
    before = _blas_threads()
    assert before, "numpy's BLAS should be visible to threadpoolctl"
    with single_threaded_blas():
        assert _blas_threads() == [1] * len(before)
    assert _blas_threads() == before


def test_decorator_returns_the_result_and_restores():
    before = _blas_threads()

    @with_single_threaded_blas
    def f(x):
        assert _blas_threads() == [1] * len(before)
        return 2 * x

    assert f(21) == 42
    assert _blas_threads() == before
