"""The whole-call time limit of a batch: ``TriangulationOptions.total_time_limit``.

``time_limit`` (the options' budget) bounds *one point*: every problem of a batch gets its own.  A batch
call -- :func:`tritools.triangulate_many`, :func:`tritools.triangulate_points`, the COLMAP workflow,
``tritools solve`` / ``dataset`` / ``colmap`` -- may also be bounded as a whole by ``total_time_limit``
seconds (None, the default: no bound).  With an end E = (start of the call) + ``total_time_limit``:

* a point solved one by one gets the per-point limit min(``time_limit``, E - now): it stops at E at the
  latest, with the best valid bounds found so far (status ``time_limit``);
* a point whose turn comes after E is not solved: it gets status ``time_limit`` with the estimate of last
  resort -- the refined DLT point, X and gamma_UB = gamma(X), no lower bound: one per-point call
  (:func:`tritools.solve.trivial.local_estimate`) for other regions, and for stacks of point problems
  :func:`expired_points`, vectorised (the vectorised certification steps are skipped);
* every point keeps its row, in input order, and the message of a point cut by E says so.

E is the wall clock (``time.time()``), so that per-point work in other processes (the local pool, dask
workers on the same clock) sees the same end.  Nested batch calls share the outermost end: :func:`call_limit`
keeps an enclosing scope's earlier end (as :func:`sospoly.budget.deadline_scope` does for one solve).
"""
from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import math
import time

import numpy as np

from ..model.cameras import camera_problems, power2_scale
from ..model.frame import recentred
from ..model.stacked import dlt_stack, refine_points_stack
from ..result import Attempt, Status, TriangulationResult, input_failure
from .report import points_report_stack
from .robust_costs import tls_start_stack

__all__ = ["call_limit", "current_end", "expired", "within", "mark_cut", "expired_points", "expired_regions",
           "expired_regions_validated",
           "reserve_for", "reserved_end", "reserving",
           "EXPIRED_SLICE", "EXPIRED_LM_ITER", "EXPIRED_SECONDS", "RESERVE_TOP_SHARE", "CUT_MESSAGE"]

#: the per-point time limit of a point whose turn comes after the end: enough to return the local estimate only.
EXPIRED_SLICE = 1e-9
#: Levenberg-Marquardt iterations of the estimate of last resort of a point past the end (:func:`expired_points`):
#: past the end, so a few; a track with wrong matches ran to LM_MAX_ITER = 100 there, and 300 mixed problems under
#: ``total_time_limit=0.5`` spent 0.3 s past it (review 29a F4).  gamma_UB is the value at whatever X it reaches.
EXPIRED_LM_ITER = 8
#: appended to the message of a point stopped by the whole-call limit.
CUT_MESSAGE = "the whole call's time limit (total_time_limit) was reached"

_END: contextvars.ContextVar = contextvars.ContextVar("tritools_call_end", default=None)


@contextlib.contextmanager
def call_limit(seconds: float | None):
    """Make ``time.time() + seconds`` the end of the batch call inside the block (None or inf: none; an
    enclosing scope's earlier end is kept); yields the end (None: no limit)."""
    outer = _END.get()
    end = None if seconds is None or math.isinf(seconds) else time.time() + float(seconds)
    if outer is not None and (end is None or outer < end):
        end = outer
    token = _END.set(end)
    try:
        yield end
    finally:
        _END.reset(token)


def current_end() -> float | None:
    """The end of the enclosing :func:`call_limit` scope (None: no whole-call limit)."""
    return _END.get()


def expired(end: float | None) -> bool:
    return end is not None and time.time() >= end


#: seconds that the row of last resort of one point problem of N views past the end costs, a + b N (the DLT,
#: :data:`EXPIRED_LM_ITER` iterations, the report): measured 0.07-0.15 ms at N = 3, 0.7-1.3 ms at N = 100 and
#: 2.9-3.8 ms at N = 300 per problem on the 2-core machine under load (:func:`reserve_for`)
EXPIRED_SECONDS = (1e-4, 1e-5)
#: the most of the time left that the reserve for the rows of later problems takes (:func:`reserved_end`)
RESERVE_TOP_SHARE = 0.5


def reserve_for(view_counts) -> float:
    """Seconds to keep before the end for the rows of last resort of problems with these view counts: a batch's
    steps end that much earlier, so the rows of the problems they did not reach still fit in the whole call's
    limit (review 29a F4: 300 problems of 2-100 views under ``total_time_limit=0.5`` returned after 0.6-0.9 s)."""
    a, b = EXPIRED_SECONDS
    return float(sum(a + b * int(n) for n in view_counts))


