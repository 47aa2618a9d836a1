"""Native solves that a signal can end: Ctrl-C (``KeyboardInterrupt``), SIGTERM/SIGHUP handlers that raise.

Python runs a signal's handler only between bytecodes of the main thread, so a signal that arrives during a native
``clarabel.DefaultSolver.solve()`` waits for the whole solve (tens of seconds on a large program; the time limit is
its only bound).  Clarabel calls a *termination callback* once per iteration; :func:`solve_interruptibly` gives it
the ``send`` of a generator (:func:`_watch`), so a pending handler runs when the generator resumes -- inside its
``try``, where the exception is kept rather than lost in the native caller.  The generator then answers "stop",
Clarabel ends the solve, and the kept exception is raised once ``solve()`` has returned: one iteration after the
signal, with nothing unwinding through the native solver.  (A plain Python function as the callback would not do:
its handler would run on entry, before any ``try``.)
"""
from __future__ import annotations

__all__ = ["solve_interruptibly"]


def solve_interruptibly(solver):
    """``solver.solve()`` for a ``clarabel.DefaultSolver``, ended within one iteration by a signal whose Python
    handler raises; that exception (``KeyboardInterrupt``, ``SystemExit``, ...) is then raised here."""
    raised: list[BaseException] = []
    watch = _watch(raised)
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


def _watch(raised: list):
    """Yields, at each iteration, whether to stop: True once a signal handler has raised (the exception appended to
    ``raised``).  Pending handlers run where the generator resumes after ``yield`` and at the inner loop's jump back,
    both inside the ``try`` (a loop around a ``try`` would check them at its own jump, outside it: review 30b F5);
    only the outer loop's jump, taken after a first exception, is outside it."""
    while True:
        try:
            while True:
                yield bool(raised)
        except GeneratorExit:
            return
        except BaseException as exc:
            raised.append(exc)
