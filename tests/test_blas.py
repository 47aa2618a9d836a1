"""sospoly.solvers.blas: one BLAS thread inside the block, the caller's setting restored after."""
import numpy as np
import pytest

from sospoly.solvers.blas import single_threaded_blas, with_single_threaded_blas

threadpoolctl = pytest.importorskip("threadpoolctl", reason="threadpoolctl not installed (a core dependency)")


def _blas_threads():
    return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]


@pytest.fixture
def two_blas_threads():
    """The caller's setting is 2 threads, so that "1 inside" and "restored after" can fail
    (the tests are run with OPENBLAS_NUM_THREADS=1, where both would hold trivially)."""
    np.linalg.cholesky(np.eye(3))          # make sure the BLAS library is loaded
    with threadpoolctl.threadpool_limits(2, user_api="blas"):
        before = _blas_threads()
        # several BLAS libraries may be loaded (numpy's, scipy's, a solver's); some ignore the
        # setting -- at least one at 2 threads is what makes the checks below able to fail
        assert 2 in before, f"numpy's BLAS should be visible and settable: {before}"
        yield before


def test_limit_inside_and_restored_after(two_blas_threads):
    with single_threaded_blas():
        assert _blas_threads() == [1] * len(two_blas_threads)
    assert _blas_threads() == two_blas_threads


def test_decorator_returns_the_result_and_restores(two_blas_threads):
    @with_single_threaded_blas
    def f(x):
        assert _blas_threads() == [1] * len(two_blas_threads)
        return 2 * x

    assert f(21) == 42
    assert _blas_threads() == two_blas_threads
