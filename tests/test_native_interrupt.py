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


def test_an_iteration_predicted_to_end_past_the_deadline_is_not_begun(monkeypatch):
    """Review 32b M1: Clarabel checks its ``time_limit`` only when an iteration begins, so one begun just before the
    limit ended a whole iteration past it (5-7 s qdldl iterations: a 20 s limit overrun by 1.4-1.8x).  The watch
    stops where the next iteration, as long as the last one (the first: the solve so far), would end after ``end``."""
    from sospoly.solvers import interrupt

    clock = [0.0]
    monkeypatch.setattr(interrupt.time, "monotonic", lambda: clock[0])
    watch = interrupt._watch([], 10.0)
    assert next(watch) is False
    answers = []
    for t in (4.0, 7.0, 8.0, 9.5):       # intervals 4, 3, 1, 1.5: predicted ends 8, 10, 9, 11
        clock[0] = t
        answers.append(watch.send(None))
    assert answers == [False, False, False, True]
    unbounded = interrupt._watch([], None)
    next(unbounded)
    clock[0] = 1e9
    assert unbounded.send(None) is False


def test_a_deadline_stops_the_native_solve_with_its_iterate():
    from sospoly.budget import Deadline
    from sospoly.solvers.interrupt import stopped_for_time

    solver, _ = _solver(12)
    sol = solve_interruptibly(solver, Deadline(time.monotonic() - 1.0, 1.0))     # long due: the first check stops it
    assert stopped_for_time(sol) and sol.iterations <= 1
    free = solve_interruptibly(_solver(12)[0], Deadline(time.monotonic() + 3600.0, 3600.0))
    assert not stopped_for_time(free) and str(free.status).endswith("Solved")


def test_the_backend_reports_a_solve_stopped_for_its_deadline_as_time_limit(monkeypatch):
    """A solve the watch stops is status ``time_limit`` (Clarabel says ``CallbackTerminated``), not a failure that
    would send the retry chain on."""
    import sospoly.solvers.backends as backends
    from sospoly.budget import Deadline

    real = backends.solve_interruptibly

    def due(solver, deadline=None):          # the deadline as it is when the solve begins: already due
        return real(solver, Deadline(time.monotonic() - 1.0, 1.0))

    monkeypatch.setattr(backends, "solve_interruptibly", due)
    from sospoly import minimize, variables
    x, = variables("x", n=1)
    res = minimize(x ** 4 - 3 * x ** 2 + x, budget=__import__("sospoly").Budget(time_limit=60.0))
    assert res.status.value == "time_limit"
    grid = np.linspace(-3.0, 3.0, 600001)
    assert res.lower_bound is None or res.lower_bound <= float(np.min(grid ** 4 - 3 * grid ** 2 + grid)) + 1e-9
