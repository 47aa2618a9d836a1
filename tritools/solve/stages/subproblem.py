"""The stage ``sub_problem``: certification through the problem without the views whose regions hold the estimate.

For a set W of views, f_V(X) = sum_{i in V} d_i(X)^2 >= f_{V-W}(X) for every X (d_w >= 0), so the L2 optimum of the
sub-problem bounds the whole problem's from below: with gamma = sqrt(f / 2N) (the paper's (6)),

    gamma*_V >= gamma*_{V-W} sqrt(|V - W| / N),

a valid lower bound for any W whatever the sub-problem's minimiser X'.  Where X' projects into every region of W
(d_w(X') = 0) the bound is attained, gamma_V(X') = gamma*_{V-W} sqrt(|V - W| / N), and the whole problem is
certified at X'.  This is the case of a region much larger than the residuals (a keypoint with a 1e4 px
uncertainty, a wide polytope): the optimum of the other views projects inside it, the view drops out, and the
sub-problem -- fewer views, no auxiliary variables for that region -- is the easy one.  The degree plan of the
whole problem meanwhile works on a program scaled by the large region and stops uncertified (review 39a F3:
ellipses / polytopes of 1e4-1e10 px, lower bound 0 after 3-4 s).

The stage runs after ``verify`` / ``trivial`` (``method="auto"``, at least three views) when the local estimate
projects into some region other than a point (W: those views, at least two views left).  The sub-problem runs the
point stages at delta = 2 within the time left (``max_delta=2``, ``path="auto"``: the per-point rows of a batch
come with ``path="sdp"`` only because the whole problem's verification was tried): its verification and delta = 2
SDP where the kept views are points, its verification only otherwise (:func:`sub_stages`); never this stage again
(no recursion) nor the degree-4 exact-variety step.

Its gamma_LB -- a bound of the sub-problem's data, already lowered for the round-off of its own normalisation --
scaled as above and rounded down is the whole problem's lower bound at X'.  It is not lowered again for the whole
problem's normalisation, whose resolution the large regions coarsen (a 5e4 px disc cost 1e-4 of the bound).  The
report at X' (:func:`~tritools.solve.stages.outcome.report_point`: gamma_UB on all N views, the decision on the
reported numbers with the whole problem's normalisation, cheirality) decides.  A certificate finishes the point;
otherwise the result joins the plan's steps as a candidate (the larger lower bound is kept, :func:`.outcome.better`).
"""
from __future__ import annotations

import math
import time

import numpy as np

from ...model.geometry import project
from ...result import Attempt, Status
from ..options import SolvePath
from .context import AttemptStep, PointContext
from .outcome import better, join, replace, report_point, step_of

__all__ = ["sub_problem_stage", "held_views", "sub_lower_bound", "sub_stages", "SUB_PROBLEM", "ROUND_DOWN"]

#: ``certified_by`` of a certificate through the sub-problem
SUB_PROBLEM = "sub_problem"
#: f = 2 |S| gamma^2 is rescaled with a few roundings (and gamma came through a square root): this factor keeps
#: the product a lower bound by a wide margin (relative error ~1e-15 at most)
ROUND_DOWN = 1.0 - 1e-12
#: the statuses whose gamma_lb is a valid lower bound of the sub-problem
_TRUSTED = frozenset({Status.OPTIMAL, Status.BEHIND_CAMERA, Status.NOT_CERTIFIED, Status.TIME_LIMIT,
                      Status.BUDGET_EXCEEDED})


def held_views(cams: np.ndarray, regions, X) -> list[int]:
    """The views other than points whose region holds the projection of the world point ``X`` (distance exactly
    0: the region's own closest point is the projection)."""
    out = []
    for i, (P, r) in enumerate(zip(cams, regions)):
        if r.is_point:
            continue
        with np.errstate(all="ignore"):
            p = project(X, P)
        if np.all(np.isfinite(p)) and float(r.distance(p)) == 0.0:
            out.append(i)
    return out


def sub_lower_bound(gamma_lb: float, n_sub: int, n_views: int) -> float:
    """gamma*_V >= gamma*_{V-W} sqrt(|V - W| / N) (module docstring), rounded down."""
    return max(0.0, float(gamma_lb) * math.sqrt(n_sub / n_views) * ROUND_DOWN)


