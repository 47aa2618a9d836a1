"""The results of the stages: one point's report, the trivial bound, and the last three point stages.

* :func:`report_point` -- the result of an estimate X (world frame, normalised problem's units decided)
  with gamma_UB, residuals and depths on the cameras (:func:`tritools.solve.report.point_report`), the
  decision confirmed on the numbers reported (:func:`tritools.solve.decide.decide_reported`) and
  cheirality (:func:`tritools.solve.decide.cheirality`);
* :func:`trivial_certificate` -- a certificate through gamma* >= 0 (:mod:`tritools.solve.trivial`);
* the stages ``settle`` (the trivial bound at the best estimate, the local estimate when there is none,
  TIME_LIMIT / BUDGET_EXCEEDED when the plan stopped short), ``world_frame`` (the estimate back in the
  caller's frame, :mod:`tritools.model.frame`) and ``report`` (timings and attempts).
"""
from __future__ import annotations

import copy
import dataclasses
import time

import numpy as np

from ...model.constraints import Method
from ...model.geometry import project, project_point_views
from ...result import Attempt, Status, TriangulationResult
from ..decide import cheirality, decide_reported, gamma_lower, transfer_contradicts
from ..front import front_estimate
from ..multistart import multistart_point
from ..plan import Step
from ..report import point_report
from ..trivial import TRIVIAL_BOUND, trivially_certified, trivially_certified_reported
from .context import AttemptStep, PointContext, sparsity_name

__all__ = ["report_point", "trivial_certificate", "failed", "better", "behind_message", "replace",
           "settle_stage", "world_frame_stage", "report_stage"]


def replace(res: TriangulationResult, **kw) -> TriangulationResult:
    return dataclasses.replace(res, **kw)


def join(*messages: str) -> str:
    return "; ".join(m for m in messages if m)


def behind_message(depths, objective: str = "L2") -> str:
    """The message of a certified optimum behind some camera(s): which ones (``objective``: "L2", or "TLS" with
    the depths of its inlier views only)."""
    return f"certified {objective} optimum, but behind camera(s) " + \
        ", ".join(str(i) for i in np.nonzero(~(np.asarray(depths, float) > 0))[0])


#: why a result whose bounds met is not certified when its estimate has no finite gamma_UB.
UNDEFINED_MESSAGE = "the estimate's projection is undefined in some view (a point at a camera centre)"
#: a lowered bound above gamma(X) of the caller's data beyond the rule (:func:`~tritools.solve.decide.
#: transfer_contradicts`): the transfer's allowance did not hold, so no bound is reported.
TRANSFER_MESSAGE = "the lower bound transferred to the caller's data lies above gamma(X): no bound"


def has_upper(rep) -> bool:
    """Whether a point report gives a finite gamma_UB: without one there is no certificate (e.g. views sharing one
    centre, where the extracted point is the centre itself; a georeferenced point 1e-7 from a camera centre)."""
    return rep.gamma is not None and bool(np.isfinite(rep.gamma))


