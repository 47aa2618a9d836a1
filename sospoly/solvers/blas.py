"""One BLAS thread inside the hot loops of the small dense solves.

The interior-point iterations of :mod:`sospoly.solvers.ipm` factor many small matrices
(a 495x495 Schur complement for Theorem 1 at delta = 4, stacks of 5x5..25x25 for
batched Corollary 1 problems).  A multi-threaded BLAS gains nothing at these sizes
and, on a machine with few cores that are busy (process pools, CI), its spinning
threads slow each factorisation down by one to two orders of magnitude (measured
on a 2-core machine under load: a 495x495 Cholesky 22 ms threaded, 11 ms with one
thread; 100x in worse cases).  :func:`single_threaded_blas` limits BLAS to one
thread for the duration of a ``with`` block (threadpoolctl, ~0.03 ms per entry)
and restores the caller's setting afterwards; without threadpoolctl it does nothing.
"""
from __future__ import annotations

import contextlib
import functools

__all__ = ["single_threaded_blas", "with_single_threaded_blas"]

_controller = None


def _get_controller():
    global _controller
    if _controller is None:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # optional at run time: a plain no-op then
            _controller = False
        else:
            _controller = ThreadpoolController()
    return _controller


@contextlib.contextmanager
def single_threaded_blas():
    """Context manager: BLAS limited to one thread inside the block."""
    ctl = _get_controller()
    if not ctl:
        yield
        return
    with ctl.limit(limits=1, user_api="blas"):
        yield


def with_single_threaded_blas(func=None, *, min_stack: int = 0):
    """Decorator form of :func:`single_threaded_blas`.  ``min_stack``: the limit is applied only when the
    first argument (a stack of problems) has at least that many entries -- a stack of one (a single
    ``tritools.triangulate`` call) makes only tiny BLAS calls, which OpenBLAS runs on one thread anyway,
    and skips threadpoolctl's per-call query and restore of every BLAS library."""
    if func is None:
        return functools.partial(with_single_threaded_blas, min_stack=min_stack)

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        if min_stack and args and hasattr(args[0], "__len__") and len(args[0]) < min_stack:
            return func(*args, **kwargs)
        with single_threaded_blas():
            return func(*args, **kwargs)
    return wrapper
