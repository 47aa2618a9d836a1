"""is_sos estimates its memory before building (review 25b F6): a quartic in 85 variables (Gram side 3741, under
max_gram_side) raised MemoryError after 54 s in the basis reduction; now BUDGET_EXCEEDED at once, naming the size."""
import time

import sospoly as sp
from sospoly import SolveStatus


def _quartic(n):
    V = sp.variables(" ".join(f"v{i}" for i in range(n)))
    return sum(v ** 4 for v in V) + sum(V) ** 2 + 1


def test_large_question_refused_before_it_is_built():
    t = time.perf_counter()
    r = sp.is_sos(_quartic(85))
    assert time.perf_counter() - t < 5.0
    assert not r.is_sos and r.status == SolveStatus.BUDGET_EXCEEDED and "GiB" in r.message


def test_program_estimate_after_the_reduction():
    r = sp.is_sos(_quartic(20))
    assert r.status == SolveStatus.BUDGET_EXCEEDED and "the program" in r.message
    r = sp.is_sos(_quartic(20), budget=sp.Budget(max_bytes=None, time_limit=0.5))
    assert r.status != SolveStatus.BUDGET_EXCEEDED


def test_small_question_answered():
    r = sp.is_sos(_quartic(4))
    assert r.is_sos and r.status == SolveStatus.FEASIBLE