def report_point(ctx: PointContext, step: Step, status, optimal, gamma_lb, *, X, X_raw, image_points,
                 certified_by, n_lmivar=None, lowered: bool = False, front_tried: bool = False) -> TriangulationResult:
    """The result of the estimate ``X`` under ``step`` (module docstring); ``lowered``: ``gamma_lb`` is already a
    bound of the caller's data (:func:`tritools.solve.decide.gamma_lower`, done by the batch paths).  A certified
    estimate of cost 0 (within the rule) behind a camera is replaced by an in-front one where the regions admit it
    (:func:`tritools.solve.front.front_estimate`; the certificate decided again on it)."""
    status0, optimal0, gamma_lb0 = status, optimal, gamma_lb
    rep = point_report(X, ctx.cams, ctx.regions, ctx.opts.world_frame)
    same = X_raw is X or (X_raw is not None and X is not None and np.array_equal(X_raw, X))
    raw = rep if same else point_report(X_raw, ctx.cams, ctx.regions)     # gamma only: the frame is irrelevant
    msg = ""
    if gamma_lb is not None and rep.gamma is not None and np.isfinite(rep.gamma):
        # of the caller's float data (the normalisation's round-off), never above the reported upper bound
        if not lowered:
            gamma_lb = gamma_lower(gamma_lb, rep.gamma, ctx.norm.scale, ctx.norm.lowering_resolution,
                                   ctx.norm.magnitude_at(ctx.cams, X))
        if transfer_contradicts(gamma_lb, rep.gamma, ctx.tolerances, ctx.N, ctx.norm.scale):
            # the bound of the normalised problem, lowered by its round-off, is above gamma(X) of the caller's data
            # beyond the rule: the transfer's allowance did not hold, so there is no bound to report (review 46a)
            status, optimal, gamma_lb = Status.NUMERICAL_FAILURE, False, None
            msg = TRANSFER_MESSAGE
        else:
            gamma_lb = min(gamma_lb, rep.gamma)
        if optimal and gamma_lb is not None:         # the decision again, on the numbers reported
            optimal = decide_reported(gamma_lb, rep.gamma, ctx.tolerances, ctx.N, ctx.norm.scale,
                                      ctx.norm.resolution)
            if not optimal:
                status = Status.NOT_CERTIFIED
                msg = "the bounds met in normalised coordinates, but not at the estimate in world coordinates"
    if optimal and not has_upper(rep):
        status, optimal, msg = Status.NOT_CERTIFIED, False, UNDEFINED_MESSAGE
    if optimal and rep.depths is not None and not cheirality(status, rep.depths)[1] and not front_tried \
            and trivially_certified_reported(rep.gamma, ctx.tolerances, ctx.N, ctx.norm.scale, ctx.norm.resolution):
        # gamma* = 0 within the rule: the minimisers may form a set with points in front (uncertain regions, review
        # 21b F1); a positive optimum's minimiser is the one the certificate came with (review 21c F1: the search
        # cost 0.1-0.6 s per call where none exists)
        front = front_estimate(ctx, X)
        if front is not None:
            ip = np.array([r.closest_point(project(front, P)[None])[0] for P, r in zip(ctx.cams, ctx.regions)])
            out = report_point(ctx, step, status0, optimal0, gamma_lb0, X=front, X_raw=front, image_points=ip,
                               certified_by=certified_by, n_lmivar=n_lmivar, lowered=lowered, front_tried=True)
            if out.optimal and out.in_front:
                return out
    status, in_front = cheirality(status, rep.depths, ctx.opts.require_in_front)
    if optimal and not in_front:
        msg = behind_message(rep.depths)
    return TriangulationResult(step.result_method.value, status, X=X, gamma_ub=rep.gamma, gamma_lb=gamma_lb,
                               optimal=optimal, delta=step.delta, n_lmivar=n_lmivar, image_points=image_points,
                               X_raw=X_raw, gamma_ub_raw=raw.gamma, certified_by=certified_by if optimal else None,
                               message=msg, sparsity=sparsity_name(step), in_front=in_front, depths=rep.depths,
                               residuals=rep.residuals)


def failed(ctx: PointContext, step: Step, status: Status, message: str, label: AttemptStep,
           t: float) -> TriangulationResult:
    """A step that produced no bound (an attempt is recorded)."""
    sparsity = sparsity_name(step)
    ctx.attempts.append(Attempt(step.method.value, step.delta, status.value, None, None, label, sparsity, (),
                                time.perf_counter() - t))
    return TriangulationResult(step.result_method.value, status, delta=step.delta, message=message,
                               sparsity=sparsity)


def trivial_certificate(ctx: PointContext, step: Step, X=None) -> TriangulationResult | None:
    """A certificate through the trivial bound gamma* >= 0 (:mod:`tritools.solve.trivial`) at ``X`` (world
    frame; default the local estimate), or None when gamma(X) is not within the tolerance of 0."""
    t = time.perf_counter()
    if X is None:
        est = ctx.local()
        if est is None or not trivially_certified(2 * ctx.N * est[0] ** 2, ctx.tolerances, ctx.N,
                                                  ctx.norm.resolution):
            return None
        X = ctx.norm.world_point(est[1])
    rep = point_report(X, ctx.cams, ctx.regions)
    if rep.gamma is None or not trivially_certified_reported(rep.gamma, ctx.tolerances, ctx.N, ctx.norm.scale,
                                                             ctx.norm.resolution):
        return None
    with np.errstate(all="ignore"):
        x = _projections(X, ctx.cams)
    res = report_point(ctx, step, Status.OPTIMAL, True, 0.0, X=X, X_raw=X, image_points=x, certified_by=TRIVIAL_BOUND)
    if not res.optimal:
        return None
    ctx.attempts.append(Attempt(step.method.value, step.delta, Status.OPTIMAL.value, 0.0, res.gamma_ub,
                                AttemptStep.TRIVIAL_BOUND, res.sparsity, (), time.perf_counter() - t))
    return replace(res, message=join("gamma_UB within the certificate tolerance of the trivial lower bound 0",
                                     res.message))


