"""The best-bound stop of a lower-bound solve: stop once an iterate proves the caller's level.

A caller that needs only ``f >= level`` (a branch and bound pruning a node, a MIP solver's best-bound stop) gains
nothing from the optimal c*: inside :func:`level_scope`, an interior-point solve whose iterates are certificates by
construction stops at the first one whose objective reaches the level.  In the reduced moment form
(:class:`sospoly.solvers.ipm.MomentReduction`) the form's dual side is the Gram certificate itself: strictly
positive definite in the interior and its equalities held to round-off from the first iteration, so each iterate's
image-form x is a certificate of its own objective up to the rigorous margin of
:func:`sospoly.analysis.rigor.rigorous_psatz_bound`.  Measured on three-view Theorem 1 degree-4 programs with a
wrong match (tritools' robust search, whose nodes need 9-72% of the optimum): the first or second of ~10
iterations proves the level, with margins ~1e-11 of it.

Such a solve is not solved to optimality: its status is ``INACCURATE`` (raw ``ALMOST_SOLVED``, taken only with
``Tolerances.accept_inaccurate``, whose callers make the bound rigorous), its message says that the level was
reached.  The level is in the caller's objective units (``objective_sign * q^T x + objective_offset``) and means
"at least" for a maximised objective (a lower bound), "at most" for a minimised one.  Other back-ends and forms
ignore it (they solve to optimality).
"""
from __future__ import annotations

import contextlib
import contextvars
import math

__all__ = ["level_scope", "active_level", "stop_threshold", "IPM_LEVEL"]

_ACTIVE_LEVEL: contextvars.ContextVar = contextvars.ContextVar("sospoly_level", default=None)

#: the reason (``Attempt.solver_status``) of an interior-point solve stopped at the caller's level
IPM_LEVEL = "level reached"


@contextlib.contextmanager
def level_scope(level: float | None):
    """Solves inside the block may stop once an iterate reaches ``level`` (module docstring; None or a non-finite
    level: no stop)."""
    if level is not None and not isinstance(level, (int, float)):
        raise TypeError(f"level: a number or None, got {type(level).__name__}")
    token = _ACTIVE_LEVEL.set(None if level is None or not math.isfinite(level) else float(level))
    try:
        yield
    finally:
        _ACTIVE_LEVEL.reset(token)


def active_level() -> float | None:
    """The level of the innermost :func:`level_scope` (None outside any)."""
    return _ACTIVE_LEVEL.get()


def stop_threshold(level: float | None, objective_sign: float, objective_offset: float) -> float | None:
    """The level as a threshold t on the minimised q^T x: the caller's objective sign q^T x + offset reaches
    ``level`` (at least when maximised, sign < 0; at most when minimised) exactly when q^T x <= t."""
    if level is None or not objective_sign:
        return None
    t = (float(level) - float(objective_offset)) / float(objective_sign)
    return t if math.isfinite(t) else None