def _applies(ctx: PointContext) -> bool:
    opts = ctx.opts
    return ctx.N >= 3 and not (ctx.finished or ctx.expired) and opts.explicit_method is None \
        and not all(r.is_point for r in ctx.regions)


def sub_problem_stage(ctx: PointContext) -> None:
    """Certification through the sub-problem without the views whose regions hold the local estimate (module
    docstring)."""
    if not _applies(ctx):
        return
    est = ctx.local()
    if est is None:
        return
    W = held_views(ctx.cams, ctx.regions, ctx.norm.world_point(est[1]))
    keep = [i for i in range(ctx.N) if i not in set(W)]
    if not W or len(keep) < 2:
        return
    t = time.perf_counter()
    sub = _solve(ctx, keep)
    ctx.tick("sub_problem", t)
    if sub is None or sub.X is None or sub.gamma_lb is None or sub.status not in _TRUSTED:
        why = "failed" if sub is None else sub.status.value if sub.gamma_lb is not None else "no_bound"
        ctx.attempts.append(Attempt("auto", None, why, None, None, AttemptStep.SUB_PROBLEM, None, (),
                                    time.perf_counter() - t))
        return
    lb = sub_lower_bound(sub.gamma_lb, len(keep), ctx.N)
    step = step_of(sub, ctx)
    with np.errstate(all="ignore"):
        x = np.array([project(sub.X, P) for P in ctx.cams])
    res = report_point(ctx, step, Status.OPTIMAL if sub.status.certified else sub.status, sub.status.certified, lb,
                       X=sub.X, X_raw=sub.X, image_points=x, certified_by=SUB_PROBLEM, lowered=True)
    ctx.attempts.append(Attempt(sub.method, sub.delta, res.status.value, res.gamma_lb, res.gamma_ub,
                                AttemptStep.SUB_PROBLEM, sub.sparsity, (), time.perf_counter() - t))
    dropped = ", ".join(map(str, W))
    if res.optimal:
        ctx.best, ctx.finished = replace(res, message=join(
            f"certified by the sub-problem without view(s) {dropped}, whose regions hold its optimum", res.message)), \
            True
    elif res.gamma_lb is not None and (ctx.best is None or better(res, ctx.best)):
        ctx.best = replace(res, message=join(f"lower bound of the sub-problem without view(s) {dropped}",
                                             res.message))


#: the point stages the sub-problem never runs: itself (no recursion), and the degree-4 exact-variety step
_NEVER = frozenset({"sub_problem", "exact_variety"})
#: ... nor, where some kept view is not a point, the SDP steps: a delta = 2 step on regions costs 0.3 s in its
#: estimate's search alone (a 3-view ellipse / border sub-problem of a 4-view mixed scene) and the whole
#: problem's plan runs anyway; kept point views take the delta = 2 SDP (ms)
_REGION_NEVER = _NEVER | {"steps"}


def sub_stages(regions) -> tuple:
    """The point stages of the sub-problem on ``regions`` (module docstring, :data:`_NEVER`, :data:`_REGION_NEVER`)."""
    from . import POINT_STAGES     # (the stage list lives in the package that imports this module)

    never = _NEVER if all(r.is_point for r in regions) else _REGION_NEVER
    return tuple(s for s in POINT_STAGES if s.name not in never)


def _solve(ctx: PointContext, keep: list[int]):
    """The sub-problem of the views ``keep`` (:func:`sub_stages`, delta = 2 at most) within the time left."""
    from . import run_point

    left = ctx.settings.deadline.remaining()
    opts = ctx.opts.replace(max_delta=2, path=SolvePath.AUTO)
    if left is not None:
        opts = opts.replace(time_limit=max(1e-3, left))
    regions = [ctx.regions[i] for i in keep]
    try:
        return run_point(ctx.cams[keep], regions, opts, stages=sub_stages(regions), fast=ctx.fast)
    except (ValueError, TypeError):         # e.g. the kept views share one centre: no sub-problem to solve
        return None