def _projections(X, cams: np.ndarray) -> np.ndarray:
    """The projections (N, 2) of the world point X by the validated cameras: those of
    :func:`tritools.model.geometry.image_points` (the same numbers), without validating the cameras again and in
    one stacked expression (a 400-view report past a time limit: ~1 ms, not ~30)."""
    return project_point_views(np.append(np.asarray(X, float), 1.0)[None], cams)


def better(a: TriangulationResult, b: TriangulationResult) -> bool:
    """Is ``a`` a better result to report than ``b``: certified first, then any estimate with a lower bound
    (the larger one), then any estimate."""
    if a.status.certified != b.status.certified:
        return a.status.certified
    if (a.gamma_lb is not None) != (b.gamma_lb is not None):
        return a.gamma_lb is not None
    if a.gamma_lb is not None and b.gamma_lb is not None and a.gamma_lb != b.gamma_lb:
        return a.gamma_lb > b.gamma_lb
    return a.X is not None and b.X is None


def step_of(res: TriangulationResult, ctx: PointContext) -> Step:
    """The plan step a result belongs to (for reporting an estimate under it)."""
    first = ctx.steps[0] if ctx.steps else Step(ctx.opts.explicit_method or Method.COROLLARY1, 2, "dense")
    try:
        method = Method(res.method)
    except ValueError:
        method = first.method
    return Step(method, res.delta if res.delta is not None else first.delta,
                "views" if res.sparsity == "views" else "dense")


def _stopped_short(ctx: PointContext, best: TriangulationResult | None) -> TriangulationResult:
    """``best`` with TIME_LIMIT / BUDGET_EXCEEDED when the plan stopped short of a certificate."""
    if best is None:
        method = ctx.steps[0].result_method.value if ctx.steps else \
            (ctx.opts.explicit_method or Method.COROLLARY1).value
        return TriangulationResult(method, Status.TIME_LIMIT,
                                   message="time limit reached before any certificate was computed")
    open_ = not best.status.certified and best.status != Status.ILL_POSED
    # a step cut by its solver's time limit (MaxTime a little before the deadline) stopped the plan short too: its
    # result is not the plan's last word (a robust search would take a not_certified sub-problem as exhausted)
    timed_out = ctx.expired or any(a.status == Status.TIME_LIMIT.value for a in ctx.attempts)
    if timed_out and open_:
        why = "time limit reached" + (" (the verification's all-pairs bound did not fit in the time left)"
                                      if ctx.verify_cut else "")
        return replace(best, status=Status.TIME_LIMIT, message=join(best.message, why))
    if ctx.skipped is not None and ctx.skipped is not best and open_:
        # the best bounds so far, and why the plan stopped short of a certificate
        return replace(best, status=Status.BUDGET_EXCEEDED, message=join(best.message,
                                                                         f"skipped {ctx.skipped.message}"))
    return best


def settle_stage(ctx: PointContext) -> None:
    """The final result: the plan's outcome (:func:`_stopped_short`), then a certificate through the trivial
    bound at the best estimate (or the local one) when one holds; otherwise the best result, with the local
    estimate when it has none (every status but ``invalid_input`` carries an estimate when one exists), and for
    point regions the multi-start estimate of :mod:`tritools.solve.multistart` where it is lower."""
    _settle(ctx)
    if not ctx.best.status.certified and ctx.best.status != Status.INVALID_INPUT:
        ctx.best = _multistart_estimate(ctx, ctx.best)


