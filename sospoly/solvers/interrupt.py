"""Native solves that a signal can end: Ctrl-C (``KeyboardInterrupt``), SIGTERM/SIGHUP handlers that raise.

Python runs a signal's handler only between bytecodes of the main thread, so a signal that arrives during a native
``clarabel.DefaultSolver.solve()`` waits for the whole solve (tens of seconds on a large program; the time limit is
its only bound).  Clarabel calls a *termination callback* once per iteration; :func:`solve_interruptibly` gives it
the ``send`` of a generator (:func:`_watch`), so a pending handler runs when the generator resumes -- inside its
``try``, where the exception is kept rather than lost in the native caller.  The generator then answers "stop",
Clarabel ends the solve, and the kept exception is raised once ``solve()`` has returned: one iteration after the
signal, with nothing unwinding through the native solver.  (A plain Python function as the callback would not do:
its handler would run on entry, before any ``try``.)

The same callback keeps a ``deadline`` (:class:`sospoly.budget.Deadline`): Clarabel checks its own ``time_limit``
only when an iteration begins, so an iteration begun just before the limit ends one iteration past it (review 32b
M1: a qdldl iteration of ~5 s on a 60-block program, a 20 s limit overrun by 1.4-1.8x).  The callback therefore
stops the solve where the next iteration, predicted to take as long as the last one (the first: as long as the
solve so far, the initial point's factorisation), would end past the deadline by more than ``PREDICTED_SLACK``
of its span; Clarabel then reports ``CallbackTerminated`` with the iterate reached (:func:`stopped_for_time`).
"""
from __future__ import annotations

import time

__all__ = ["solve_interruptibly", "stopped_for_time", "PREDICTED_SLACK"]

#: an iteration is not begun when it is predicted to end past the deadline by more than this share of the
#: deadline's span (the time limit it stands for; none without a span)
PREDICTED_SLACK = 0.05


def solve_interruptibly(solver, deadline=None):
    """``solver.solve()`` for a ``clarabel.DefaultSolver``, ended within one iteration by a signal whose Python
    handler raises; that exception (``KeyboardInterrupt``, ``SystemExit``, ...) is then raised here.  With a
    ``deadline`` (:class:`sospoly.budget.Deadline`), no iteration is begun that is predicted to end past it (module
    docstring): the solution's status is then ``CallbackTerminated`` (:func:`stopped_for_time`)."""
    raised: list[BaseException] = []
    end = None if deadline is None or deadline.end is None else deadline.end + PREDICTED_SLACK * (deadline.span or 0.0)
    watch = _watch(raised, end)
    next(watch)
    solver.set_termination_callback(watch.send)
    try:
        sol = solver.solve()
    finally:
        solver.unset_termination_callback()
        watch.close()
    if raised:
        raise raised[0]
    return sol


def stopped_for_time(sol) -> bool:
    """Did :func:`solve_interruptibly` stop this solution for its deadline (status ``CallbackTerminated``: the only
    other stop, a signal, raises instead of returning)?"""
    return str(sol.status).split(".")[-1] == "CallbackTerminated"


def _watch(raised: list, end: float | None = None):
    """Yields, at each iteration, whether to stop: True once a signal handler has raised (the exception appended to
    ``raised``), or when the next iteration, taking as long as the last one, would end after ``end`` (a
    ``time.monotonic`` time; None: never).  Pending handlers run where the generator resumes after ``yield`` and at
    the inner loop's jump back, both inside the ``try`` (a loop around a ``try`` would check them at its own jump,
    outside it: review 30b F5); only the outer loop's jump, taken after a first exception, is outside it."""
    last = time.monotonic()
    stop = False
    while True:
        try:
            while True:
                yield stop or bool(raised)
                if end is not None:
                    now = time.monotonic()
                    stop, last = now + (now - last) > end, now
        except GeneratorExit:
            return
        except BaseException as exc:
            raised.append(exc)
