"""Many robust (TLS) searches run together (:func:`drive`): their sub-bound requests batched per round.

Each :class:`tritools.solve.robust.TlsSearch` is a generator that yields the view subsets whose certified L2
lower bounds it needs; :func:`drive` collects the requests of every open search, computes them in one
vectorised call per subset size (:func:`tritools.solve.robust_bounds.compute_many`) and resumes them.  A clean
track thus costs one row of the first call, and the search of a track with outliers shares every call with
the other searches of its batch.
"""
from __future__ import annotations

import contextlib
import gc
import logging
import time

from ..result import Status, TriangulationResult
from .call_limit import current_end
from .robust_bounds import compute_many

__all__ = ["drive", "credit", "within_call", "charges"]

log = logging.getLogger(__name__)


def drive(searches: list) -> list:
    """Run TLS searches together: every round, the subset bounds all of them wait for are computed in one batch
    per subset size (:func:`tritools.solve.robust_bounds.compute_many`).  A search that raises gets a
    SOLVER_FAILED result (its message says why); results in input order.

    Time limits stay per problem: each search's clock starts with the drive and is charged its own steps and
    an even share of the batched calls of the rounds it takes part in; the rest of a round's time moves its
    deadline on before it resumes (:func:`credit`).  With one search nothing moves."""
    gens = [s.run() for s in searches]
    results: list = [None] * len(gens)
    pending: dict = {}
    if len(searches) > 1:
        call_end = current_end()
        for s in searches:
            s.set_deadline(within_call(s.opts.budget.deadline(), call_end))

    def step(i: int) -> float:
        t = time.monotonic()
        try:
            pending[i] = gens[i].send(None)
        except StopIteration as stop:
            pending.pop(i, None)
            results[i] = stop.value
        except Exception as exc:  # noqa: BLE001 - one failing problem never stops the others
            log.debug("robust search failed", exc_info=True)
            pending.pop(i, None)
            results[i] = TriangulationResult("tls", Status.SOLVER_FAILED, message=f"{type(exc).__name__}: {exc}")
        return time.monotonic() - t

    def round_(active: list, shared: float, solved: dict | None = None) -> None:
        """Step the active searches, each credited first with the time it waited for (the batched calls beyond
        its charge, :func:`charges`; the steps before it), then with the steps after it."""
        own, before = {}, 0.0
        waited = charges(shared, [(solved or {}).get(id(searches[i].bounds), 0.0) for i in active])
        for i, w in zip(active, waited):
            credit(searches[i], w + before)
            own[i] = step(i)
            before += own[i]
        later = 0.0
        for i in reversed(active):
            credit(searches[i], later)
            later += own[i]

    with _collector_paused(len(searches)):
        round_(list(range(len(gens))), 0.0)
        while pending:
            t = time.monotonic()
            solved = compute_many([(searches[i].bounds, req) for i, req in pending.items()])
            round_(list(pending), time.monotonic() - t, solved)
    return results


def charges(shared: float, own: list) -> list:
    """The time each of the searches of a round waited for beyond its charge: a round's batched calls took
    ``shared`` seconds, of which ``own[k]`` were search k's own sub-problems solved one by one (regions); search k
    is charged own[k] and an even share of the rest, and credited the remainder.  An even split of the whole made a
    disc problem certified alone in 0.3 s pay for the others' region sub-problems and stop at its time limit in a
    batch (review 29a F6)."""
    n = len(own)
    if n == 0:
        return []
    even = max(0.0, shared - sum(own)) / n
    return [max(0.0, shared - o - even) for o in own]


#: drives of at least this many searches pause the cyclic garbage collector (:func:`_collector_paused`).
GC_PAUSE_FROM = 64


@contextlib.contextmanager
def _collector_paused(n_searches: int):
    """Pause Python's cyclic garbage collector during a drive of many searches, restoring its state after.  The
    searches keep many small containers (subset caches, generator frames) alive until the drive ends, and the
    collector's full passes over them cost 5-10% of a batch (benchmarks/robust_speed.py) while freeing nothing:
    reference counting still frees every object outside a cycle at once, and the next collection after the drive
    takes the rest."""
    pause = n_searches >= GC_PAUSE_FROM and gc.isenabled()
    if pause:
        gc.disable()
    try:
        yield
    finally:
        if pause:
            gc.enable()


def within_call(deadline, call_end: float | None):
    """``deadline`` (monotonic clock) no later than the whole call's wall-clock ``call_end`` (None: no end).  A
    drive's searches count their time limit from the drive's start, after the enumeration that came before it in
    their chunk: without this a batch under ``total_time_limit`` ran on that long past its end (review 29a F4: 1.4-1.9x
    the limit, robust, 300 problems)."""
    if call_end is None:
        return deadline
    end = time.monotonic() + (call_end - time.time())
    if deadline.end is not None and deadline.end <= end:
        return deadline
    return type(deadline)(end, deadline.span)


def credit(search, seconds: float) -> None:
    """Move a search's deadline (if any) on by ``seconds`` it was not charged, never past the end of the whole
    call (``total_time_limit``, :func:`tritools.solve.call_limit.current_end`, wall clock): the searches of a
    batch together stop there (review finding F4)."""
    d = search.deadline
    if d.end is not None and seconds > 0:
        search.set_deadline(within_call(type(d)(d.end + seconds, d.span), current_end()))