def _settle(ctx: PointContext) -> None:
    """:func:`settle_stage` before the multi-start estimate."""
    best = _stopped_short(ctx, ctx.best)
    if best.status.certified or best.status == Status.INVALID_INPUT:
        ctx.best = best
        return
    best = _steps_best_estimate(ctx, best)
    step = step_of(best, ctx)
    cert = (trivial_certificate(ctx, step, best.X) if best.X is not None else None) or trivial_certificate(ctx, step)
    if cert is not None:
        why = f" (before: {best.status.value}{': ' + best.message if best.message else ''})"
        ctx.best = replace(cert, n_lmivar=best.n_lmivar, message=cert.message + why)
        return
    est = ctx.local()
    if best.X is not None or est is None:
        ctx.best = best
        return
    X = ctx.norm.world_point(est[1])
    with np.errstate(all="ignore"):
        x = _projections(X, ctx.cams)
    rep = report_point(ctx, step, best.status, False, best.gamma_lb, X=X, X_raw=X, image_points=x, certified_by=None)
    note = "X and gamma_UB from the local L2 refinement of the DLT point"
    ctx.best = replace(rep, delta=best.delta, n_lmivar=best.n_lmivar, sparsity=best.sparsity,
                       message=join(best.message, note))


def _multistart_estimate(ctx: PointContext, best: TriangulationResult) -> TriangulationResult:
    """``best`` (not certified) with X and gamma_UB from :func:`~tritools.solve.multistart.multistart_point` when
    that is lower (``method="auto"``, point regions only, before the deadline; when ``best`` is in front of its
    cameras or ``require_in_front`` is set, only an estimate in front of every camera).  The bound, status, solver
    fields and X_raw (the step's own estimate before refinement) stay those of ``best``; an explicit method reports
    the paper's estimate (its tables' X^)."""
    if best.X is None or best.gamma_ub is None or ctx.expired or ctx.opts.explicit_method is not None \
            or not all(r.is_point for r in ctx.regions):
        return best
    found = multistart_point(ctx.cams, np.array([r.center for r in ctx.regions]))
    if found is None or not np.sqrt(found[1] / (2 * ctx.N)) < best.gamma_ub:
        return best
    X = found[0]
    with np.errstate(all="ignore"):
        x = _projections(X, ctx.cams)
    rep = report_point(ctx, step_of(best, ctx), best.status, False, best.gamma_lb, X=X, X_raw=X, image_points=x,
                       certified_by=None, lowered=True)
    if rep.gamma_ub is None or not rep.gamma_ub < best.gamma_ub or rep.status != best.status or \
            ((ctx.opts.require_in_front or best.in_front) and not rep.in_front):
        return best                     # (an estimate in front of its cameras is never traded for one behind)
    return replace(best, X=rep.X, gamma_ub=rep.gamma_ub, gamma_lb=rep.gamma_lb, image_points=rep.image_points,
                   residuals=rep.residuals, depths=rep.depths,
                   in_front=rep.in_front, message=join(best.message, "X and gamma_UB from the best of the local "
                                                                     "refinements from view-pair DLT points"))


def _steps_best_estimate(ctx: PointContext, best: TriangulationResult) -> TriangulationResult:
    """``best`` (the largest lower bound of the plan, not certified) with the steps' best estimate
    (``PointContext.estimate_n``) when another step's estimate has a lower gamma_UB: the reported bounds are then
    the largest lower bound and the lowest upper bound of the plan (both valid), not one step's pair (a delta = 2
    step's estimate at 112 px was reported beside a delta = 4 step's at 0.61 px, both lower bounds 0: review 14 F1).
    The step, degree and solver fields stay those of the bound."""
    est, norm = ctx.estimate_n, ctx.norm
    if best.X is None or est is None or best.gamma_ub is None or not est[0] / norm.scale < best.gamma_ub:
        return best                     # (est[0] = s gamma: the report below decides on the caller's numbers)
    _, X_n, X_raw_n, x_star_n = est
    rep = report_point(ctx, step_of(best, ctx), best.status, False, best.gamma_lb, X=norm.world_point(X_n),
                       X_raw=norm.world_point(X_raw_n), image_points=norm.image_points(x_star_n), certified_by=None,
                       lowered=True)
    if rep.gamma_ub is None or not rep.gamma_ub < best.gamma_ub:
        return best
    gamma_lb, note = rep.gamma_lb, "X and gamma_UB from the plan's best estimate"
    if best.gamma_lb is not None and best.gamma_lb > rep.gamma_ub:
        # a valid bound is at most gamma* <= gamma(X) <= gamma_UB: this step's is refuted (review 44b MEDIUM-2: a
        # stalled delta = 4 program's 4647 px beside a 1736 px estimate was clipped to that gamma_UB, rounded up)
        gamma_lb = max((a.gamma_lb for a in ctx.attempts if a.gamma_lb is not None and a.gamma_lb <= rep.gamma_ub),
                       default=None)
        note = join(note, f"the lower bound {best.gamma_lb:.10g} of the {best.method} delta = {best.delta} step is "
                          f"above it (numerical failure): the largest bound of the other steps is reported")
    return replace(best, X=rep.X, X_raw=rep.X_raw, gamma_ub=rep.gamma_ub, gamma_ub_raw=rep.gamma_ub_raw,
                   gamma_lb=gamma_lb, image_points=rep.image_points, residuals=rep.residuals, depths=rep.depths,
                   in_front=rep.in_front, message=join(best.message, note))


