"""A proven positive floor of a fixed multiplier q that is not of the evident forms (review 39b A10).

The Positivstellensatz argument q (f - c) = sigma (+ constraint terms) proves f >= c where q > 0, so every proof
asks :func:`sospoly.analysis.proof.q_lower_bound` for q_min > 0 with q >= q_min for *every* v.  The evident forms (a
positive constant, 1 + even powers with positive coefficients) are read off the terms; any other q -- (x - 1)^2 + 1,
a user's SOS with cross terms -- is minimised here by :func:`sospoly.minimize`, whose lower bound is proven:
q >= lower_bound everywhere.  Its default multipliers are of the evident forms, and a floor asked for while one is
computed is 0, so this never recurses.  A floor <= 0, a minimisation without a proven bound, or one past
:data:`Q_FLOOR_SECONDS` proves nothing (0).  Results are kept per q (its variables and terms) for the process: the
proofs of one solve ask several times.
"""
from __future__ import annotations

import contextvars
import math

__all__ = ["proven_floor", "Q_FLOOR_SECONDS"]

#: the time a floor of q may take (seconds)
Q_FLOOR_SECONDS = 5.0
#: at most this many floors are remembered
_MEMO_SIZE = 64
_MEMO: dict = {}
#: set while a floor is being computed: a floor asked for inside it is 0 (no recursion, whatever minimize runs)
_INSIDE = contextvars.ContextVar("sospoly_q_floor", default=False)


def _key(q) -> tuple:
    return tuple(q.gens), tuple(sorted(q.terms.items()))


def proven_floor(q) -> float:
    """m with q(v) >= m for every v, proven (:func:`sospoly.minimize`'s lower bound), or 0.0 (module docstring)."""
    if _INSIDE.get():
        return 0.0
    key = _key(q)
    if key in _MEMO:
        return _MEMO[key]
    floor, final = _floor(q)
    if final:                   # (a floor cut by a time limit -- the caller's may be short -- is asked again)
        if len(_MEMO) >= _MEMO_SIZE:
            _MEMO.pop(next(iter(_MEMO)))
        _MEMO[key] = floor
    return floor


def _floor(q) -> tuple[float, bool]:
    """(the proven floor or 0.0, whether it is final: not cut by a time or memory limit)."""
    from ..budget import Budget, BudgetExceeded, TimeLimitReached
    from ..minimize import minimize
    from ..status import SolveStatus

    token = _INSIDE.set(True)
    try:
        res = minimize(q, budget=Budget(time_limit=Q_FLOOR_SECONDS))
    except (ValueError, TypeError, ArithmeticError):
        return 0.0, True
    except (TimeLimitReached, BudgetExceeded):         # an enclosing deadline (the caller's) came first
        return 0.0, False
    finally:
        _INSIDE.reset(token)
    lb = res.lower_bound
    final = res.status not in (SolveStatus.TIME_LIMIT, SolveStatus.BUDGET_EXCEEDED)
    return (float(lb) if lb is not None and math.isfinite(lb) and lb > 0 else 0.0), final
