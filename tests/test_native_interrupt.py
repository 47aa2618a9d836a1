"""A signal during a native Clarabel solve ends it within an iteration (review 29b F13): Ctrl-C inside one large
solve used to wait for the whole solve (41 s after the signal on ``minimize(x**200 + y**2)``)."""
from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest
import scipy.sparse as sp

clarabel = pytest.importorskip("clarabel")

from sospoly.solvers.interrupt import solve_interruptibly  # noqa: E402


class _Stop(Exception):
    pass


def _solver(side: int):
    """min <C, X> s.t. trace X = 1, X PSD (side x side): a few iterations of a dense PSD block."""
    rows, cols = np.tril_indices(side)                 # Clarabel's svec order: the upper triangle by columns
    C = np.random.default_rng(0).standard_normal((side, side))
    C = C + C.T
    q = np.where(rows == cols, 1.0, np.sqrt(2.0)) * C[rows, cols]
    n = q.size
    A = sp.vstack([sp.csc_matrix((rows == cols).astype(float)[None, :]), -sp.identity(n, format="csc")]).tocsc()
    b = np.zeros(n + 1)
    b[0] = 1.0
    s = clarabel.DefaultSettings()
    s.verbose = False
    return clarabel.DefaultSolver(sp.csc_matrix((n, n)), q, A, b,
                                  [clarabel.ZeroConeT(1), clarabel.PSDTriangleConeT(side)], s), C


def test_same_answer_without_a_signal():
    plain, C = _solver(12)
    ours, _ = _solver(12)
    a, b = plain.solve(), solve_interruptibly(ours)
    assert str(a.status) == str(b.status) and a.iterations == b.iterations
    np.testing.assert_array_equal(np.asarray(a.x), np.asarray(b.x))
    assert abs(a.obj_val - np.linalg.eigvalsh(C)[0]) < 1e-6 * max(1.0, abs(a.obj_val))


def test_a_signal_ends_the_native_solve_within_an_iteration():
    side = 70
    t = time.perf_counter()
    _solver(side)[0].solve()
    whole = time.perf_counter() - t                    # ~2 s on a quiet machine, 5 iterations
    armed = [True]

    def handler(signum, frame):
        if armed[0]:
            raise _Stop()

    old = signal.signal(signal.SIGUSR1, handler)
    solver = _solver(side)[0]
    timer = threading.Timer(0.05 * whole, lambda: os.kill(os.getpid(), signal.SIGUSR1))
    try:
        timer.start()
        t = time.perf_counter()
        with pytest.raises(_Stop):
            solve_interruptibly(solver)
        took = time.perf_counter() - t
    finally:
        armed[0] = False
        timer.cancel()
        timer.join()
        signal.signal(signal.SIGUSR1, old)
    # before: the exception came only when the whole solve had returned (took >= whole)
    assert took < 0.75 * whole, (took, whole)
