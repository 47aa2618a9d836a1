"""The solver settings of one triangulation call: :class:`SolveSettings`, built once from the options.

backend, Gram form, tolerances and deadline travel together from :class:`~tritools.solve.options.
TriangulationOptions` down to every stage (:mod:`tritools.solve.stages`) and vectorised implementation
(:mod:`tritools.solve.fastpath`, :mod:`tritools.solve.discs`, :mod:`tritools.solve.sdp_batch`), instead of
four separate arguments.  Two rules live here and nowhere else:

* ``backend=None`` means ``"auto"`` (:class:`sospoly.solvers.backends.AutoBackend`: the interior-point
  method for small programs, Clarabel beyond) on every path: the compiled structures, the free and
  user multipliers (GEVP bisection) and the batched degree-2 SDP alike;
* ``time_limit`` (``options.budget.time_limit``) is **per point**: a single call gets one
  :class:`sospoly.budget.Deadline` that every stage checks (building, compiling, solving, and the
  vectorised verification between its steps); a stack of M points solved together by a vectorised
  stage gets M times the per-point limit, ending no later than the batch call's ``total_time_limit``
  (:func:`stack_deadline`), and each point a later stage solves alone gets its own.  A whole-call limit of a
  batch is a separate option of the batch.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

from sospoly import GramForm, Tolerances
from sospoly.budget import Deadline

__all__ = ["SolveSettings", "AUTO_BACKEND", "stack_deadline", "no_deadline", "call_deadline", "report_reserve",
           "REPORT_RESERVE_SHARE", "REPORT_RESERVE_MAX"]

#: the back-end name ``backend=None`` stands for.
AUTO_BACKEND = "auto"


@dataclass(frozen=True)
class SolveSettings:
    """What every solver call of one point needs: ``backend`` (a sospoly back-end or its name; never None),
    ``form`` (the Gram form of non-compiled programs), ``tolerances`` (the certificate rule) and ``deadline``
    (the point's time limit, :mod:`sospoly.budget`)."""

    backend: object
    form: GramForm
    tolerances: Tolerances
    deadline: Deadline

    def __post_init__(self) -> None:
        if self.backend is None:
            raise TypeError("SolveSettings.backend must be a back-end or its name, not None (None means 'auto': "
                            "build the settings with SolveSettings.from_options)")
        for name, kind in (("form", GramForm), ("tolerances", Tolerances), ("deadline", Deadline)):
            if not isinstance(getattr(self, name), kind):
                raise TypeError(f"SolveSettings.{name} must be a {kind.__name__}, got "
                                f"{type(getattr(self, name)).__name__}")

    @classmethod
    def from_options(cls, options, deadline: Deadline | None = None) -> SolveSettings:
        """The settings of one point under validated :class:`~tritools.solve.options.TriangulationOptions`
        (its ``tolerances`` already checked by ``as_tolerances``); the deadline starts now unless given."""
        backend = AUTO_BACKEND if options.backend is None else options.backend
        return cls(backend, GramForm(options.form), options.tolerances,
                   options.budget.deadline() if deadline is None else deadline)

    @property
    def auto_backend(self) -> bool:
        """The default back-end (the batched interior-point SDP is its twin for stacks)."""
        return isinstance(self.backend, str) and self.backend == AUTO_BACKEND

    @property
    def expired(self) -> bool:
        return self.deadline.expired


def stack_deadline(options, n_points: int) -> Deadline:
    """The deadline of one vectorised call over ``n_points`` points: the per-point ``time_limit`` times the
    number of points (no limit when the budget has none), and no later than the end of the enclosing batch call
    (``total_time_limit``, :func:`tritools.solve.call_limit.current_end`: six 100-view point tracks under
    ``total_time_limit=0.2`` ran their band and all-pairs bounds for ~2 s before)."""
    from .call_limit import current_end

    limit = options.budget.time_limit
    seconds = None if limit is None else float(limit) * max(1, int(n_points))
    end = current_end()
    if end is not None:
        left = max(0.0, end - time.time())
        seconds = left if seconds is None else min(seconds, left)
    return Deadline.after(seconds)


def call_deadline(options, t0: float, regions=()) -> Deadline:
    """The deadline of one call that started at ``t0`` (``time.perf_counter()`` at its entry): the options'
    ``time_limit`` counted from the call's entry, so the input checks before the first stage (~5-10 ms for 400
    views of regions) are inside the limit; none without a limit.  The steps' deadline comes
    :func:`report_reserve` before the limit (counting the call's ``regions`` other than points): what runs after
    the last step (the report at the estimate, the result's checks) fits in it."""
    limit = options.budget.time_limit
    if limit is None:
        return Deadline(None)
    region_views = sum(not r.is_point for r in regions)
    return Deadline.after(limit - report_reserve(limit, region_views) - (time.perf_counter() - t0), span=limit)


#: the share of a call's time limit kept for the work after its last step, and its most in seconds
#: (:func:`report_reserve`)
REPORT_RESERVE_SHARE = 0.1
REPORT_RESERVE_MAX = 0.5
#: seconds per view of a region other than a point that the work past the steps' deadline takes (the regions'
#: closest points and gamma at the estimate, the step it is in): 100 views of mixed regions at 0.05 s ran 8-10 ms
#: past the steps' deadline (1.05-1.11x the limit with the 10% share alone, wave 19)
REPORT_SECONDS_PER_REGION = 1e-4
#: the reserve never takes more than this share of the limit (the steps keep at least the rest)
REPORT_RESERVE_TOP_SHARE = 0.5


def report_reserve(limit: float, region_views: int = 0) -> float:
    """Seconds of a call's ``limit`` kept after its steps' deadline: :data:`REPORT_RESERVE_SHARE` of it, or the
    predicted work of ``region_views`` views of regions (:data:`REPORT_SECONDS_PER_REGION` each) if more, at most
    :data:`REPORT_RESERVE_TOP_SHARE` of the limit and :data:`REPORT_RESERVE_MAX`.  Past the deadline a call still
    reports at its estimate (region distances, compensated projections, the TLS report) and ends the step it is
    in: 3-6 ms at 8-30 views of regions, so calls with 10-50 ms limits ended 1.07-1.33x their limit (review 18)."""
    tail = REPORT_SECONDS_PER_REGION * max(int(region_views), 0)
    return min(max(REPORT_RESERVE_SHARE * limit, tail), REPORT_RESERVE_TOP_SHARE * limit, REPORT_RESERVE_MAX)


def no_deadline() -> Deadline:
    """A deadline that never passes (the default of the vectorised functions called directly)."""
    return Deadline(None)
