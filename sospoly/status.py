"""Solve statuses shared by every sospoly result."""
from __future__ import annotations

import enum

__all__ = ["SolveStatus"]


class SolveStatus(str, enum.Enum):
    """Outcome of a conic solve, after the a-posteriori certificate checks.

    ``OPTIMAL`` (and ``FEASIBLE`` for pure feasibility problems): the solver's numbers passed the checks.  The
    other statuses carry no solver numbers to be trusted; a bound reported beside one of them (``INACCURATE``,
    ``TIME_LIMIT`` in :func:`sospoly.minimize`) was proven without the solver's word (the result's message says
    how).
    """

    OPTIMAL = "optimal"                    #: solved to tolerance and certificate checked
    FEASIBLE = "feasible"                  #: feasibility problem solved, certificate checked
    INFEASIBLE = "infeasible"              #: the conic program has no solution (no certificate at this degree)
    UNBOUNDED = "unbounded"                #: objective unbounded (e.g. the constraint set is empty)
    INACCURATE = "inaccurate"              #: solver stopped at reduced accuracy: a bound only where proven rigorously
    CHECK_FAILED = "certificate_check_failed"  #: solver said solved, a-posteriori check rejected it
    NUMERICAL_ERROR = "numerical_error"    #: solver failed (error, panic, iteration limit)
    INCONSISTENT = "inconsistent_bounds"   #: lower bound above a feasible value: numerical failure
    UNPROVEN = "unproven_bound"            #: a relaxation's value that could not be proven a bound: no claim
    TIME_LIMIT = "time_limit"              #: the time limit of the budget was reached first
    BUDGET_EXCEEDED = "budget_exceeded"    #: the program's estimated size exceeds the budget: not built
    NOT_SOLVED = "not_solved"

    @property
    def ok(self) -> bool:
        return self in (SolveStatus.OPTIMAL, SolveStatus.FEASIBLE)