def reserved_end(end: float | None, seconds: float) -> float | None:
    """``end`` moved ``seconds`` earlier, by at most :data:`RESERVE_TOP_SHARE` of the time left (None: no end)."""
    if end is None or seconds <= 0.0:
        return end
    return end - min(float(seconds), RESERVE_TOP_SHARE * max(0.0, end - time.time()))


@contextlib.contextmanager
def reserving(seconds: float):
    """A :func:`call_limit` scope that ends :func:`reserved_end` ``seconds`` before the enclosing one (none without
    an enclosing end); yields its end."""
    end = reserved_end(current_end(), seconds)
    with call_limit(None if end is None else max(0.0, end - time.time())) as inner:
        yield inner


def within(opts, end: float | None):
    """(options, cut): ``opts`` with its per-point time limit cut to what is left before ``end`` (at least
    :data:`EXPIRED_SLICE`), and whether it was cut."""
    if end is None:
        return opts, False
    left = end - time.time()
    per = opts.budget.time_limit
    if per is not None and per <= left:
        return opts, False
    return opts.replace(time_limit=max(left, EXPIRED_SLICE)), True


def mark_cut(result):
    """``result`` with :data:`CUT_MESSAGE` added to its message when it stopped on time (status ``time_limit``)."""
    if getattr(result.status, "value", result.status) != "time_limit" or CUT_MESSAGE in (result.message or ""):
        return result
    message = f"{result.message}; {CUT_MESSAGE}" if result.message else CUT_MESSAGE
    return dataclasses.replace(result, message=message)


def expired_points(C: np.ndarray, x: np.ndarray, opts, *, refine: bool = True,
                   c: np.ndarray | None = None) -> list[TriangulationResult]:
    """``time_limit`` results of point problems (C (M, N, 3, 4), x (M, N, 2)) not solved before the end: the DLT point
    refined by :data:`EXPIRED_LM_ITER` Levenberg-Marquardt iterations (vectorised), gamma_UB = gamma(X) (a valid upper
    bound: the value of the objective at a point), no lower bound, not optimal.  A problem that the per-point checks
    refuse (non-finite numbers, a camera of rank < 3, cameras all equal, fewer than two views:
    :func:`~tritools.model.cameras.camera_problems`, the vectorised twin of the camera checks) gets their
    ``invalid_input`` result instead (:func:`_refused`: what a batch without the limit reports); a stack the vectorised
    steps cannot take (LinAlgError on extreme numbers) is taken one problem at a time; each camera is divided by a power
    of two near its largest entry first (exactly the same camera).  ``refine=False``: the DLT point itself (the robust
    rows: an L2 refinement through wrong matches costs tens of iterations and means nothing for their TLS value); with
    TLS thresholds ``c`` (M, N), the cheap TLS start of :func:`~tritools.solve.robust_costs.tls_start_stack` instead."""
    t0 = time.perf_counter()
    C, x = np.asarray(C, float), np.asarray(x, float)
    finite = camera_problems(C).valid & np.isfinite(x).all(axis=(1, 2)) & (x.shape[1] >= 2)
    if not finite.all():
        good_rows = iter(expired_points(C[finite], x[finite], opts, refine=refine,
                                        c=None if c is None else c[finite]) if finite.any() else [])
        return [next(good_rows) if finite[m] else _refused(C[m], x[m], opts) for m in range(len(x))]
    with np.errstate(all="ignore"):
        C = C / power2_scale(C, (2, 3))             # each camera by a power of two near its largest entry: exact (a
        # division by the entry itself rounds every entry, which a georeferenced world amplifies past gamma_UB's margin)
        try:
            Cr, origin = recentred(C)                   # a georeferenced world: the DLT in its local frame
            X0, ok = dlt_stack(Cr, x) if c is None else tls_start_stack(Cr, x, c)
            Xr, ok = refine_points_stack(Cr, x, X0, ok, max_iter=EXPIRED_LM_ITER) if refine else (X0, ok)
            X = origin + Xr
            gamma, res, dep = points_report_stack(C, x, X, opts.world_frame)
        except np.linalg.LinAlgError:
            if len(x) == 1:
                X, ok, gamma = np.full((1, 3), np.nan), np.zeros(1, bool), np.full(1, np.nan)
                res, dep = [None], [None]
            else:
                return [r for m in range(len(x)) for r in expired_points(C[m:m + 1], x[m:m + 1], opts, refine=refine,
                                                                         c=None if c is None else c[m:m + 1])]
    share = (time.perf_counter() - t0) / max(len(x), 1)
    out = []
    for m in range(len(x)):
        good = bool(ok[m]) and bool(np.isfinite(gamma[m]))
        why = ("X and gamma_UB from the local L2 refinement of the DLT point" if refine else
               "X and gamma_UB from the DLT point" if c is None else
               "X and gamma_UB from the best of the DLT points of all views and of view pairs") if good else \
            "no estimate: the DLT point is at infinity"
        out.append(TriangulationResult(
            opts.method.value, Status.TIME_LIMIT, X=X[m] if good else None,
            gamma_ub=float(gamma[m]) if good else None, optimal=False,
            message=f"{CUT_MESSAGE} before this point was solved; {why}",
            timings={"batch_share": share}, in_front=bool(np.all(dep[m] > 0)) if good else None,
            depths=dep[m] if good else None, residuals=res[m] if good else None,
            attempts=(Attempt(opts.method.value, None, Status.TIME_LIMIT.value, step="call"),)))
    return out