def world_frame_stage(ctx: PointContext) -> None:
    """The result with X moved back to the caller's world frame (:mod:`tritools.model.frame`) and gamma_UB,
    residuals and depths evaluated there on the caller's cameras -- the numbers a user re-computes -- the
    certificate confirmed on them (:func:`tritools.solve.decide.decide_reported`)."""
    res = ctx.best
    if not ctx.frame.moved or res.X is None:
        return
    X, X_raw = ctx.frame.user_point(res.X), ctx.frame.user_point(res.X_raw)
    rep = point_report(X, ctx.cams_user, ctx.regions)
    kw = dict(X=X, X_raw=X_raw, gamma_ub=rep.gamma, residuals=rep.residuals, depths=rep.depths,
              gamma_ub_raw=point_report(X_raw, ctx.cams_user, ctx.regions).gamma)
    if res.gamma_lb is not None and rep.gamma is not None and np.isfinite(rep.gamma):
        if transfer_contradicts(res.gamma_lb, rep.gamma, ctx.tolerances, ctx.N, ctx.norm.scale):
            # the re-centred frame's bound lies above a cost the caller's data attain beyond the rule: no bound, as
            # in report_point (review 46c L3; clipping it to gamma_UB would report a certificate)
            ctx.best = replace(res, **kw, gamma_lb=None, status=Status.NUMERICAL_FAILURE, optimal=False,
                               certified_by=None, message=TRANSFER_MESSAGE + " in the caller's frame")
            return
        kw["gamma_lb"] = min(res.gamma_lb, rep.gamma)
        if res.optimal and not decide_reported(kw["gamma_lb"], rep.gamma, ctx.tolerances, ctx.N, ctx.norm.scale,
                                               ctx.norm.resolution):
            kw.update(status=Status.NOT_CERTIFIED, optimal=False, certified_by=None,
                      message=join(res.message, "the bounds met in the re-centred frame, but not at the estimate "
                                                "in the caller's frame"))
    if res.optimal and not has_upper(rep):                     # report_point's rule, on the caller's numbers
        kw.update(status=Status.NOT_CERTIFIED, optimal=False, certified_by=None,
                  message=UNDEFINED_MESSAGE + " in the caller's frame")
    ctx.best = replace(res, **kw)


def report_stage(ctx: PointContext) -> None:
    """Timings and every attempt into the result."""
    ctx.timings["total"] = time.perf_counter() - ctx.t0
    ctx.best = with_record(ctx.best, dict(ctx.timings), tuple(ctx.attempts))


def with_record(res: TriangulationResult, timings: dict, attempts: tuple) -> TriangulationResult:
    """``replace(res, timings=timings, attempts=attempts)`` without validating the other fields again: they were
    validated when ``res`` was made, and a fresh dict and a tuple of :class:`~tritools.result.Attempt` are what
    ``__post_init__`` would store (anything else takes the validating path)."""
    if type(res) is not TriangulationResult or not all(type(a) is Attempt for a in attempts):
        return replace(res, timings=timings, attempts=attempts)
    out = copy.copy(res)
    object.__setattr__(out, "timings", timings)
    object.__setattr__(out, "attempts", attempts)
    return out