def _refused(cameras, points, opts) -> TriangulationResult:
    """The ``invalid_input`` (``ill_posed``) result of one point problem that the per-point checks refuse
    (:func:`~tritools.solve.fastpath_cameras.validated_problem`: the message a batch without the limit gives); a
    ``time_limit`` result without an estimate if they accept it."""
    from .fastpath_cameras import validated_problem

    try:
        validated_problem(cameras, points)
    except (ValueError, TypeError) as exc:
        status, why = input_failure(exc)                 # (all cameras equal: ill_posed, as without the limit)
        return TriangulationResult(opts.method.value, status, message=why,
                                   attempts=(Attempt(opts.method.value, None, status.value, step="call"),))
    return TriangulationResult(opts.method.value, Status.TIME_LIMIT, optimal=False,
                               message=f"{CUT_MESSAGE} before this point was solved; no estimate",
                               attempts=(Attempt(opts.method.value, None, Status.TIME_LIMIT.value, step="call"),))


def expired_regions(cameras, regions, opts) -> TriangulationResult | None:
    """The ``time_limit`` result of one problem with regions not started before the end: the DLT point of the region
    centres, gamma_UB = gamma(X) (:func:`~tritools.solve.report.point_report`: a valid upper bound), no lower bound,
    not optimal -- without the local refinement through the regions' distances and the normalisation (~10-20 ms a
    problem at 12 views of mixed regions, review 15 F1: 12 such problems took a 0.2 s batch limit to 1.4x).  None
    where the input does not validate (the caller's per-point path then reports what is wrong)."""
    from .fastpath_cameras import validated_problem

    t0 = time.perf_counter()
    try:
        cams, regs = validated_problem(cameras, regions)
        centres = np.array([np.asarray(r.center, float).reshape(2) for r in regs])
    except (ValueError, TypeError):
        return None
    return expired_regions_validated(cams, regs, centres, opts, t0)


def expired_regions_validated(cams: np.ndarray, regs: list, centres: np.ndarray, opts, t0: float,
                              c: np.ndarray | None = None) -> TriangulationResult:
    """:func:`expired_regions` of a validated problem (cameras, regions and their centres (N, 2)); with TLS
    thresholds ``c`` (N,) the cheap TLS start (:func:`~tritools.solve.robust_costs.tls_start_stack` on the centres)
    instead of the DLT point."""
    from .report import point_report

    with np.errstate(all="ignore"):
        Cr, origin = recentred(cams[None])              # a georeferenced world: the DLT in its local frame
        X, ok = dlt_stack(Cr, centres[None]) if c is None else \
            tls_start_stack(Cr, centres[None], np.asarray(c, float)[None])
        X = origin + X
    rep = point_report(X[0] if ok[0] else None, cams, regs, opts.world_frame)
    good = rep.gamma is not None and bool(np.isfinite(rep.gamma))
    why = ("X and gamma_UB from the DLT point of the region centres" if c is None else
           "X and gamma_UB from the best of the DLT points of the region centres of all views and of view pairs") \
        if good else \
        "no estimate: the DLT point is at infinity"
    return TriangulationResult(
        opts.method.value, Status.TIME_LIMIT, X=X[0] if good else None, gamma_ub=float(rep.gamma) if good else None,
        optimal=False, message=f"{CUT_MESSAGE} before this point was solved; {why}",
        timings={"total": time.perf_counter() - t0}, in_front=bool(np.all(rep.depths > 0)) if good else None,
        depths=rep.depths if good else None, residuals=rep.residuals if good else None,
        attempts=(Attempt(opts.method.value, None, Status.TIME_LIMIT.value, step="call"),))
